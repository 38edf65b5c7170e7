"""The issue's acceptance for class grading: a generated class of 20 submissions (for each assignment the
reference solution, the untouched template and every seeded bug of ``tests/grade_cases.py``), graded
with ``lab grade all CLASS/`` on this machine (``--batch``), through a local pool (``--workers N``) and
through a real Dask cluster (``LocalCluster(processes=True)``, via ``--scheduler``): are the CSV and
every results.json the same (timings aside: each test's duration, the whole run's, and the time left in
a submission's budget that a test cut short by it quotes)? Prints the wall time of each, measured one
after the other.

Run: ``nice .venv/bin/python benchmarks/grade_class_dask.py [--workers 2] [--timeout-scale 3]``
"""

from __future__ import annotations

import argparse
import json
import os
import re
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))  # the kept wrong submissions

from grade_cases import make_class  # noqa: E402

from lab.cli import main as lab  # noqa: E402

# a test cut short by the submission's time budget quotes the time that was left: a wall-clock figure
_LEFT = re.compile(r"within this test's limit of [0-9.]+ s")


def _results(each: Path) -> dict:
    """Every results.json without what measures the machine (the timings, the time left)."""
    out = {}
    for p in sorted(each.glob("*/*.json")):
        d = json.loads(p.read_text())
        d.pop("execution_time")
        for t in d["tests"]:
            t["extra_data"].pop("duration_s")
            t["output"] = _LEFT.sub("within this test's limit of (time left) s", t["output"])
        out[f"{p.parent.name}/{p.name}"] = d
    return out


def _diff(a, b) -> str:
    if a is None or b is None:
        return "missing on one side"
    out = [f"{k}: {a[k]!r} / {b[k]!r}" for k in a if k != "tests" and a[k] != b.get(k)]
    for ta, tb in zip(a["tests"], b["tests"], strict=True):
        for k in ta:
            if ta[k] != tb.get(k):
                out.append(f"test {ta['extra_data']['id']} {k}: {str(ta[k])[:200]!r} / {str(tb[k])[:200]!r}")
    return "; ".join(out)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=2, help="local pool and Dask workers (default 2)")
    ap.add_argument(
        "--timeout-scale",
        default="1",
        help="lab grade's --timeout-scale for all three (a loaded machine: an import that passes its "
        "limit of 10 s in one run and not in another is the load, not the engine)",
    )
    args = ap.parse_args()
    from dask.distributed import LocalCluster

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        klass = tmp / "class"
        students = make_class(klass)
        print(f"{len(students)} submissions; CPUs {os.cpu_count()}; load average {os.getloadavg()[0]:.1f}")
        runs = {
            "this machine (--batch)": ["--batch"],
            f"local pool (--workers {args.workers})": ["--workers", str(args.workers)],
        }
        got, times = {}, {}
        for name, extra in runs.items():
            t0 = time.perf_counter()
            rc = lab(["grade", "all", str(klass), *extra, "--timeout-scale", args.timeout_scale,
                      "--csv", str(tmp / f"{len(got)}.csv"),
                      "--out", str(tmp / f"each{len(got)}"), "--quiet"])  # fmt: skip
            times[name] = time.perf_counter() - t0
            got[name] = (rc, (tmp / f"{len(got)}.csv").read_text(), _results(tmp / f"each{len(got)}"))
        with LocalCluster(
            n_workers=args.workers, threads_per_worker=1, processes=True, dashboard_address=None
        ) as c:
            name = f"Dask cluster of {args.workers} (--scheduler)"
            i = len(got)
            t0 = time.perf_counter()
            rc = lab(["grade", "all", str(klass), "--scheduler", c.scheduler_address,
                      "--timeout-scale", args.timeout_scale, "--csv",
                      str(tmp / f"{i}.csv"), "--out", str(tmp / f"each{i}"), "--quiet"])  # fmt: skip
            times[name] = time.perf_counter() - t0
            got[name] = (rc, (tmp / f"{i}.csv").read_text(), _results(tmp / f"each{i}"))
        ref_name = next(iter(got))
        ref = got[ref_name]
        print(f"{'how':36s} {'exit':>4s} {'wall s':>7s}  same CSV and results.json as {ref_name}")
        for name, (rc, text, res) in got.items():
            same = text == ref[1] and res == ref[2]
            print(f"{name:36s} {rc:4d} {times[name]:7.1f}  {'yes' if same else 'NO'}")
        for name, (_, _text, res) in got.items():  # what differs, if anything
            for f in sorted(set(res) | set(ref[2])):
                a, b = ref[2].get(f), res.get(f)
                if a != b:
                    print(f"  {name}: {f} differs: {_diff(a, b)}")
        totals = [line.rsplit(",", 2)[-2] for line in ref[1].splitlines()[1:]]
        print(f"scores (of {len(totals)} students x 4 assignments): totals {', '.join(totals)}")
        print(f"load average after: {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
