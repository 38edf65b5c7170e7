"""Localization against the room: odometry alone vs the landmark EKF on seeded ~30 m drives.

Run from the repository root (long: about 15 s of CPU per drive and mode)::

    nice python benchmarks/bench_localization.py [--seeds 0-19] [--length 30] \
        [--sensing realistic] [--figure out/localization.png] [--json out/localization.json]

Each seed drives the same seeded loop through the lab room
(:func:`lab.runs.localization.run_localization_drive`) twice: once on odometry alone, once localized
against the posters. Printed: the median final position and heading error of each (with the 25-75 %
range), the localizer's NEES (its error against the truth weighted by its own covariance) after every
accepted update and the fraction inside the chi-square(3) 95 % band [0.216, 9.35], and the number of
updates and rejected observations.

**Which seeds.** By default 20 fresh report seeds (:func:`lab.evaluation.fresh_report_seeds`: above every
seed in the ledger of spent seeds, ``lab/data/spent_seeds.toml``); tune on seeds < 1000. A report seed
the ledger lists as spent (the drives' former default, 100000-100019, is) is refused unless
``--allow-spent-seeds``, and the summary then says "ON SPENT SEEDS".
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time

import numpy as np
from scipy.stats import chi2

from lab.errors import ConfigError
from lab.evaluation import (
    ALLOW_SPENT_FLAG,
    check_report_seeds,
    fresh_report_seeds,
    parse_seeds,
    seed_ranges_text,
    split_of,
    wilson_interval,
)
from lab.io import write_text_atomic
from lab.runs.localization import run_localization_drive


def _q(values, q):
    return float(np.percentile(np.asarray(values, float), q))


DRIVE_SEEDS = 20  #: the default: this many fresh report seeds
RUN = "localization drives"  #: the ledger's name of these runs


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--seeds",
        type=parse_seeds,
        default=fresh_report_seeds(DRIVE_SEEDS),
        help=f"seed list, e.g. 0-19 (tuning) or report seeds (default: {DRIVE_SEEDS} fresh report seeds, "
        f"above every seed in the ledger of spent seeds; a spent one is refused without {ALLOW_SPENT_FLAG})",
    )
    ap.add_argument("--length", type=float, default=30.0, help="drive length [m]")
    ap.add_argument("--sensing", default="realistic")
    ap.add_argument("--figure", default=None, help="write a figure of the first seed's trajectories")
    ap.add_argument("--json", default=None, help="write the per-seed figures as JSON")
    ap.add_argument(
        ALLOW_SPENT_FLAG,
        action="store_true",
        help="run even on report seeds the ledger lists as spent (refused otherwise); the summary says so",
    )
    return ap


def main(argv=None) -> int:
    try:  # a malformed ledger or seed list, or a spent seed: one line
        args = build_parser().parse_args(argv)
        spent = check_report_seeds(args.seeds, allow_spent=args.allow_spent_seeds, run=RUN)
    except ConfigError as e:
        print(f"bench_localization: error: {e}", file=sys.stderr)
        return 2
    on = f"; ON SPENT SEEDS: {seed_ranges_text(spent)}, no fresh evidence" if spent else ""
    print(f"split: {split_of(args.seeds)} ({seed_ranges_text(args.seeds)}{on})", flush=True)
    drive(args, args.seeds)
    return 0


def drive(args, seeds) -> None:
    """The drives and their summary (see the module docstring)."""
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
    sys.exit(main())
