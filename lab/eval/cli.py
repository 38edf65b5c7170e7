"""The handlers of ``lab eval identify`` and ``lab eval search`` (their options: :mod:`lab.cli.parser`)."""

from __future__ import annotations

from pathlib import Path

from lab.errors import ConfigError

__all__ = ["IDENTIFY_SEEDS", "SEARCH_SEEDS", "identify_sweep", "run_eval", "search_sweep", "spend"]

IDENTIFY_SEEDS = 25  #: ``lab eval identify``'s default: this many fresh report seeds
SEARCH_SEEDS = 2  #: ``lab eval search``'s default: this many fresh report seeds


def _ints(v, what: str) -> tuple[int, ...]:
    from lab.evaluation import parse_seeds

    if isinstance(v, list):
        if not all(isinstance(x, int) for x in v):
            raise ConfigError(f"{what} must be integers, got {v!r}")
        return tuple(v)
    return tuple(parse_seeds(str(v)))


def _names(v) -> tuple[str, ...]:
    return tuple(v) if isinstance(v, list) else tuple(s.strip() for s in str(v).split(",") if s.strip())


def _sensing(v) -> tuple[str, ...]:
    """``--sensing``'s profiles; a sensing file as an absolute path, so every worker reads the same one."""
    return tuple(str(Path(s).resolve()) if s.endswith(".toml") else s for s in _names(v))


def _spec(args, fields) -> dict:
    """The sweep file's fields (``--sweep``) with the flags given on the command line over them."""
    from lab.eval.sweep import load_sweep_file

    spec = load_sweep_file(args.sweep, fields) if args.sweep else {}
    for name in fields:  # the sweep file's fields are the command line's flags
        v = getattr(args, name)
        if v is not None:
            spec[name] = v
    return spec


def identify_sweep(args):
    """The grid of ``lab eval identify``, checked."""
    from lab.eval.robustness import parse_error_scales
    from lab.eval.sweep import SWEEP_FIELDS, IdentifySweep
    from lab.evaluation import fresh_report_seeds

    spec = _spec(args, SWEEP_FIELDS)
    sw = IdentifySweep(
        models=_ints(spec.get("models", "0-3"), "models"),
        seeds=_ints(spec["seeds"], "seeds") if "seeds" in spec else tuple(fresh_report_seeds(IDENTIFY_SEEDS)),
        planners=_names(spec.get("planners", "lut,random")),
        movers=_names(spec.get("movers", "evasive")),
        sensing=_sensing(spec.get("sensing", "realistic")),
        localization=_names(spec.get("localization", "odometry")),
        max_actions=int(spec.get("max_actions", 8)),
        max_time=float(spec.get("max_time", 240.0)),
        keep_direction=spec.get("keep_direction"),
        error_scale=parse_error_scales(spec.get("error_scale", "1")),
    )
    sw.check()
    return sw


def search_sweep(args):
    """The grid of ``lab eval search``, checked."""
    from lab.eval.robustness import parse_error_scales
    from lab.eval.search import SEARCH_FIELDS, SEARCH_MAX_TIME_S, STRATEGIES, SearchSweep
    from lab.evaluation import fresh_report_seeds

    spec = _spec(args, SEARCH_FIELDS)
    wall = spec.get("max_wall_time")
    sw = SearchSweep(
        objects=_names(spec.get("objects", "cereal_box,book,toy_block")),
        surfaces=_names(spec.get("surfaces", "floor" if spec.get("moving") else "floor,table,shelf")),
        seeds=_ints(spec["seeds"], "seeds") if "seeds" in spec else tuple(fresh_report_seeds(SEARCH_SEEDS)),
        strategies=_names(spec.get("strategies", ",".join(STRATEGIES))),
        obstacles=str(spec.get("obstacles", "both")),
        sensing=_sensing(spec.get("sensing", "realistic")),
        localization=_names(spec.get("localization", "landmarks")),
        max_time=float(spec.get("max_time", SEARCH_MAX_TIME_S)),
        max_wall_time=None if wall is None else float(wall),
        moving=spec.get("moving"),
        object_speed=float(spec.get("object_speed", 0.1)),
        pause=float(spec.get("pause", 5.0)),
        maps=_names(spec.get("maps", "predict,static")),
        error_scale=parse_error_scales(spec.get("error_scale", "1")),
        survey_tour=bool(spec.get("survey_tour", False)),
        survey_once=str(Path(args.out) / "surveys") if spec.get("survey_once") else None,
    )
    sw.check()
    return sw


def spend(args) -> int:
    """``lab eval spend SEEDS --why TEXT``: record report seeds as spent (appended to the ledger)."""
    from lab.evaluation import ledger_path, parse_seeds, record_spending

    path = args.ledger or ledger_path()
    seeds, runs = parse_seeds(args.seeds), _names(args.runs)
    new = record_spending(seeds, args.why, runs, path, commit=args.commit, source=args.source)
    print(f"recorded in {path}: {', '.join(e.label for e in new)} spent ({args.why}); commit the file")
    return 0


def run_eval(args) -> int:
    from lab.eval.executor import make_executor
    from lab.eval.sweep import IDENTIFY, print_split, run_sweep
    from lab.evaluation import check_report_seeds

    if args.eval_command == "spend":
        return spend(args)
    if args.eval_command == "identify":
        sw, kind = identify_sweep(args), IDENTIFY  # every check before anything starts
    elif args.eval_command == "search":
        from lab.eval.search import SEARCH, SEARCH_MOVING

        sw = search_sweep(args)
        kind = SEARCH if sw.moving is None else SEARCH_MOVING
    else:
        raise ConfigError(f"unknown sweep {args.eval_command!r}; sweeps: identify, search, spend")
    if args.retries < 0:
        raise ConfigError(f"--retries must be >= 0, got {args.retries}")
    if args.job_timeout is not None and not args.job_timeout > 0:
        raise ConfigError(f"--job-timeout must be > 0 s, got {args.job_timeout:g}")
    check_report_seeds(sw.seeds, allow_spent=args.allow_spent_seeds, run=args.eval_command)
    jobs = sw.jobs()
    out = Path(args.out)
    if not args.resume and (out / "results.csv").exists():
        raise ConfigError(f"{out} already holds a sweep: --resume to complete it, or another --out")
    print_split(sw.seeds)
    ex = make_executor(args.workers, args.scheduler, args.retries, args.job_timeout)
    try:
        rows = run_sweep(out, jobs, ex, resume=args.resume, echo=lambda s: print(s, flush=True), kind=kind)
    finally:
        ex.close()
    failed = sum(bool(r["error"]) for r in rows)
    print(
        f"wrote {out / 'results.csv'}, {out / 'report.md'} and {out / 'jobs'}/ ({len(rows)} jobs, "
        f"{failed} failed{': --resume runs them again' if failed else ''})"
    )
    return 1 if failed else 0
