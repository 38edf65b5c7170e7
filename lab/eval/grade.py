"""``lab grade ASSIGNMENTS CLASS/ --workers N | --scheduler ADDRESS``: a class graded through the
executor of ``lab eval`` (:mod:`lab.eval.executor`), one job per student and assignment.

Each job is :func:`grade_job`: the grader itself (:func:`lab.grading.grade_submission`) in the worker,
with everything that makes it safe where it runs: each test in its own sandboxed child (bubblewrap),
its time and memory limits. The worker sends back the results.json it would have written
(:meth:`~lab.grading.report.GradeReport.to_gradescope`), from which the same report is rebuilt here, so
the CSV and the per-student results are those of ``lab grade --batch`` on this machine. The workers
must see the class folder and the assignments at the same paths (a shared file system on a cluster).

A job that fails (its worker died, it passed ``--job-timeout``) costs that student's assignment only:
it is named on stderr, the student is left out of the CSV (a grade is never made up), and the exit
status is 1.
"""

from __future__ import annotations

import sys
from pathlib import Path

from lab.errors import ConfigError
from lab.eval.executor import Job

__all__ = ["grade_class", "grade_job"]


def grade_job(
    assignment: str,
    assignments_root: str | None,
    submission: str,
    jobs: int | None,
    timeout_scale: float,
    insecure: bool,
) -> dict:
    """Grade one submission in this worker: ``{"results": results.json, "error": ...}``."""
    from lab.grading import get_assignment, grade_submission

    a = get_assignment(assignment, assignments_root)
    rep = grade_submission(a, submission, jobs=jobs, timeout_scale=timeout_scale, insecure=insecure)
    return {"results": rep.to_gradescope(), "error": rep.error}


def grade_class(args, chosen, folder: Path, executor) -> int:
    """Grade every student folder of ``folder`` on ``chosen`` assignments through ``executor``; write
    the scores CSV (and ``--out``'s results.json files) as ``lab grade --batch`` does."""
    from lab.grading.report import GradeReport, write_scores_csv

    students = sorted(
        p for p in folder.iterdir() if p.is_dir() and not p.is_symlink() and not p.name.startswith(".")
    )
    if not students:
        raise ConfigError(f"{folder} has no student subfolders")
    root = None if args.assignments is None else str(Path(args.assignments).resolve())
    jobs = [
        Job(
            f"{s.name}:{a.name}",
            grade_job,
            dict(
                assignment=a.name,
                assignments_root=root,
                submission=str(s),
                jobs=args.jobs,
                timeout_scale=args.timeout_scale,
                insecure=bool(getattr(args, "insecure", False)),
            ),
        )
        for s in students
        for a in chosen
    ]
    if not args.quiet:
        print(f"{len(jobs)} submissions ({len(students)} students) to grade on {executor.name}", flush=True)
    by_key = {a.name: a for a in chosen}
    reports: dict[tuple[str, str], GradeReport] = {}
    failed: dict[str, str] = {}
    for o in executor.run(jobs):
        student, name = o.job.key.split(":")
        if o.error is not None:
            failed[o.job.key] = o.error
            print(
                f"{student}: {name} FAILED to grade: {o.error.splitlines()[0]}", file=sys.stderr, flush=True
            )
            continue
        rep = GradeReport.from_gradescope(by_key[name], o.result["results"], o.result["error"])
        reports[(student, name)] = rep
        if args.out:
            rep.write_json(Path(args.out) / student / f"{name}.json")
        if not args.quiet:
            print(
                f"{student}: {name} {rep.score:g}/{rep.max_score:g} ({rep.execution_time_s:.1f} s)",
                flush=True,
            )
    rows = []
    for s in students:
        mine = [reports.get((s.name, a.name)) for a in chosen]
        if all(r is not None for r in mine):
            rows.append((s.name, mine))
    csv_path = write_scores_csv(args.csv or folder / "scores.csv", rows)
    if not args.quiet:
        for name, reps in rows:
            parts = ", ".join(f"{r.assignment.name} {r.score:g}/{r.max_score:g}" for r in reps)
            print(f"{name}: {parts}; total {sum(r.score for r in reps):g}/{sum(r.max_score for r in reps):g}")
        print(f"wrote {csv_path} ({len(rows)} students)")
    if failed:
        left = sorted({k.split(":")[0] for k in failed})
        print(
            f"{len(failed)} submission(s) could not be graded; left out of {csv_path}: {', '.join(left)}",
            file=sys.stderr,
        )
        return 1
    return 0
