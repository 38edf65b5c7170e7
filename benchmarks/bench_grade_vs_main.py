"""Wall time of ``lab grade`` on a reference solution, this checkout against another (issue 48: the
seccomp filter, the capped tmpfs and the bounded frames may cost at most 1.3x what grading took before).

For each isolation mode and assignment it runs ``lab grade ASSIGNMENT assignments/ASSIGNMENT --json``
with this checkout's ``lab`` and with the other checkout's (its own venv and its own assignments),
round by round, alternating which goes first (so that neither gets a warmer machine), after one untimed
run of each; then prints both medians of the command's wall time and of ``execution_time`` in
results.json (the grading alone, without the interpreter's start), and the ratios. Needs root and
bubblewrap for both modes.

Run: ``python benchmarks/bench_grade_vs_main.py [--other /work/main] [--rounds N] [--assignments stereo,ekf]
[--modes bwrap,uid]``
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

HERE = Path(__file__).resolve().parent.parent


def _grade(checkout: Path, assignment: str, mode: str, out: Path) -> tuple[float, float, float]:
    """(wall time, execution_time, score) of one ``lab grade`` of the reference in ``checkout``."""
    lab = checkout / ".venv" / "bin" / "lab"
    env = dict(os.environ, LAB_GRADE_SANDBOX=mode)
    cmd = [
        str(lab),
        "grade",
        assignment,
        str(checkout / "assignments" / assignment),
        "--json",
        str(out),
        "--quiet",
    ]
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, env=env, cwd=out.parent, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    data = json.loads(out.read_text())
    return wall, float(data["execution_time"]), float(data["score"])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--other", default="/work/main", help="the checkout to compare with (its own .venv)")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--assignments", default="stereo,ekf")
    ap.add_argument("--modes", default="bwrap,uid")
    args = ap.parse_args(argv)
    sides = {"this": HERE, "other": Path(args.other).resolve()}
    print(f"this = {sides['this']}, other = {sides['other']}; {args.rounds} rounds")
    print(
        f"{'mode':<6} {'assignment':<10} {'other [s]':>9} {'this [s]':>9} {'ratio':>6}   grading only: "
        f"{'other':>6} {'this':>6} {'ratio':>6}  scores"
    )
    worst = 0.0
    with tempfile.TemporaryDirectory(prefix="lab-bench-") as tmp:
        out = Path(tmp) / "results.json"
        for mode in args.modes.split(","):
            for name in args.assignments.split(","):
                for side in sides.values():  # untimed: warms the caches and the mode's probe
                    _grade(side, name, mode, out)
                wall: dict[str, list[float]] = {k: [] for k in sides}
                inner: dict[str, list[float]] = {k: [] for k in sides}
                scores: dict[str, set[float]] = {k: set() for k in sides}
                for r in range(args.rounds):
                    for k in list(sides) if r % 2 == 0 else list(reversed(sides)):
                        w, e, s = _grade(sides[k], name, mode, out)
                        wall[k].append(w)
                        inner[k].append(e)
                        scores[k].add(s)
                mw = {k: statistics.median(v) for k, v in wall.items()}
                me = {k: statistics.median(v) for k, v in inner.items()}
                ratio, ratio_e = mw["this"] / mw["other"], me["this"] / me["other"]
                worst = max(worst, ratio)
                print(
                    f"{mode:<6} {name:<10} {mw['other']:>9.2f} {mw['this']:>9.2f} {ratio:>6.2f}   "
                    f"{'':>14}{me['other']:>6.2f} {me['this']:>6.2f} {ratio_e:>6.2f}  {scores}",
                    flush=True,
                )
    print(f"largest ratio this/other (wall time): {worst:.2f} (target: no more than 1.3)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
