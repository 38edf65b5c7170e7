"""The search issue's acceptance, measured: success, collisions, path length and SPL per strategy.

Run from the repository root (each trial is a full closed-loop run in the simulator, with the stereo-
costmap navigator that ``lab search`` uses; expect one to three minutes of CPU per trial)::

    python benchmarks/eval_search.py run --out out/eval_search [--strategies paper,rate,lawnmower,frontier]
        [--seeds A,B] [--sensing realistic|ideal]
        [--obstacles both|no|yes] [--surfaces floor,table,shelf] [--max-time 600]
        [--workers N | --scheduler tcp://HOST:8786] [--allow-spent-seeds]
    python benchmarks/eval_search.py report out/eval_search [more folders, or old .jsonl files]

``run`` is ``lab eval search`` (:mod:`lab.eval.search`: the same trials, placements and scoring, on a
local pool or a Dask cluster, resumable) with this script's report-split defaults; ``report`` reads the
sweep's ``jobs/`` (and ``failed/``) and prints what follows.

**Trials.** Three textured objects (cereal_box, book, toy_block) x three heights (floor, table_a or
table_b at 0.75 m, the shelf at 1.2 m) x the seeds: each (object, surface, seed) is one seeded random
placement (``random_placement`` with ``default_rng([seed, object, surface])``: position and yaw), the
same for every strategy and with and without obstacles. ``--obstacles yes`` adds the two boxes of
``lab.runs.search.path_obstacles`` on the straight line from the start to the object (the paper's
"obstacles placed in the planned path"; the boxes are not in the robot's map, it must see them).
Two seeds give the issue's 18 placements; by default two fresh report seeds
(:func:`lab.evaluation.fresh_report_seeds`: above every seed in the ledger of spent seeds,
``lab/data/spent_seeds.toml``), under the ``realistic`` sensing profile (``--sensing``). A report seed
the ledger lists as spent is refused unless ``--allow-spent-seeds``; ``report`` says "ON SPENT SEEDS"
when its trials are on some. Once figures on fresh seeds are reported, record them: ``lab eval spend
A-B --why "..."``. A trial that runs out
of ``--max-time`` (simulated seconds; default 600, ``lab search``'s own) is a failure: a slow baseline
fails by its budget. The report also counts the successes found within shorter budgets (90 s, the
issue's median; 300 s, the evaluation's budget until stop 42), read off the same runs: the budget only
stops a run, it does not change what the agent does before it.

``run`` writes one JSON per trial into ``OUT/jobs/`` (the ``lab search`` JSON without its map
snapshots, plus ``shortest_path_m``) and skips trials already there, so a killed run can be resumed;
several machines share the work through ``--scheduler`` (the old ``--shard K/N`` is gone).

**Report** (``report FILE...``), per strategy and obstacle setting and overall:

* success: found, position error <= 5 cm and orientation error <= 10 degrees (``SearchResult.success``);
* collisions (the simulator's bump count, summed);
* SPL, success weighted by path length: mean of ``S_i l_i / max(p_i, l_i)`` with ``l_i`` the shortest
  collision-free path from the start to local-search range of the object (A* on the scene's true
  occupancy grown by the robot's radius: evaluation only, the robot never sees it) and ``p_i`` the
  driven path (odometry);
* the median over the trials both strategies got right of the ratio of the paper strategy's path
  length to the lawnmower's on the same trial (the issue wants <= 0.7), and the same ratio with the
  lawnmower's path on its failures counted as driven (a lower bound of what it would have needed);
  the same for the rate strategy against the paper's.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import statistics
import sys
from pathlib import Path

import numpy as np

from lab.eval.cli import SEARCH_SEEDS
from lab.eval.search import SEARCH_MAX_TIME_S, spl
from lab.evaluation import fresh_report_seeds, seed_ranges_text, spent_among, wilson_interval

OBJECTS = ("cereal_box", "book", "toy_block")
SURFACES = ("floor", "table", "shelf")


def key(d: dict) -> tuple:
    return (d["object"], d["surface"], int(d["seed"]), bool(d["obstacles"]), d["strategy"])


def label(d: dict) -> str:
    """One trial's name for the printouts."""
    obst = "obstacles" if d["obstacles"] else "no obstacles"
    return f"{d['strategy']:9s} {d['object']:10s} {d['surface']:5s} seed {d['seed']} {obst:12s}"


