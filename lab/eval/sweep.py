"""A sweep: a grid of seeded jobs, run by an executor, each job's JSON written as it finishes.

``OUT/jobs/KEY.json`` is a finished job's result (the ``lab identify --json`` or ``lab search --json``
schema, checked against ``lab/schemas`` by :mod:`lab.contract`); ``OUT/failed/KEY.json`` a failed one's
error; ``OUT/results.csv`` one row per job (rewritten after each), ``OUT/report.md`` the success rates
with Wilson 95 % intervals per condition. ``resume=True`` runs only the jobs without a result (the
failed ones again). What differs between ``lab eval identify`` and ``lab eval search`` (the table's
columns, the report's conditions and medians) is a :class:`SweepKind`: :data:`IDENTIFY` here,
:data:`lab.eval.search.SEARCH`.

**Seeds.** Job ``(model, planner, mover, sensing, seed)`` runs the episode ``lab identify --seed
SEED`` would, wherever it runs: every generator of the episode is ``numpy.random.default_rng(SEED)``,
i.e. seeded through ``numpy.random.SeedSequence(SEED)``, so jobs with different seeds draw independent
streams and a job's stream depends on nothing but its seed (:func:`job_seed_sequence`).
"""

from __future__ import annotations

import csv
import io
import json
import sys
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lab.errors import ConfigError
from lab.eval.executor import Job, Outcome

__all__ = [
    "IDENTIFY",
    "IdentifySweep",
    "SweepKind",
    "confidently_wrong_pose",
    "final_pose_quantile",
    "with_pose_columns",
    "identify_job",
    "identify_key",
    "job_seed_sequence",
    "load_sweep_file",
    "run_sweep",
]

#: The columns of ``lab eval identify``'s results.csv.
CSV_FIELDS = (
    "key",
    "true_model",
    "planner",
    "mover",
    "sensing",
    "seed",
    "max_actions",
    "error_scale",
    "localization",
    "success",
    "identified_model",
    "actions",
    "sim_time_s",
    "wall_time_s",
    "position_error_m",
    "orientation_error_deg",
    "std_position_m",
    "std_orientation_deg",
    "error",
)


@dataclass(frozen=True)
class SweepKind:
    """What one kind of sweep puts in its table and report.

    ``schema``: the :mod:`lab.contract` schema each job's JSON keeps; ``columns``: results.csv's
    columns (``key``, ``error`` and ``wall_time_s`` among them), the others read from the job's
    parameters (``params``) or its result; ``conditions``: the parameters a report row is grouped
    by; ``medians``: ``(header, function of the rows that ran -> value)`` columns of the report;
    ``state``: a finished job's progress line; ``derive``: the columns computed from a job's result
    (a function of it returning a dict, read before the result's own fields). A sweep over several
    error scales is grouped by ``error_scale`` too (:func:`write_report`)."""

    name: str
    schema: str
    columns: tuple[str, ...]
    params: tuple[str, ...]
    conditions: tuple[str, ...]
    medians: tuple = ()
    state: object = None
    derive: object = None


def _med(xs, fmt="{:.1f}"):
    import statistics

    xs = [x for x in xs if x is not None]
    return fmt.format(statistics.median(xs)) if xs else "-"


def _median_actions(rows) -> str:
    return _med([r["actions"] if r["success"] else r["max_actions"] for r in rows], "{:g}")


def _num(row, key) -> float | None:
    v = row.get(key)
    return None if v in (None, "") else float(v)


def confidently_wrong_pose(row, position_m: float = 0.05, orientation_deg: float = 10.0) -> bool:
    """Whether a stated pose is confidently wrong (issue 52's bar): more than ``position_m`` [m] or
    ``orientation_deg`` [deg] off the truth (``position_error_m``, ``orientation_error_deg``) while its
    stated deviation (``std_position_m``, ``std_orientation_deg``) is under a third of that error. False
    without an error or a stated deviation (no truth, no pose).

    >>> confidently_wrong_pose({"position_error_m": 0.06, "std_position_m": 0.01})
    True
    >>> confidently_wrong_pose({"position_error_m": 0.06, "std_position_m": 0.03})
    False
    """
    pe, oe = _num(row, "position_error_m"), _num(row, "orientation_error_deg")
    sp, so = _num(row, "std_position_m"), _num(row, "std_orientation_deg")
    off_p = pe is not None and sp is not None and pe > position_m and sp < pe / 3
    off_o = oe is not None and so is not None and oe > orientation_deg and so < oe / 3
    return off_p or off_o


