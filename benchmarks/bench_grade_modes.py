"""Wall time of grading one submission in the uid isolation mode against bubblewrap (issue 47: the uid
mode, for a root grader where namespaces are forbidden, may cost at most 1.5x bubblewrap).

For each assignment it grades the reference solution round by round, alternating the two modes in one
process (so that neither gets a warmer machine), after one untimed run of each (the graded tests'
import and the mode's probe), then prints both medians and their ratio. Needs root and bubblewrap.

Run: ``python benchmarks/bench_grade_modes.py [--rounds N] [--assignments ekf,stereo] [--jobs J]``
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

from lab.grading import get_assignment, grade_submission
from lab.grading.isolation import SandboxUnavailable, find_sandbox


def _mode(choice: str):
    os.environ["LAB_GRADE_SANDBOX"] = choice
    try:
        return find_sandbox()
    finally:
        del os.environ["LAB_GRADE_SANDBOX"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--assignments", default="stereo,ekf")
    ap.add_argument("--jobs", type=int, default=None, help="tests at once (default: as lab grade)")
    args = ap.parse_args(argv)
    try:
        modes = {"bwrap": _mode("bwrap"), "uid": _mode("uid")}
    except SandboxUnavailable as e:
        print(f"bench_grade_modes: needs both modes (root and bubblewrap): {e}", file=sys.stderr)
        return 1
    print(f"modes: bwrap = {modes['bwrap'].kind}, uid = {modes['uid'].kind}; {args.rounds} rounds")
    print(f"{'assignment':<10} {'bwrap [s]':>10} {'uid [s]':>10} {'uid/bwrap':>10}  scores")
    worst = 0.0
    for name in args.assignments.split(","):
        a = get_assignment(name)
        times: dict[str, list[float]] = {k: [] for k in modes}
        scores: dict[str, set[float]] = {k: set() for k in modes}
        for sb in modes.values():  # untimed: imports the graded tests, warms the caches
            grade_submission(a, a.module_path, sandbox=sb, jobs=args.jobs)
        for r in range(args.rounds):
            order = list(modes) if r % 2 == 0 else list(reversed(modes))
            for k in order:
                t0 = time.perf_counter()
                rep = grade_submission(a, a.module_path, sandbox=modes[k], jobs=args.jobs)
                times[k].append(time.perf_counter() - t0)
                scores[k].add(rep.score)
        med = {k: statistics.median(v) for k, v in times.items()}
        ratio = med["uid"] / med["bwrap"]
        worst = max(worst, ratio)
        print(f"{name:<10} {med['bwrap']:>10.2f} {med['uid']:>10.2f} {ratio:>10.2f}  {scores}")
    print(f"largest ratio uid/bwrap: {worst:.2f} (target: no more than 1.5)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