def cmd_run(args) -> int:
    from lab.cli import main as lab

    argv = ["eval", "search", "--objects", ",".join(OBJECTS), "--surfaces", args.surfaces,
            "--seeds", args.seeds, "--strategies", args.strategies, "--obstacles", args.obstacles,
            "--sensing", args.sensing, "--max-time", str(args.max_time), "--out", str(args.out),
            "--resume"]  # fmt: skip
    if args.max_wall_time is not None:
        argv += ["--max-wall-time", str(args.max_wall_time)]
    if args.workers is not None:
        argv += ["--workers", str(args.workers)]
    if args.scheduler is not None:
        argv += ["--scheduler", args.scheduler]
    if args.allow_spent_seeds:
        argv += ["--allow-spent-seeds"]
    return lab(argv)


def read_trials(path: Path) -> list[dict]:
    """The trials of a ``lab eval search`` folder (finished ones from ``jobs/``, crashed ones from
    ``failed/`` as failures with their error), or of an old ``run`` JSON-lines file."""
    path = Path(path)
    if path.is_file():
        return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    rows = []
    for p in sorted((path / "jobs").glob("*.json")):
        d = json.loads(p.read_text())
        d["obstacle_poses"] = d.get("obstacles", [])
        d["obstacles"] = bool(d["obstacles_on_path"])
        rows.append(d)
    for p in sorted((path / "failed").glob("*.json")):
        f = json.loads(p.read_text())
        prm = f["params"]
        rows.append(
            {
                **{k: prm[k] for k in ("object", "surface", "seed", "obstacles", "strategy")},
                "error": f["error"],
                "found": False,
                "success": False,
                "collisions": 0,
                "path_length_m": 0.0,
                "obstacle_poses": [],
                "shortest_path_m": None,
            }  # fmt: skip
        )
    return rows


def n_obstacles_placed(d: dict) -> int:
    """Boxes ``path_obstacles`` actually put on the line (none fit when the object is near the start):
    recomputed from the seed as ``run_search`` draws them."""
    if not d["obstacles"]:
        return 0
    if "obstacle_poses" in d:
        return len(d["obstacle_poses"])
    from lab.runs.search import path_obstacles
    from lab.scene import load_scene

    place = tuple(d["place"])
    scene = load_scene("lab_room").with_pose(d["object"], place)
    return len(path_obstacles(scene, d["object"], place, np.random.default_rng(int(d["seed"])))[1])


def summary_line(label: str, rows) -> str:
    n = len(rows)
    s = sum(bool(d.get("success")) for d in rows)
    f = sum(bool(d.get("found")) for d in rows)
    c = sum(int(d.get("collisions") or 0) for d in rows)
    bumped = sum(int(d.get("collisions") or 0) > 0 for d in rows)
    errs = sum("error" in d for d in rows)
    lo, hi = wilson_interval(s, n) if n else (math.nan, math.nan)
    return (
        f"{label:34s} n {n:3d}  success {s:3d} ({100 * s / max(n, 1):5.1f} %, Wilson 95 % "
        f"[{100 * lo:.1f}, {100 * hi:.1f}])  found {f:3d}  "
        f"collisions {c} (in {bumped} trials)  SPL {spl(rows):.3f}" + (f"  crashed {errs}" if errs else "")
    )


_FOUND_STD = re.compile(r"std ([0-9.]+) cm, ([0-9.]+) deg")


def claimed_std(d: dict) -> tuple[float, float] | None:
    """The filter's standard deviations ``(cm, deg)`` the found trial's last local-search event claims."""
    for e in reversed(d.get("events") or []):
        if e["kind"] == "local":
            m = _FOUND_STD.search(e["detail"])
            return (float(m.group(1)), float(m.group(2))) if m else None
    return None