def _identified(row) -> bool:
    return str(row.get("success")) in ("True", "true", "1")


def final_pose_quantile(rows, q: float) -> tuple[float, float] | None:
    """The ``q``-quantile (0..1, linear interpolation) of the final pose's position [cm] and orientation
    [deg] error over the episodes that identified their model (an unidentified one has no pose of the
    right model to score; it counts as a failure in the success column); None without one."""
    ok = [r for r in rows if _identified(r) and _num(r, "position_error_m") is not None]
    if not ok:
        return None
    p = np.quantile([100.0 * _num(r, "position_error_m") for r in ok], q)
    o = np.quantile([_num(r, "orientation_error_deg") for r in ok], q)
    return float(p), float(o)


def _pose_cell(q: float):
    def cell(rows) -> str:
        v = final_pose_quantile(rows, q)
        return "-" if v is None else f"{v[0]:.2f} cm / {v[1]:.1f}°"

    return cell


IDENTIFY = SweepKind(
    name="identify",
    schema="identify",
    columns=CSV_FIELDS,
    params=(
        "true_model",
        "planner",
        "mover",
        "sensing",
        "localization",
        "error_scale",
        "seed",
        "max_actions",
    ),
    conditions=("planner", "mover", "sensing", "localization"),
    medians=(
        # an episode that did not identify its model counts its whole budget (a lower bound)
        ("median actions", _median_actions),
        ("median sim s", lambda rs: _med([r["sim_time_s"] for r in rs])),
        # the final pose of the identified episodes: the bar is 1 cm / 2 deg and 3 cm / 5 deg
        ("final pose median", _pose_cell(0.5)),
        ("final pose p90", _pose_cell(0.9)),
        ("final pose worst", _pose_cell(1.0)),
        ("confidently wrong", lambda rs: str(sum(_identified(r) and confidently_wrong_pose(r) for r in rs))),
    ),
    state=lambda r: f"success {r['success']} after {r['actions']} actions, {r['sim_time_s']:.1f} s sim",
    derive=lambda res: with_pose_columns(res),
)


def job_seed_sequence(seed: int):
    """The job's ``SeedSequence``: what ``default_rng(seed)`` in every part of the episode starts from."""
    import numpy as np

    return np.random.SeedSequence(int(seed))


