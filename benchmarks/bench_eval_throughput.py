"""Throughput of ``lab eval``: a 40-job identification sweep on 1 and 2 local workers (the speed-up
ratio), the same sweep through a local Dask cluster of 2 workers (the Dask path's overhead per job
against the local pool), and the per-job overhead of each engine on empty jobs, all measured side by
side in one run.

The sweep's jobs are real but cheap identification episodes (``lab eval identify``: models 0-3 x ten
seeds of the tuning split, the circle planner, a static box, one planning action, 4 s of simulated
time, ideal sensing); each sweep is timed from the command's start to its end (worker start-up
included, as a user waits for it) and every job's JSON is checked to be the same in the three sweeps
(timings aside). The empty-job overhead is the median over ``--rounds`` rounds (alternating engines) of
the makespan of ``--empty`` jobs that return at once, divided by their number.

Run (about 6-10 minutes on a quiet 2-core machine)::

    nice .venv/bin/python benchmarks/bench_eval_throughput.py [--seeds 0-9] [--rounds 3]

On a shared machine the 1 -> 2 worker ratio is bounded by the other processes' load: the script prints
the load average before and after.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

from lab.cli import main as lab
from lab.eval.executor import DaskExecutor, Job, LocalPool

SWEEP = ["--models", "0-3", "--planners", "circle", "--movers", "static", "--max-actions", "1",
         "--max-time", "4", "--sensing", "ideal"]  # fmt: skip
VOLATILE = ("wall_time_s", "cpu_time_s", "real_time_factor", "real_time_factor_cpu", "loop_wall_time_s",
            "loop_cpu_time_s", "real_time_factor_wall", "real_time_factor_loop_cpu")  # fmt: skip


def _jobs(out: Path) -> dict:
    got = {}
    for p in sorted((out / "jobs").glob("*.json")):
        d = {k: v for k, v in json.loads(p.read_text()).items() if k not in VOLATILE}
        d["decisions"] = [{k: v for k, v in x.items() if k != "elapsed_s"} for x in d.get("decisions", [])]
        got[p.stem] = d
    return got


def _sweep(out: Path, seeds: str, engine: list[str]) -> tuple[float, list[float]]:
    """Wall time [s] of the whole ``lab eval identify`` command; the jobs' own wall times."""
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):
        rc = lab(["eval", "identify", *SWEEP, "--seeds", seeds, *engine, "--out", str(out)])
    wall = time.perf_counter() - t0
    if rc != 0:
        raise SystemExit(f"the sweep on {engine} failed (exit {rc}): see {out}/failed/")
    walls = [float(line.split(",")[-2]) for line in (out / "results.csv").read_text().splitlines()[1:]]
    return wall, walls


def _empty_makespan(ex, n: int) -> float:
    jobs = [Job(f"empty{i}", dict, {"i": i}) for i in range(n)]
    t0 = time.perf_counter()
    got = list(ex.run(jobs))
    dt = time.perf_counter() - t0
    assert sorted(o.result["i"] for o in got) == list(range(n)) and not any(o.error for o in got)
    return dt


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0-9", help="seeds of the sweep (x 4 models; default 0-9: 40 jobs)")
    ap.add_argument("--rounds", type=int, default=3, help="rounds of the empty-job measurement")
    ap.add_argument("--empty", type=int, default=200, help="empty jobs per round")
    args = ap.parse_args()
    print(f"CPUs {os.cpu_count()}; load average before {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        runs = {
            "local pool, 1 worker": ["--workers", "1"],
            "local pool, 2 workers": ["--workers", "2"],
            "Dask local cluster, 2 workers": ["--scheduler", "local", "--workers", "2"],
        }
        res = {}
        for i, (name, engine) in enumerate(runs.items()):
            res[name] = _sweep(tmp / f"s{i}", args.seeds, engine)
            print(f"  {name}: {res[name][0]:.1f} s", flush=True)
        outs = [_jobs(tmp / f"s{i}") for i in range(len(runs))]
        n = len(outs[0])
        same = all(o == outs[0] for o in outs[1:])
        print(f"\n{n}-job sweep (lab eval identify {' '.join(SWEEP)} --seeds {args.seeds})")
        print(f"{'engine':32s} {'sweep s':>8s} {'jobs/min':>8s} {'median job s':>12s}")
        for name, (wall, walls) in res.items():
            print(f"{name:32s} {wall:8.1f} {60 * n / wall:8.2f} {statistics.median(walls):12.2f}")
        one, two, dask = (res[k][0] for k in runs)
        print(f"speed-up 1 -> 2 local workers: {one / two:.2f}")
        print(f"Dask path against the local pool (2 workers): {(dask - two) / n:+.2f} s per job "
              f"(sweep {dask / two:.2f}x)")  # fmt: skip
        print(f"every job's result the same in the three sweeps: {'yes' if same else 'NO'}")

    # the engines' own cost per job: empty jobs, rounds alternating, each engine started once
    pool = LocalPool(2, job_timeout_s=None)
    dask_ex = DaskExecutor(workers=2, job_timeout_s=None)
    try:
        _empty_makespan(pool, 4), _empty_makespan(dask_ex, 4)  # warm: workers started, imports done
        t = {"local pool": [], "Dask": []}
        for _ in range(args.rounds):
            t["local pool"].append(_empty_makespan(pool, args.empty) / args.empty)
            t["Dask"].append(_empty_makespan(dask_ex, args.empty) / args.empty)
    finally:
        dask_ex.close()
    lp, dk = statistics.median(t["local pool"]), statistics.median(t["Dask"])
    print(f"\nempty jobs ({args.empty} per round, {args.rounds} rounds, 2 workers), median per job:")
    print(
        f"  local pool {1000 * lp:.2f} ms (it starts its workers per run: included), Dask {1000 * dk:.2f} ms"
    )
    print(f"load average after {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