def confidently_wrong(d: dict, limit_deg: float = 10.0, claimed_deg: float = 5.0) -> bool:
    """Found with an orientation more than ``limit_deg`` off while the filter claims under ``claimed_deg``
    (the search issue's "confidently wrong pose")."""
    if not d.get("found") or d.get("orientation_error_deg") is None:
        return False
    std = claimed_std(d)
    return d["orientation_error_deg"] > limit_deg and std is not None and std[1] < claimed_deg


def medians_line(rows) -> str:
    """Median simulated time and path length over the successes (the search issue's <= 90 s, <= 20 m)."""
    ok = [d for d in rows if d.get("success")]
    if not ok:
        return "    no success: no medians"
    t = statistics.median(d["sim_time_s"] for d in ok)
    m = statistics.median(d["path_length_m"] for d in ok)
    wrong = sum(confidently_wrong(d) for d in rows)
    return (
        f"    over the {len(ok)} successes: median time {t:.1f} s, median path {m:.1f} m; "
        f"confidently wrong poses (> 10 deg, filter < 5 deg): {wrong}"
    )


def within_line(rows, budgets=(90.0, 300.0)) -> str:
    """The successes that ended within each shorter budget [s] of simulated time: what a run with that
    budget would have scored (the budget does not change what the agent does before it), less the rare
    run that the budget's check, between steps, lets finish a look past it."""
    n = len(rows)
    parts = []
    for b in budgets:
        k = sum(bool(d.get("success")) and float(d.get("sim_time_s") or math.inf) <= b for d in rows)
        lo, hi = wilson_interval(k, n) if n else (math.nan, math.nan)
        parts.append(f"<= {b:g} s: {k} ({100 * k / max(n, 1):.1f} %, [{100 * lo:.1f}, {100 * hi:.1f}])")
    return "    successes within a shorter budget: " + "; ".join(parts)


def local_searches_at_object(d: dict) -> tuple[int, int]:
    """``(k, n)``: of the trial's ``n`` local searches, ``k`` answered for the object's true cell (a cell
    within ``LocalSearchConfig.detection.neighbour_radius_m`` of the searched one, as the map update
    counts it):
    k > 0 on a miss means the local search looked at the object and did not find it."""
    from lab.runs.search import map_spec
    from lab.scene import load_scene
    from lab.search.local_search import LocalSearchConfig

    spec = map_spec(load_scene("lab_room"))
    r = LocalSearchConfig().detection.neighbour_radius_m
    ox, oy = spec.cell_to_world(*spec.world_to_cell(*d["place"][:2]))
    cells = [e["cell"] for e in d.get("events") or [] if e["kind"] == "local" and e["cell"]]
    near = [c for c in cells if math.dist(spec.cell_to_world(*c), (ox, oy)) <= r + 1e-9]
    return len(near), len(cells)


def paired_path_ratio(rows, by, a_s: str, b_s: str) -> None:
    """Print the median ratio of strategy ``a_s``'s path length to ``b_s``'s over the trials both ran
    and got right, and the same with ``b_s``'s path on its failures counted as driven."""
    pairs = []
    for d in rows:
        if d["strategy"] != a_s:
            continue
        k = key(d)[:4] + (b_s,)
        if k in by:
            pairs.append((d, by[k]))
    if not pairs:
        return
    both = [
        a["path_length_m"] / b["path_length_m"] for a, b in pairs if a.get("success") and b.get("success")
    ]
    censored = [
        a["path_length_m"] / b["path_length_m"]
        for a, b in pairs
        if a.get("success") and b["path_length_m"] > 0
    ]
    if both:
        med = statistics.median(both)
        print(f"path length {a_s} / {b_s}, same trials: median {med:.3f} over the {len(both)} both got right")
    else:
        print(f"path length {a_s} / {b_s}: no trial both got right")
    if censored:
        print(
            f"  over the {len(censored)} the {a_s} strategy got right, the {b_s} strategy's path on its "
            f"failures counted as driven (an upper bound): median {statistics.median(censored):.3f}"
        )