@dataclass(frozen=True)
class IdentifySweep:
    """The grid of ``lab eval identify``: models x seeds x planners x movers x sensing profiles x
    localization modes x error scales (every error of the profile times it,
    :meth:`lab.sim.sensing.SensingProfile.scaled`). Localization defaults to ``lab identify``'s own
    (odometry), so the default grid's jobs keep their names."""

    models: tuple[int, ...] = (0, 1, 2, 3)
    seeds: tuple[int, ...] = ()
    planners: tuple[str, ...] = ("lut", "random")
    movers: tuple[str, ...] = ("evasive",)
    sensing: tuple[str, ...] = ("realistic",)
    localization: tuple[str, ...] = ("odometry",)
    max_actions: int = 8
    max_time: float = 240.0
    keep_direction: float | None = None
    error_scale: tuple[float, ...] = (1.0,)
    fields: tuple = field(default=(), compare=False, repr=False)

    def check(self) -> None:
        from lab.eval.robustness import parse_error_scales
        from lab.identification.agent import PlannerChoice

        if not self.seeds:
            raise ConfigError("the seed range is empty: give --seeds like 100000-100009 (or seeds = [...])")
        if not self.models:
            raise ConfigError("no models: give --models like 0,1,2,3")
        bad = [m for m in self.models if not 0 <= m <= 3]
        if bad:
            raise ConfigError(f"models must be 0..3, got {bad}")
        known = [p.value for p in PlannerChoice]
        for p in self.planners:
            if p not in known:
                raise ConfigError(f"unknown planner {p!r}; planners: {', '.join(known)}")
        for m in self.movers:
            if m not in ("static", "scripted", "random", "evasive"):
                raise ConfigError(f"unknown mover {m!r}; movers: static, scripted, random, evasive")
        check_sensing(self.sensing)
        if not self.localization:
            raise ConfigError("no localization: give --localization like odometry,landmarks")
        for loc in self.localization:
            if loc not in ("odometry", "landmarks"):
                raise ConfigError(f"unknown localization {loc!r}; allowed: odometry, landmarks")
        parse_error_scales(self.error_scale)
        if self.max_actions < 0:
            raise ConfigError(f"max_actions must be >= 0, got {self.max_actions}")
        if not self.max_time > 0:
            raise ConfigError(f"max_time must be > 0 s, got {self.max_time}")

    def jobs(self) -> list[Job]:
        from lab.eval.robustness import scale_suffix

        out = []
        grid = [
            (p, mv, s, loc)
            for p in self.planners
            for mv in self.movers
            for s in self.sensing
            for loc in self.localization
        ]
        for (planner, mover, sensing, loc), k in [(g, k) for g in grid for k in self.error_scale]:
            for seed in self.seeds:
                for m in self.models:
                    kw = dict(
                        true_model=m,
                        seed=seed,
                        mover=mover,
                        planner=planner,
                        max_actions=self.max_actions,
                        max_time_s=self.max_time,
                        sensing=sensing,
                        localization=loc,
                        keep_direction=self.keep_direction,
                        error_scale=k,
                    )
                    key = identify_key(planner, mover, sensing_label(sensing), m, seed, loc) + scale_suffix(k)
                    out.append(Job(key, identify_job, kw))
        return out


def check_sensing(names: tuple[str, ...]) -> None:
    """Each of a sweep's sensing profiles is a profile's name or a sensing file (a ``.toml`` with a
    ``[sensing]`` table, as ``lab identify --sensing my_room.toml`` reads), read here so that a missing
    or bad file stops the sweep in one line before any job runs."""
    from lab.sim.sensing import PROFILES, sensing_profile

    if not names:
        raise ConfigError(f"no sensing profile: give --sensing like {','.join(PROFILES)} or a .toml file")
    for s in names:
        if not s.endswith(".toml"):
            if s not in PROFILES:
                raise ConfigError(
                    f"unknown sensing profile {s!r}; profiles: {', '.join(PROFILES)}, or a .toml file"
                )
        elif not Path(s).is_file():
            raise ConfigError(f"sensing file {s} not found (a profile's name or a .toml file is allowed)")
        else:
            sensing_profile(Path(s))


def sensing_label(sensing: str) -> str:
    """A sensing profile's name in a job's key: the profile's name, or a sensing file's stem."""
    return Path(sensing).stem if sensing.endswith(".toml") else sensing


def identify_key(
    planner: str, mover: str, sensing: str, model: int, seed: int, localization: str = "odometry"
) -> str:
    """An identification job's name: ``OUT/jobs/KEY.json`` (``_landmarks`` added for that localization,
    so the default's names stay those of earlier sweeps and ``--resume`` finds them)."""
    loc = "" if localization == "odometry" else f"_{localization}"
    return f"{planner}_{mover}_{sensing}{loc}_m{model}_s{seed}"


SWEEP_FIELDS = (
    "models",
    "seeds",
    "planners",
    "movers",
    "sensing",
    "localization",
    "max_actions",
    "max_time",
    "keep_direction",
    "error_scale",
)


def load_sweep_file(path: Path, fields: tuple[str, ...] = SWEEP_FIELDS) -> dict:
    """A TOML sweep file's ``fields`` (``[sweep]`` table or top level): lists, or strings like the
    flags'. An unknown field is an error naming the allowed ones."""
    try:
        data = tomllib.loads(Path(path).read_text())
    except FileNotFoundError:
        raise ConfigError(f"sweep file {path} does not exist") from None
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"sweep file {path} is not valid TOML: {e}") from None
    data = data.get("sweep", data)
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise ConfigError(
            f"sweep file {path}: unknown field(s) {', '.join(unknown)}; fields: {', '.join(fields)}"
        )
    return data


