"""Localization against the room: odometry alone vs the landmark EKF on seeded ~30 m drives.

Run from the repository root (long: about 15 s of CPU per drive and mode)::

    nice python benchmarks/bench_localization.py [--seeds 100000-100019] [--length 30] \
        [--sensing realistic] [--figure out/localization.png] [--json out/localization.json]

Each seed drives the same seeded loop through the lab room
(:func:`lab.runs.localization.run_localization_drive`) twice: once on odometry alone, once localized
against the posters. Printed: the median final position and heading error of each (with the 25-75 %
range), the localizer's NEES (its error against the truth weighted by its own covariance) after every
accepted update and the fraction inside the chi-square(3) 95 % band [0.216, 9.35], and the number of
updates and rejected observations. The default seeds are the report split
(:func:`lab.evaluation.report_seeds`); tune on seeds < 1000.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

import numpy as np
from scipy.stats import chi2

from lab.evaluation import parse_seeds, report_seeds, wilson_interval
from lab.io import write_text_atomic
from lab.runs.localization import run_localization_drive


def _q(values, q):
    return float(np.percentile(np.asarray(values, float), q))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default=None, help="seed list, e.g. 0-19 (default: 20 report seeds)")
    ap.add_argument("--length", type=float, default=30.0, help="drive length [m]")
    ap.add_argument("--sensing", default="realistic")
    ap.add_argument("--figure", default=None, help="write a figure of the first seed's trajectories")
    ap.add_argument("--json", default=None, help="write the per-seed figures as JSON")
    args = ap.parse_args()
    seeds = parse_seeds(args.seeds) if args.seeds else report_seeds(20)
    lo, hi = chi2.ppf(0.025, 3), chi2.ppf(0.975, 3)
    rows, nees_all, first = [], [], None
    t0 = time.perf_counter()
    for s in seeds:
        odo = run_localization_drive(s, "odometry", args.length, args.sensing)
        loc = run_localization_drive(s, "landmarks", args.length, args.sensing)
        first = first or (odo, loc)
        nees_all.extend(loc.nees.tolist())
        inband = float(np.mean((loc.nees >= lo) & (loc.nees <= hi))) if len(loc.nees) else float("nan")
        rows.append(
            {
                "seed": s,
                "path_m": round(loc.path_length_m, 2),
                "odometry_error_m": round(odo.odometry_error_m, 4),
                "odometry_heading_error_deg": round(odo.odometry_heading_error_deg, 3),
                "localization_error_m": round(loc.localization_error_m, 4),
                "localization_heading_error_deg": round(loc.localization_heading_error_deg, 3),
                "updates": loc.n_updates,
                "rejected": loc.n_rejected,
                "nees_in_band": round(inband, 3),
                "sigma_xy_m": round(loc.sigma_xy_m, 4),
            }
        )
        print(json.dumps(rows[-1]), flush=True)
    n = len(rows)

    def med(k):
        v = [r[k] for r in rows]
        return f"{statistics.median(v):.4g} (25-75 %: {_q(v, 25):.4g}-{_q(v, 75):.4g})"

    nees = np.asarray(nees_all)
    k_in = int(np.sum((nees >= lo) & (nees <= hi)))
    ok_pos = sum(
        r["localization_error_m"] <= 0.03 and r["localization_heading_error_deg"] <= 1.0 for r in rows
    )
    print(
        f"\n{n} drives of {args.length:g} m, sensing {args.sensing}, seeds {seeds[0]}..{seeds[-1]}, "
        f"{time.perf_counter() - t0:.0f} s"
    )
    print(f"path length [m]                  {med('path_m')}")
    print(f"odometry final error [m]         {med('odometry_error_m')}")
    print(f"odometry final heading [deg]     {med('odometry_heading_error_deg')}")
    print(f"localizer final error [m]        {med('localization_error_m')}")
    print(f"localizer final heading [deg]    {med('localization_heading_error_deg')}")
    w = wilson_interval(ok_pos, n)
    print(f"drives within 3 cm and 1 deg     {ok_pos}/{n} (Wilson 95 %: {w[0]:.2f}-{w[1]:.2f})")
    wn = wilson_interval(k_in, max(len(nees), 1))
    print(
        f"NEES in the 95 % band            {k_in}/{len(nees)} = {k_in / max(len(nees), 1):.3f} "
        f"(Wilson 95 %: {wn[0]:.3f}-{wn[1]:.3f}); median NEES {np.median(nees):.2f} (chi2(3) median 2.37)"
    )
    print(
        f"updates per drive                {med('updates')}; "
        f"rejected {sum(r['rejected'] for r in rows)} in all"
    )
    if args.json:
        write_text_atomic(
            args.json,
            json.dumps(
                {"seeds": seeds, "length_m": args.length, "sensing": args.sensing, "rows": rows}, indent=1
            ),
        )
    if args.figure and first is not None:
        from lab.viz.localization import drive_figure

        drive_figure(first[0], first[1], args.figure)
        print(f"figure -> {args.figure}")


if __name__ == "__main__":
    main()
