"""Wall time of grading one submission (`lab grade`), per assignment: the reference solution with one
and two tests at a time, the untouched template, and the slowest realistic case (A* that never ends,
which waits out four time limits). Prints medians of a few runs measured side by side, and which
sandbox the children ran in (each test's child starts inside bubblewrap: compare with a checkout from
before the sandbox by running this script from it, interleaved with this one).

Run: ``python benchmarks/bench_grade.py [--repeat N]``
"""

from __future__ import annotations

import argparse
import os
import statistics
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


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
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
