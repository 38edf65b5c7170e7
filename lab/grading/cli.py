"""The handlers of ``lab grade`` and ``lab assignments`` (their options are defined in :mod:`lab.cli`)."""

from __future__ import annotations

import sys
from pathlib import Path

from lab.errors import ConfigError
from lab.grading.assignments import Assignment, get_assignment, list_assignments
from lab.grading.isolation import make_grader_private
from lab.grading.limits import clean
from lab.grading.report import GradeReport, write_scores_csv
from lab.grading.runner import choose_sandbox, grade_submission

__all__ = ["run_grade", "run_check_sandbox", "run_assignments"]


def _pick(spec: str, root) -> list[Assignment]:
    if spec == "all":
        return list_assignments(root)
    return [get_assignment(name.strip(), root) for name in spec.split(",") if name.strip()]


def run_check_sandbox(args) -> int:
    """``lab grade --check-sandbox``: try from inside a sandboxed child what a cheating submission would;
    exit 0 when every attempt is stopped, 1 otherwise (or when there is no sandbox)."""
    from lab.grading.sandbox_check import check_sandbox

    ok, lines = check_sandbox(getattr(args, "json", None))
    if not args.quiet:
        print("\n".join(lines))
        print("sandbox active: grading is isolated" if ok else "sandbox NOT active: see the BAD lines above")
    return 0 if ok else 1


def run_grade(args, batch=None) -> int:
    """``lab grade ASSIGNMENT SUBMISSION``: one submission, or a class with ``--batch``.

    ``batch(chosen, folder, args) -> exit status`` grades the class instead of this machine's loop
    (``lab grade ... --workers/--scheduler``: :func:`lab.eval.grade.grade_class`), after the same checks."""
    if getattr(args, "check_sandbox", False):
        return run_check_sandbox(args)
    if args.assignment is None or args.submission is None:
        raise ConfigError("lab grade needs ASSIGNMENT and SUBMISSION (or --check-sandbox)")
    chosen = _pick(args.assignment, args.assignments)
    sub = Path(args.submission)
    if not sub.exists() and not sub.is_symlink():
        raise ConfigError(f"submission {sub} does not exist")
    insecure = getattr(args, "insecure", False)
    if args.batch:
        _check_batch(sub, args)
    elif len(chosen) != 1:
        raise ConfigError("grade one assignment at a time (several, or 'all', only with --batch)")
    sb = choose_sandbox(insecure)  # refuses here, once, before any grading, when there is no sandbox
    if args.batch:
        return (batch or _batch)(chosen, sub, args)
    if args.json and sb.kind == "uid":  # the results' folder: the grader's alone
        make_grader_private([Path(args.json).resolve().parent])
    report = grade_submission(
        chosen[0], sub, jobs=args.jobs, timeout_scale=args.timeout_scale, insecure=insecure
    )
    if args.json:
        report.write_json(args.json)
    if not args.quiet:
        print(report.summary())
        if args.json:
            print(f"wrote {args.json}")
        _warn(sb)
    return 0


def _warn(sb) -> None:
    """What the isolation mode cannot stop, said after grading, not hidden (stderr: not the student's)."""
    for c in sb.cannot_stop:
        print(f"lab grade: WARNING: the {sb.kind} isolation mode cannot stop {c}", file=sys.stderr)


def _check_batch(folder: Path, args) -> None:
    if args.json:
        raise ConfigError(
            "--json is for one submission; with --batch use --csv (and --out for each results.json)"
        )
    if not folder.is_dir():
        raise ConfigError(f"with --batch, {folder} must be a folder with one subfolder per student")


def _batch(chosen: list[Assignment], folder: Path, args) -> int:
    students = sorted(
        p for p in folder.iterdir() if p.is_dir() and not p.is_symlink() and not p.name.startswith(".")
    )
    if not students:
        raise ConfigError(f"{folder} has no student subfolders")
    rows: list[tuple[str, list[GradeReport]]] = []
    if choose_sandbox(getattr(args, "insecure", False)).kind == "uid":
        # the uid mode's children see the filesystem: no student may read a classmate's folder
        make_grader_private([folder, *([Path(args.out)] if args.out else [])])
    for s in students:
        # each student's every test in a sandbox of its own that sees only that student's copy
        reports = [
            grade_submission(
                a,
                s,
                jobs=args.jobs,
                timeout_scale=args.timeout_scale,
                insecure=getattr(args, "insecure", False),
            )
            for a in chosen
        ]
        rows.append((s.name, reports))
        if args.out:
            for rep in reports:
                rep.write_json(Path(args.out) / s.name / f"{rep.assignment.name}.json")
        if not args.quiet:
            parts = ", ".join(f"{r.assignment.name} {r.score:g}/{r.max_score:g}" for r in reports)
            total, top = sum(r.score for r in reports), sum(r.max_score for r in reports)
            secs = sum(r.execution_time_s for r in reports)
            print(f"{clean(s.name, 200)}: {parts}; total {total:g}/{top:g} ({secs:.1f} s)", flush=True)
    csv_path = write_scores_csv(args.csv or folder / "scores.csv", rows)
    if not args.quiet:
        print(f"wrote {csv_path} ({len(rows)} students)")
        _warn(choose_sandbox(getattr(args, "insecure", False)))
    return 0


def run_assignments(args) -> int:
    """``lab assignments list``, ``lab assignments release OUT_DIR [NAME ...]`` and
    ``lab assignments gradescope NAME --out FILE.zip``."""
    from lab.grading.release import release

    if args.action == "gradescope":
        from lab.grading.gradescope import build_bundle

        if args.out_dir is None or args.names:
            raise ConfigError("lab assignments gradescope needs one ASSIGNMENT (and --out FILE.zip)")
        a = get_assignment(str(args.out_dir), args.assignments)
        out = build_bundle(a, args.out or Path("autograder.zip"))
        if not args.quiet:
            print(f"wrote {out}: upload it as the autograder of {a.name} (assignments/README.md)")
        return 0
    if args.action == "list":
        for a in list_assignments(args.assignments):
            suite = a.load_suite()
            print(
                f"{a.name:10s} {a.module:12s} {len(suite.tests):2d} tests {suite.max_score:4g} points  "
                f"{a.title}"
            )
        return 0
    chosen = list_assignments(args.assignments)
    if args.names:
        chosen = [get_assignment(n, args.assignments) for n in args.names]
    folders = release(chosen, args.out_dir, force=args.force)
    for f in folders:
        print(f"released {f}: {', '.join(sorted(p.name for p in f.iterdir()))}")
    print(
        "checked: no solution code, no solution markers, no graded tests",
        file=sys.stderr if args.quiet else sys.stdout,
    )
    return 0
