"""The handler of ``lab eval identify`` (its options: :mod:`lab.cli.parser`)."""

from __future__ import annotations

from pathlib import Path

from lab.errors import ConfigError

__all__ = ["run_eval"]


def _ints(v, what: str) -> tuple[int, ...]:
    from lab.evaluation import parse_seeds

    if isinstance(v, list):
        if not all(isinstance(x, int) for x in v):
            raise ConfigError(f"{what} must be integers, got {v!r}")
        return tuple(v)
    return tuple(parse_seeds(str(v)))


def _names(v) -> tuple[str, ...]:
    return tuple(v) if isinstance(v, list) else tuple(s.strip() for s in str(v).split(",") if s.strip())


def identify_sweep(args):
    """The grid from the sweep file (``--sweep``) with the flags given on the command line over it."""
    from lab.eval.sweep import SWEEP_FIELDS, IdentifySweep, load_sweep_file
    from lab.evaluation import report_seeds

    spec = load_sweep_file(args.sweep) if args.sweep else {}
    for name in SWEEP_FIELDS:  # the sweep file's fields are the command line's flags
        v = getattr(args, name)
        if v is not None:
            spec[name] = v
    sw = IdentifySweep(
        models=_ints(spec.get("models", "0-3"), "models"),
        seeds=_ints(spec["seeds"], "seeds") if "seeds" in spec else tuple(report_seeds(25)),
        planners=_names(spec.get("planners", "lut,random")),
        movers=_names(spec.get("movers", "evasive")),
        sensing=_names(spec.get("sensing", "realistic")),
        max_actions=int(spec.get("max_actions", 8)),
        max_time=float(spec.get("max_time", 240.0)),
        keep_direction=spec.get("keep_direction"),
    )
    sw.check()
    return sw


def run_eval(args) -> int:
    from lab.eval.executor import make_executor
    from lab.eval.sweep import print_split, run_sweep

    if args.eval_command != "identify":
        raise ConfigError(f"unknown sweep {args.eval_command!r}; sweeps: identify")
    if args.retries < 0:
        raise ConfigError(f"--retries must be >= 0, got {args.retries}")
    sw = identify_sweep(args)  # every check before anything starts
    jobs = sw.jobs()
    out = Path(args.out)
    if not args.resume and (out / "results.csv").exists():
        raise ConfigError(f"{out} already holds a sweep: --resume to complete it, or another --out")
    print_split(sw.seeds)
    ex = make_executor(args.workers, args.scheduler, args.retries)
    try:
        rows = run_sweep(out, jobs, ex, resume=args.resume, echo=lambda s: print(s, flush=True))
    finally:
        ex.close()
    failed = sum(bool(r["error"]) for r in rows)
    print(
        f"wrote {out / 'results.csv'}, {out / 'report.md'} and {out / 'jobs'}/ ({len(rows)} jobs, "
        f"{failed} failed{': --resume runs them again' if failed else ''})"
    )
    return 1 if failed else 0
