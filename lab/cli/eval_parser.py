"""The ``lab eval`` command's arguments (its sweeps: identify, search; and ``spend``), and where a sweep's
independent jobs run (``--workers``, ``--scheduler``: shared with ``lab grade``)."""

from __future__ import annotations

import argparse
from pathlib import Path

__all__ = ["add_eval_parser", "executor_arguments"]


def executor_arguments(p: argparse.ArgumentParser) -> None:
    """Where independent jobs run: ``--workers N`` local processes, or ``--scheduler`` (Dask)."""
    p.add_argument("--workers", type=int, help="worker processes on this machine (default 1)")
    p.add_argument(
        "--scheduler",
        help="a Dask scheduler's address (tcp://HOST:8786, from `dask scheduler`), or 'local' for a local "
        "Dask cluster of --workers processes (needs pip install 'lab[cluster]')",
    )
    p.add_argument(
        "--job-timeout",
        type=float,
        default=3600.0,
        metavar="SECONDS",
        help="a job still running after this wall time is stopped and recorded as failed (default 3600)",
    )


def _sweep_run_arguments(p: argparse.ArgumentParser) -> None:
    """The output and the executor of a ``lab eval`` sweep."""
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--resume", action="store_true", help="run only the jobs without a result in --out")
    executor_arguments(p)
    p.add_argument("--retries", type=int, default=0, help="Dask re-runs a job that raised this often")
    p.add_argument(
        "--allow-spent-seeds",
        action="store_true",
        help="run even on report seeds the ledger lists as spent (lab/data/spent_seeds.toml; refused "
        "otherwise); the report then says 'on spent seeds'. Tuning seeds (< 1000) are never refused",
    )