def cmd_report(args) -> int:
    rows = []
    for p in args.files:
        rows += read_trials(p)
    by = {}
    for d in rows:
        by.setdefault(key(d), d)  # first record of a trial wins
    rows = list(by.values())
    for d in rows:
        d["n_obstacles"] = n_obstacles_placed(d)
    spent = spent_among(int(d["seed"]) for d in rows)
    if spent:
        print(f"ON SPENT SEEDS: {seed_ranges_text(spent)} (the ledger of spent seeds): no fresh evidence")
    strategies = sorted(
        {d["strategy"] for d in rows}, key=lambda s: ("rate", "paper", "frontier", "lawnmower").index(s)
    )
    print(f"{len(rows)} trials")
    for s in strategies:
        rs = [d for d in rows if d["strategy"] == s]
        print(summary_line(f"{s}", rs))
        print(medians_line(rs))
        print(within_line(rs))
        for ob in (False, True):
            sub = [d for d in rs if bool(d["obstacles"]) == ob]
            if sub:
                print(summary_line(f"  {'with' if ob else 'without'} obstacles", sub))
            if ob and sub:
                placed = [d for d in sub if d["n_obstacles"] > 0]
                print(summary_line("    (with >= 1 box actually placed)", placed))
        for surf in SURFACES:
            sub = [d for d in rs if d["surface"] == surf]
            if sub:
                print(summary_line(f"  on the {surf}", sub))
        for name in OBJECTS:
            sub = [d for d in rs if d["object"] == name]
            if sub:
                print(summary_line(f"  {name}", sub))
    # the paper strategy against the lawnmower, and the rate strategy against the paper's, on the same trials
    for a_s, b_s in (("paper", "lawnmower"), ("rate", "paper")):
        paired_path_ratio(rows, by, a_s, b_s)
    fails = [d for d in rows if not d.get("success")]
    if fails:
        print("failures (not found: k/n of its local searches answered for the object's cell):")
        for d in sorted(fails, key=key):
            at = ""
            if not d.get("found") and "error" not in d:
                at = "{}/{} at the object; ".format(*local_searches_at_object(d))
            print(
                f"  {label(d)} place {d.get('place')}: found {d.get('found')} pe {d.get('position_error_m')} "
                f"oe {d.get('orientation_error_deg')}: {at}{d.get('reason', d.get('error'))}"
            )
    return 0


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("--out", required=True, help="the sweep's folder (lab eval search --out)")
    r.add_argument("--strategies", default="paper,rate,lawnmower,frontier")
    r.add_argument(
        "--seeds",
        default=seed_ranges_text(fresh_report_seeds(SEARCH_SEEDS)),
        help=f"e.g. 0,1 (tuning) or report seeds (default: {SEARCH_SEEDS} fresh report seeds, above every "
        "seed in the ledger of spent seeds, lab/data/spent_seeds.toml; a spent one is refused)",
    )
    r.add_argument("--sensing", default="realistic", choices=("realistic", "ideal", "sensors"))
    r.add_argument("--obstacles", choices=("no", "yes", "both"), default="both")
    r.add_argument("--surfaces", default=",".join(SURFACES), help="a subset of floor,table,shelf")
    r.add_argument(
        "--max-time", type=float, default=SEARCH_MAX_TIME_S, help="simulated-time budget per trial [s]"
    )
    r.add_argument("--max-wall-time", type=float, default=None, help="wall-clock cap per trial [s]")
    r.add_argument("--workers", type=int, help="worker processes (default 1)")
    r.add_argument("--scheduler", help="a Dask scheduler's address (tcp://HOST:8786), or 'local'")
    r.add_argument(
        "--allow-spent-seeds",
        action="store_true",
        help="run even on report seeds the ledger lists as spent (refused otherwise); the report says so",
    )
    rep = sub.add_parser("report")
    rep.add_argument("files", nargs="+", help="lab eval search folders (or old run .jsonl files)")
    return ap


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    return cmd_run(args) if args.cmd == "run" else cmd_report(args)


if __name__ == "__main__":
    sys.exit(main())
