"""Wall time of grading one submission (`lab grade`), per assignment: the reference solution with one
and two tests at a time, the untouched template, and the slowest realistic case (A* that never ends,
which waits out four time limits). Prints medians of a few runs measured side by side, and which
sandbox the children ran in.

``--against DIR`` compares with another checkout of the package (e.g. from before the sandbox:
``git archive COMMIT lab assignments | tar -x -C DIR``): for each assignment it alternates, round by
round, a grading run of this checkout and one of DIR (each in a fresh process, so that both pay the
same start-up and neither gets a warmer machine), and also times the whole ``lab grade`` command, then
prints both medians and their ratio.

Run: ``python benchmarks/bench_grade.py [--repeat N] [--against DIR --rounds R]``
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))  # the kept wrong submissions

from grade_cases import CASES  # noqa: E402

from lab.grading import get_assignment, grade_submission, list_assignments  # noqa: E402
from lab.grading.release import release  # noqa: E402


def _median_time(fn, repeat: int) -> tuple[float, float]:
    times, score = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        report = fn()
        times.append(time.perf_counter() - t0)
        score = 100.0 * report.score / report.max_score
    return statistics.median(times), score


# Runs in a fresh process with one checkout on PYTHONPATH; uses only API that both checkouts have.
_MEASURE = """
import json, sys, tempfile, time
from pathlib import Path
from lab.grading import get_assignment, grade_submission
from lab.grading.release import release
name, kind, jobs, repeat = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
a = get_assignment(name)
with tempfile.TemporaryDirectory() as tmp:
    sub = a.module_path
    if kind == "template":
        release([a], Path(tmp))
        sub = Path(tmp) / name
    grade_submission(a, sub, jobs=jobs)  # not timed: imports the graded tests (and probes the sandbox)
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        r = grade_submission(a, sub, jobs=jobs)
        times.append(time.perf_counter() - t0)
print(json.dumps({"times": times, "score": 100.0 * r.score / r.max_score}))
"""


def _in(checkout: Path, *args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(checkout)}
    env.pop("LAB_ASSIGNMENTS", None)
    return subprocess.run(
        [sys.executable, *args], cwd=checkout, env=env, capture_output=True, text=True, check=True
    )


def _against(other: Path, rounds: int, repeat: int) -> int:
    this = Path(__file__).resolve().parent.parent
    print(f"this checkout: {this}; against: {other}; {rounds} alternating rounds of {repeat} runs each")
    print(f"load average {os.getloadavg()[0]:.1f}; CPUs: {os.cpu_count()}")
    head = f"{'what':32s} {'against':>9s} {'this':>9s} {'ratio':>6s}"
    print(head)
    cases = [
        (a.name, kind, jobs)
        for a in list_assignments()
        for kind, jobs in (("reference", 1), ("reference", 2), ("template", 2))
    ]
    for name, kind, jobs in cases:
        t = {this: [], other: []}
        for _ in range(rounds):
            for checkout in (other, this):
                out = json.loads(_in(checkout, "-c", _MEASURE, name, kind, str(jobs), str(repeat)).stdout)
                assert out["score"] == (100.0 if kind == "reference" else 0.0), (checkout, name, out)
                t[checkout] += out["times"]
        a, b = statistics.median(t[other]), statistics.median(t[this])
        print(f"{f'{name} {kind} j={jobs}':32s} {a:8.2f}s {b:8.2f}s {b / a:6.2f}", flush=True)
    for name in [a.name for a in list_assignments()]:  # the whole command: start-up, sandbox probe, grading
        t = {this: [], other: []}
        for _ in range(rounds * repeat):
            for checkout in (other, this):
                ref = checkout / "assignments" / name
                t0 = time.perf_counter()
                _in(checkout, "-m", "lab", "grade", name, str(ref), "--quiet")
                t[checkout].append(time.perf_counter() - t0)
        a, b = statistics.median(t[other]), statistics.median(t[this])
        print(f"{f'lab grade {name} (reference)':32s} {a:8.2f}s {b:8.2f}s {b / a:6.2f}", flush=True)
    return 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--against", type=Path, help="another checkout to compare with, side by side")
    ap.add_argument("--rounds", type=int, default=3, help="with --against: alternating rounds")
    args = ap.parse_args()
    if args.against:
        return _against(args.against.resolve(), args.rounds, args.repeat)
    try:
        from lab.grading.isolation import find_sandbox

        sandbox = find_sandbox().describe()
    except ImportError:  # before the sandbox existed
        sandbox = "none (resource limits only)"
    print(f"CPUs: {os.cpu_count()}; {args.repeat} runs each; median wall time of one submission")
    print(f"sandbox: {sandbox}; load average {os.getloadavg()[0]:.1f}")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        assignments = list_assignments()
        release(assignments, tmp / "release")
        head = ("assignment", "tests", "reference j=1", "reference j=2", "template")
        print(f"{head[0]:10s} {head[1]:>5s} {head[2]:>14s} {head[3]:>14s} {head[4]:>9s}")
        for a in assignments:
            n = len(a.load_suite().tests)
            r1, s1 = _median_time(lambda a=a: grade_submission(a, a.module_path, jobs=1), args.repeat)
            r2, s2 = _median_time(lambda a=a: grade_submission(a, a.module_path, jobs=2), args.repeat)
            template = tmp / "release" / a.name
            t, st = _median_time(lambda a=a, d=template: grade_submission(a, d, jobs=2), args.repeat)
            assert s1 == s2 == 100.0 and st == 0.0
            print(f"{a.name:10s} {n:5d} {r1:13.2f}s {r2:13.2f}s {t:8.2f}s")
        for case in CASES:
            if case.name not in ("astar_infinite_loop", "crash_on_import"):
                continue
            a = get_assignment(case.assignment)
            d = tmp / case.name
            d.mkdir()
            (d / a.module).write_text(case.source(a.module_path.read_text()))
            w, s = _median_time(lambda a=a, d=d: grade_submission(a, d, jobs=2), 1)
            print(f"{case.name:24s} ({a.name}): {w:.2f}s, score {s:.0f} %")
    return 0


if __name__ == "__main__":
    sys.exit(main())
