"""The identification acceptance grid (issue 7): true models x seeds x planners, evasive mover.

Run (from the repository root; resumable: an episode whose JSON exists is not run again)::

    nice .venv/bin/python benchmarks/eval_identify.py --out out/eval_identify --jobs 2
    nice .venv/bin/python benchmarks/eval_identify.py --out out/eval_identify --planners lut --seeds 0-4
    .venv/bin/python benchmarks/eval_identify.py --out out/eval_identify --report-only
    .venv/bin/python benchmarks/eval_identify.py --out out/eval_identify --scheduler tcp://HOST:8786

The episodes are run by ``lab eval identify`` (:mod:`lab.eval`: a local pool of ``--jobs`` processes, or
a Dask cluster with ``--scheduler``; each episode's ``lab identify --json`` result in ``OUT/jobs/``),
with this script's report-split defaults. The report prints, per planner: successes (the true model ends
as the argmax with ``P >= 0.95`` held for the dwell, within the action budget), the distribution of
planning actions and of simulated time, the true model's final pose error, the real-time factors (sim
time / wall time of the whole job, measured under whatever load the machine had; and of the loop alone,
start-up and figures excluded, per wall second and per CPU second; the load average printed is the
machine's when the report is printed), and the ratio of the median actions of ``lut`` to ``random`` over
the seeds both ran. It writes the same as JSON (``summary.json``).

An episode that did not identify its model counts ``max_actions`` actions (a lower bound: the budget
ran out), and the report lists every failure with its final probabilities.

**Which seeds.** By default 25 fresh report seeds (:func:`lab.evaluation.fresh_report_seeds`: above
every seed in the ledger of spent seeds, ``lab/data/spent_seeds.toml``) under the ``realistic`` sensing
profile; the report prints the split and gives every success rate with its Wilson 95 % interval.
Parameters are tuned on seeds below 1000 (``--seeds 0-19``), never on the report split. A report seed the
ledger lists as spent is refused unless ``--allow-spent-seeds``, and the report then says "ON SPENT
SEEDS" (``--report-only`` never refuses, it only says so). Once figures on fresh seeds are reported,
record them: ``lab eval spend A-B --why "..." --runs identify``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
from pathlib import Path

from lab.errors import ConfigError
from lab.eval.cli import IDENTIFY_SEEDS
from lab.evaluation import (
    check_report_seeds,
    fresh_report_seeds,
    parse_seeds,
    seed_ranges_text,
    spent_among,
    split_of,
    wilson_interval,
)


def episode_path(
    out: Path, planner: str, model: int, seed: int, mover="evasive", sensing="realistic"
) -> Path:
    """Where ``lab eval identify --out OUT`` writes this episode's JSON."""
    from lab.eval.sweep import identify_key

    return out / "jobs" / f"{identify_key(planner, mover, sensing, model, seed)}.json"


def run_episodes(args, planners) -> int:
    """``lab eval identify`` over the grid, resuming what ``--out`` already holds."""
    from lab.cli import main as lab

    argv = ["eval", "identify", "--models", ",".join(map(str, args.models)),
            "--seeds", ",".join(map(str, args.seeds)), "--planners", ",".join(planners),
            "--movers", args.mover, "--sensing", args.sensing, "--max-actions", str(args.max_actions),
            "--max-time", str(args.max_time), "--out", str(args.out), "--resume"]  # fmt: skip
    if args.keep_direction is not None:
        argv += ["--keep-direction", str(args.keep_direction)]
    if args.allow_spent_seeds:
        argv += ["--allow-spent-seeds"]
    if args.scheduler is not None:
        argv += ["--scheduler", args.scheduler]
    else:
        argv += ["--workers", str(max(1, args.jobs))]
    return lab(argv)


def _dist(xs) -> dict:
    xs = sorted(xs)
    if not xs:
        return {"n": 0}
    q = statistics.quantiles(xs, n=4) if len(xs) > 1 else [xs[0]] * 3
    return {
        "n": len(xs),
        "min": xs[0],
        "q1": q[0],
        "median": statistics.median(xs),
        "q3": q[2],
        "max": xs[-1],
    }


def reached(res: dict, threshold: float = 0.95) -> bool:
    """The true model reached the threshold at some step (the history's posteriors)."""
    k = res["true_model"]
    return any(h["posterior"][k] >= threshold for h in res["history"])