def identify_job(error_scale: float = 1.0, **kwargs) -> dict:
    """One identification episode in this worker process (its own PyBullet client), no figures; its
    profile's errors times ``error_scale``."""
    from lab.runs.identify import run_identify
    from lab.sim.sensing import sensing_profile

    kwargs["sensing"] = sensing_profile(kwargs.get("sensing", "realistic")).scaled(error_scale)
    return run_identify(figures=False, **kwargs)


def with_pose_columns(result: dict) -> dict:
    """The table's columns of a ``lab identify`` JSON's final pose: ``position_error_m``,
    ``orientation_error_deg`` (its ``pose_error``, the true model's estimate against the truth) and
    ``std_position_m``, ``std_orientation_deg`` (its ``pose_estimate``'s stated deviations); None where
    missing."""
    err = result.get("pose_error") or {}
    est = result.get("pose_estimate") or {}
    return {
        "position_error_m": err.get("translation_m"),
        "orientation_error_deg": err.get("rotation_deg"),
        "std_position_m": est.get("position_std_m"),
        "std_orientation_deg": est.get("orientation_std_deg"),
    }


def _row(kind: SweepKind, key: str, job_kw: dict, res: dict | None, error: str | None, wall) -> dict:
    row = {k: job_kw.get(k) for k in kind.params}
    if isinstance(row.get("sensing"), str):
        row["sensing"] = sensing_label(row["sensing"])  # a sensing file by its stem, as in the key
    row["key"] = key
    if res is not None:
        res = res if kind.derive is None else {**res, **kind.derive(res)}
        row.update({k: res.get(k) for k in kind.columns if k not in kind.params and k != "key"})
        row["wall_time_s"] = res.get("wall_time_s", wall)
    else:
        row.update(success=False, wall_time_s=wall)
    row["error"] = error or ""
    return row


def _write_table(out: Path, rows: list[dict], kind: SweepKind = IDENTIFY) -> Path:
    from lab.io import write_bytes_atomic, write_text_atomic

    fields = kind.columns
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=fields, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for r in sorted(rows, key=lambda r: r["key"]):
        w.writerow({k: ("" if r.get(k) is None else r.get(k)) for k in fields})
    write_text_atomic(out / "results.csv", buf.getvalue())
    try:  # Parquet too, when pyarrow is there
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        return out / "results.csv"
    sink = pa.BufferOutputStream()
    pq.write_table(pa.Table.from_pylist([{k: r.get(k) for k in fields} for r in rows]), sink)
    write_bytes_atomic(out / "results.parquet", sink.getvalue().to_pybytes())
    return out / "results.csv"


def run_sweep(
    out: Path, jobs: list[Job], executor, resume: bool = False, echo=print, kind: SweepKind = IDENTIFY
) -> list[dict]:
    """Run ``jobs`` (those without a result in ``out`` when ``resume``) and write the table; the rows."""
    from lab.contract import problems
    from lab.io import write_json_atomic

    out = Path(out)
    done_dir, fail_dir = out / "jobs", out / "failed"
    if not resume and (out / "results.csv").exists():
        raise ConfigError(f"{out} already holds a sweep: --resume to complete it, or another --out")
    keys = [j.key for j in jobs]
    if len(set(keys)) != len(keys):
        raise ConfigError("the sweep has duplicate jobs (a value given twice?)")
    rows: dict[str, dict] = {}
    todo = []
    for j in jobs:
        p = done_dir / f"{j.key}.json"
        if resume and p.is_file():
            rows[j.key] = _row(kind, j.key, j.kwargs, json.loads(p.read_text()), None, None)
        else:
            todo.append(j)
    echo(f"{len(jobs)} jobs, {len(jobs) - len(todo)} done before, {len(todo)} to run on {executor.name}")
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    n_ok = n_fail = 0
    for o in executor.run(todo):
        o: Outcome
        res, err = o.result, o.error
        if res is not None:
            bad = problems(kind.schema, res)
            if bad:
                res, err = None, f"ContractError: {bad[0]}"
        if res is not None:
            write_json_atomic(done_dir / f"{o.job.key}.json", res)
            (fail_dir / f"{o.job.key}.json").unlink(missing_ok=True)
            n_ok += 1
        else:
            write_json_atomic(
                fail_dir / f"{o.job.key}.json", {"key": o.job.key, "params": o.job.kwargs, "error": err}
            )
            n_fail += 1
        rows[o.job.key] = _row(kind, o.job.key, o.job.kwargs, res, err, o.wall_time_s)
        _write_table(out, list(rows.values()), kind)
        n = n_ok + n_fail
        el = time.perf_counter() - t0
        eta = el / n * (len(todo) - n)
        state = "FAILED " + err.splitlines()[0][:120] if err else kind.state(res)
        echo(
            f"[{n}/{len(todo)}] {o.job.key}: {state} ({o.wall_time_s:.1f} s; {n_fail} failed; "
            f"{el:.0f} s elapsed, ~{eta:.0f} s to go)"
        )
    rows_l = [rows[k] for k in keys if k in rows]
    _write_table(out, rows_l, kind)
    write_report(out, rows_l, kind)
    return rows_l


