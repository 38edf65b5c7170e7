"""What the recorded 3D view (``--view3d``, :mod:`lab.viz.view3d`) costs a run, and the page's size.

Run from the repository root::

    python benchmarks/bench_view3d.py [--seed 3] [--max-time 30] [--search-time 90]

One identification episode and one search trial, each run once with the 3D view. The recorder times
itself: the wall time spent inside its observer during the run (``recording_s``) and writing the page at
the end (``writing_s``); both are printed against the run's own wall time (the loop's, from the JSON), so
that the ratio is measured in the same run, undisturbed by how loaded the machine is between two runs.
Printed also: the number of timeline steps and the page's size [MB].
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--max-time", type=float, default=30.0, help="identification: sim seconds")
    ap.add_argument("--search-time", type=float, default=90.0, help="search: sim seconds")
    args = ap.parse_args()
    from lab.runs.identify import run_identify
    from lab.runs.search import navigator_factory, run_search

    out = Path(tempfile.mkdtemp(prefix="bench_view3d_"))
    views = {}

    def keep_identify(agent, carrier):
        views["identify"] = agent.on_step

    res = run_identify(
        1, seed=args.seed, mover="evasive", planner="lut", max_actions=8, max_time_s=args.max_time,
        figures=False, view3d=out / "identify.html", attach=keep_identify,
    )  # fmt: skip
    _report("identify", views["identify"], res["wall_time_s"], out / "identify.html")

    def keep_search(agent):
        views["search"] = agent.observer

    s = run_search(
        "toy_block", args.seed, max_time=args.search_time, navigate=navigator_factory,
        view3d=out / "search.html", attach=keep_search,
    )  # fmt: skip
    _report("search", views["search"], s.wall_time_s, out / "search.html")


def _report(name: str, view, wall_s: float, page: Path) -> None:
    mb = page.stat().st_size / 1e6
    print(
        f"{name:8s} steps {len(view.steps):4d}  run wall {wall_s:7.1f} s  "
        f"recording {view.recording_s:6.2f} s "
        f"({100 * view.recording_s / wall_s:4.1f} %)  writing {view.writing_s:5.2f} s "
        f"({100 * view.writing_s / wall_s:4.1f} %)  page {mb:5.2f} MB"
    )


if __name__ == "__main__":
    main()