def summarise(
    out: Path, planners, models, seeds, max_actions: int, mover="evasive", sensing="realistic"
) -> dict:
    summary: dict = {"planners": {}, "models": models, "seeds": seeds, "split": split_of(seeds)}
    summary["on_spent_seeds"] = seed_ranges_text(spent_among(seeds)) or None
    for planner in planners:
        rows = []
        for m in models:
            for s in seeds:
                p = episode_path(out, planner, m, s, mover, sensing)
                if p.is_file():
                    rows.append(json.loads(p.read_text()))
        ok = [r for r in rows if r["success"] and r["actions"] <= max_actions]
        actions = [r["actions"] if r["success"] else max_actions for r in rows]
        per_model = {}
        for m in models:
            mine = [r for r in rows if r["true_model"] == m]
            per_model[f"M{m}"] = {
                "n": len(mine),
                "success": sum(r["success"] for r in mine),
                "failures": [
                    {
                        "seed": r["seed"],
                        "identified": r["identified_model"],
                        "actions": r["actions"],
                        "sim_time_s": round(r["sim_time_s"], 1),
                        "reached_0.95": reached(r),
                        "final_posterior": [round(p, 3) for p in r["final_posterior"]],
                    }
                    for r in mine
                    if not r["success"]
                ],
            }
        pe = [r["pose_error"] for r in rows if r["pose_error"]["translation_m"] is not None]
        summary["planners"][planner] = {
            "episodes": len(rows),
            "success": len(ok),
            "success_wilson95": list(wilson_interval(len(ok), len(rows))) if rows else None,
            "sensing": sorted({r.get("sensing", "ideal") for r in rows}),
            "actions": _dist(actions),
            "actions_identified": _dist([r["actions"] for r in ok]),
            "sim_time_s": _dist([r["sim_time_s"] for r in rows]),
            "sim_time_identified_s": _dist([r["sim_time_s"] for r in ok]),
            "pose_error_translation_m": _dist([e["translation_m"] for e in pe]),
            "pose_error_rotation_deg": _dist([e["rotation_deg"] for e in pe]),
            "real_time_factor": _dist([r["real_time_factor"] for r in rows if r.get("real_time_factor")]),
            # the loop alone (no start-up, no figures): per wall second, and per CPU second of the episode
            "real_time_factor_wall": _dist(
                [r["real_time_factor_wall"] for r in rows if r.get("real_time_factor_wall")]
            ),
            "real_time_factor_loop_cpu": _dist(
                [r["real_time_factor_loop_cpu"] for r in rows if r.get("real_time_factor_loop_cpu")]
            ),
            "load_avg_1min": _dist([os.getloadavg()[0]] if rows else []),
            "per_model": per_model,
            "episode_keys": sorted((r["true_model"], r["seed"]) for r in rows),
        }
    if "lut" in summary["planners"] and "random" in summary["planners"]:
        both = set(map(tuple, summary["planners"]["lut"]["episode_keys"])) & set(
            map(tuple, summary["planners"]["random"]["episode_keys"])
        )

        def med(planner):
            acts = []
            for m, s in sorted(both):
                r = json.loads(episode_path(out, planner, m, s, mover, sensing).read_text())
                acts.append(r["actions"] if r["success"] else max_actions)
            return statistics.median(acts) if acts else None

        ml, mr = med("lut"), med("random")
        summary["lut_vs_random"] = {
            "paired_episodes": len(both),
            "median_actions_lut": ml,
            "median_actions_random": mr,
            "ratio": None if not mr else ml / mr,
        }
    return summary