def add_eval_parser(sub) -> None:
    """``lab eval identify|search|spend`` on the ``lab`` command's subparsers ``sub``."""
    ev = sub.add_parser(
        "eval",
        help="run an evaluation sweep (seeded episodes) on a process pool or a Dask cluster",
        description="Run a grid of seeded episodes (identify: models x seeds x planners x movers x sensing x "
        "error scales; search: objects x placements x seeds x strategies x obstacles x sensing x error "
        "scales x localization), locally "
        "(--workers N processes) or on a Dask cluster (--scheduler tcp://HOST:8786, or 'local' for a local "
        "one); writes OUT/jobs/KEY.json per job as it finishes, OUT/results.csv and OUT/report.md. Report "
        "seeds the ledger lists as spent are refused (--allow-spent-seeds); `lab eval spend` records "
        "new ones.",
    )
    evs = ev.add_subparsers(dest="eval_command", metavar="SWEEP", required=True)
    ei = evs.add_parser("identify", help="identification episodes (`lab identify`)")
    ei.add_argument("--sweep", type=Path, help="a TOML file with the grid (flags given here override it)")
    ei.add_argument("--models", help="true models, e.g. 0-3 (default) or 0,2")
    ei.add_argument(
        "--seeds",
        help="e.g. 0-9 (tuning) or report seeds (default: 25 fresh report seeds, above every seed in the "
        "ledger of spent seeds; a spent one is refused without --allow-spent-seeds)",
    )
    ei.add_argument("--planners", help="comma-separated: lut, mc, random, circle (default lut,random)")
    ei.add_argument("--movers", "--mover", dest="movers", help="comma-separated (default evasive)")
    ei.add_argument(
        "--sensing",
        help="comma-separated: realistic, ideal, sensors, or sensing files (.toml with a [sensing] table, "
        "as `lab search --sensing` reads) (default realistic)",
    )
    ei.add_argument(
        "--localization",
        help="comma-separated: odometry, landmarks (default odometry, as `lab identify`)",
    )
    ei.add_argument("--max-actions", type=int, help="planning actions budget per episode (default 8)")
    ei.add_argument("--max-time", type=float, help="sim-time budget per episode [s] (default 240)")
    ei.add_argument("--keep-direction", type=float, help="the agent's keep_direction (default 0.5)")
    ei.add_argument(
        "--error-scale",
        help="comma-separated scales of every error of the sensing profile, e.g. 1,2,3 (default 1): the "
        "report's robustness curve, success against scale with Wilson intervals (report.md, robustness.png)",
    )
    _sweep_run_arguments(ei)
    es = evs.add_parser("search", help="search trials (`lab search`)")
    es.add_argument("--sweep", type=Path, help="a TOML file with the grid (flags given here override it)")
    es.add_argument("--objects", help="comma-separated (default cereal_box,book,toy_block)")
    es.add_argument("--surfaces", help="placements: a subset of floor,table,shelf (default all three)")
    es.add_argument(
        "--seeds",
        help="e.g. 0-1 (tuning) or report seeds (default: 2 fresh report seeds, above every seed in the "
        "ledger of spent seeds; a spent one is refused without --allow-spent-seeds)",
    )
    es.add_argument(
        "--strategies", help="comma-separated: paper, rate, lawnmower, frontier (default all four)"
    )
    es.add_argument("--obstacles", help="no, yes, both or half (each placement once, every other with them)")
    es.add_argument(
        "--sensing",
        help="comma-separated: realistic, ideal, sensors, or sensing files (.toml with a [sensing] table, "
        "as `lab search --sensing` reads) (default realistic)",
    )
    es.add_argument("--localization", help="comma-separated: landmarks, odometry (default landmarks)")
    es.add_argument("--max-time", type=float, help="sim-time budget per trial [s] (default 600)")
    es.add_argument("--max-wall-time", type=float, help="the trial's own wall-clock cap [s] (default none)")
    es.add_argument(
        "--moving",
        choices=("random", "evasive"),
        help="the object moves (floor placements, or --surfaces floor,table: on a table's top too): each "
        "trial runs with the map's prediction step and with the static-map baseline",
    )
    es.add_argument(
        "--object-speed", type=float, help="with --moving: the object's speed [m/s] (default 0.1)"
    )
    es.add_argument("--pause", type=float, help="with --moving: its pause after each leg [s] (default 5)")
    es.add_argument(
        "--maps",
        help="with --moving: comma-separated maps to run, predict (the prediction step) and static (the "
        "baseline) (default both; add the other later with --resume in the same --out)",
    )
    es.add_argument(
        "--error-scale",
        help="comma-separated scales of every error of the sensing profile, e.g. 1,2,3 (default 1): the "
        "report's robustness curve, success against scale with Wilson intervals (report.md, robustness.png)",
    )
    es.add_argument(
        "--survey-tour",
        action="store_true",
        default=None,
        help="before each search, a survey tour that ties the surveyed map's posters together (`lab search "
        "--survey-tour`); its jobs are keyed apart (_tour)",
    )
    es.add_argument(
        "--survey-once",
        action="store_true",
        default=None,
        help="survey each seed's room once (`lab survey`, kept in OUT/surveys/) and start every search of "
        "that room from it (`lab search --survey`); its jobs are keyed apart (_surveyed)",
    )
    _sweep_run_arguments(es)
    sp = evs.add_parser(
        "spend",
        help="record report seeds as spent in the ledger (lab/data/spent_seeds.toml)",
        description="Append to the ledger of spent report seeds: seeds looked at to decide anything, or "
        "reported on, are spent, and `lab eval` refuses them afterwards unless --allow-spent-seeds. The "
        "file is written through a temporary file and a rename; commit it.",
    )
    sp.add_argument("seeds", help="the report seeds, e.g. 101300-101304 or 101300,101302")
    sp.add_argument("--why", required=True, help="what looking at them decided, or what was reported")
    sp.add_argument("--runs", default="search", help="comma-separated runs that used them (default search)")
    sp.add_argument("--commit", help="the commit the decision or report was made at")
    sp.add_argument("--source", help="where it is written down (a closing note, docs/tuning/*.md)")
    sp.add_argument("--ledger", type=Path, help="another ledger file (default: the package's)")