def write_report(out: Path, rows: list[dict], kind: SweepKind = IDENTIFY) -> Path:
    """``report.md``: success per condition (``kind.conditions``, e.g. planner, mover, sensing, and the
    error scale when there are several) with its Wilson 95 % interval and the kind's medians; the split
    of the seeds, and whether any is spent (in the ledger of :mod:`lab.evaluation`); the failed jobs; the
    robustness curve over the error scales (:mod:`lab.eval.robustness`, with ``robustness.png``)."""
    from lab.eval.robustness import robustness_lines
    from lab.evaluation import spent_among, spent_note, split_of, wilson_interval
    from lab.io import write_text_atomic

    lines = [f"# Sweep report: lab eval {kind.name}", ""]
    seeds = sorted({int(r["seed"]) for r in rows})
    if seeds:
        lines.append(f"Seeds {seeds[0]}-{seeds[-1]} ({len(seeds)}): the {split_of(seeds)} split.")
        lines.append("")
        note = spent_note(spent_among(seeds, run=kind.name), len(seeds))
        if note:
            lines += [note, ""]
    conditions = kind.conditions
    if len({float(r.get("error_scale") or 1.0) for r in rows}) > 1:
        conditions = (*conditions, "error_scale")
    heads = [*conditions, "success", "Wilson 95 %", *(h for h, _ in kind.medians), "errors"]
    lines += ["| " + " | ".join(heads) + " |", "|" + "---|" * len(heads)]
    conds = sorted({tuple(str(r[c]) for c in conditions) for r in rows})
    for c in conds:
        rs = [r for r in rows if tuple(str(r[k]) for k in conditions) == c]
        ran = [r for r in rs if not r["error"]]
        k = sum(bool(r["success"]) for r in ran)
        ci = wilson_interval(k, len(ran)) if ran else None
        cells = [*c, f"{k}/{len(ran)}", "-" if ci is None else f"[{100 * ci[0]:.1f}, {100 * ci[1]:.1f}] %"]
        cells += [f(ran) if ran else "-" for _, f in kind.medians]
        cells.append(str(len(rs) - len(ran)))
        lines.append("| " + " | ".join(cells) + " |")
    fails = [r for r in rows if r["error"]]
    if fails:
        lines += ["", "Failed jobs (`--resume` runs them again):", ""]
        lines += [f"* {r['key']}: {r['error'].splitlines()[0]}" for r in fails]
    lines.append("")
    lines += robustness_lines(out, rows, kind.name)
    return write_text_atomic(out / "report.md", "\n".join(lines)) or out / "report.md"


def print_split(seeds, file=None) -> None:
    """``split: report (seeds A-B, N seeds)``, and which of them are spent when some are."""
    from lab.evaluation import seed_ranges_text, spent_among, split_of

    file = file or sys.stdout
    s = sorted(seeds)
    spent = spent_among(s)
    on = f"; ON SPENT SEEDS: {seed_ranges_text(spent)}" if spent else ""
    print(f"split: {split_of(s)} (seeds {s[0]}-{s[-1]}, {len(s)} seeds{on})", file=file)