def print_table(summary: dict) -> None:
    def f(d, key="median", fmt="{:.2f}"):
        return "-" if d.get("n", 0) == 0 else fmt.format(d[key])

    print()
    seeds = summary["seeds"]
    spent = summary.get("on_spent_seeds")
    on = f"; ON SPENT SEEDS: {spent}, no fresh evidence" if spent else ""
    print(f"split: {summary['split']} (seeds {min(seeds)}-{max(seeds)}, {len(seeds)} seeds{on})")
    print(
        f"{'planner':8s} {'ok/n':>7s} {'Wilson 95 %':>13s} {'actions med [q1,q3] max':>25s} "
        f"{'sim s med [max]':>17s} {'pose err med cm / deg':>22s} {'RTF med':>8s} {'loop/wall':>9s} "
        f"{'loop/cpu':>8s} {'load':>5s}"
    )
    for planner, s in summary["planners"].items():
        a, t = s["actions"], s["sim_time_s"]
        acts = "-" if a["n"] == 0 else f"{a['median']:.1f} [{a['q1']:.1f},{a['q3']:.1f}] {a['max']}"
        sim = "-" if t["n"] == 0 else f"{t['median']:.1f} [{t['max']:.1f}]"
        pe_t, pe_r = s["pose_error_translation_m"], s["pose_error_rotation_deg"]
        pe = "-" if pe_t["n"] == 0 else f"{100 * pe_t['median']:.1f} / {pe_r['median']:.1f}"
        ci = s["success_wilson95"]
        ci = "-" if ci is None else f"[{100 * ci[0]:.1f},{100 * ci[1]:.1f}] %"
        print(
            f"{planner:8s} {s['success']:>3d}/{s['episodes']:<3d} {ci:>13s} {acts:>25s} {sim:>17s} {pe:>22s} "
            f"{f(s['real_time_factor']):>8s} {f(s.get('real_time_factor_wall', {})):>9s} "
            f"{f(s.get('real_time_factor_loop_cpu', {})):>8s} {f(s['load_avg_1min'], fmt='{:.1f}'):>5s}"
        )
        for m, pm in s["per_model"].items():
            for fail in pm["failures"]:
                print(f"    {planner} {m} failed: {fail}")
    if "lut_vs_random" in summary:
        c = summary["lut_vs_random"]
        print(
            f"\nmedian actions lut / random over {c['paired_episodes']} paired episodes: "
            f"{c['median_actions_lut']} / {c['median_actions_random']} = "
            f"{'-' if c['ratio'] is None else format(c['ratio'], '.2f')} (acceptance: <= 0.6)"
        )


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("out/eval_identify"))
    ap.add_argument("--models", type=parse_seeds, default=[0, 1, 2, 3], help="e.g. 0-3 (default)")
    ap.add_argument(
        "--seeds",
        type=parse_seeds,
        default=fresh_report_seeds(IDENTIFY_SEEDS),
        help=f"e.g. 0-9 (the tuning split) or report seeds (default: {IDENTIFY_SEEDS} fresh report seeds, "
        "above every seed in the ledger of spent seeds, lab/data/spent_seeds.toml)",
    )
    ap.add_argument(
        "--sensing",
        default="realistic",
        choices=("realistic", "ideal", "sensors"),
        help="the simulator's sensor errors",
    )
    ap.add_argument("--planners", default="lut,random", help="comma-separated (default lut,random)")
    ap.add_argument("--mover", default="evasive")
    ap.add_argument("--max-actions", type=int, default=8)
    ap.add_argument("--max-time", type=float, default=240.0)
    ap.add_argument(
        "--keep-direction",
        type=float,
        help="the agent's keep_direction ratio (default: the agent's, 0.5; 1 = Eq. (6)'s argmax)",
    )
    ap.add_argument("--jobs", type=int, default=1, help="episodes run side by side (default 1)")
    ap.add_argument("--scheduler", help="a Dask scheduler's address (tcp://HOST:8786), or 'local'")
    ap.add_argument("--report-only", action="store_true", help="summarise the JSONs already in --out")
    ap.add_argument(
        "--allow-spent-seeds",
        action="store_true",
        help="run even on report seeds the ledger lists as spent (refused otherwise); the report says so",
    )
    return ap


def main(argv=None) -> int:
    try:  # a malformed ledger, or a spent seed: one line
        args = build_parser().parse_args(argv)
        check_report_seeds(args.seeds, allow_spent=args.allow_spent_seeds or args.report_only)
    except ConfigError as e:
        print(f"eval_identify: error: {e}", file=sys.stderr)
        return 2
    planners = [p for p in args.planners.split(",") if p]
    if not args.report_only:
        run_episodes(args, planners)  # failed episodes are listed by it; --resume-like reruns retry them
    summary = summarise(
        args.out, planners, args.models, args.seeds, args.max_actions, args.mover, args.sensing
    )
    print_table(summary)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "summary.json").write_text(json.dumps(summary, indent=2))
    print(f"\nsummary: {args.out / 'summary.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
