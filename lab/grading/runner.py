"""Grade one submission: every graded test in its own child process, scored here.

Isolation (see :mod:`lab.grading.isolation` for the sandbox, :mod:`lab.grading.sandbox` for the
child's side):

* **The student's code runs in a sandbox, as another user.** Each test starts a fresh child inside
  bubblewrap: a filesystem holding only the system, Python and a private copy of the submission (no
  assignments, graded tests, reference solutions, other students' folders or grader files), no
  network, its own PID namespace, and (when the grader is root) a throwaway uid of its own. Where
  namespaces are forbidden (a root grader in Docker, as on Gradescope), the ``uid`` mode gives the
  child a throwaway uid and a private folder instead, and makes the grader's folders private (see
  :mod:`lab.grading.isolation` for what it cannot stop). The grading process is not dumpable, so no
  process can read or write its memory.
* **The submission is read once, as a regular file.** Its bytes are read when grading starts (a
  classmate changing the file later changes nothing); a symbolic link, a device or a folder where the
  module is expected is refused with a message.
* **The scoring process never imports the submission.** The child imports its copy under a memory
  limit (``RLIMIT_AS``), a CPU-time backstop, no file writes (``RLIMIT_FSIZE = 0``) and no new
  processes. The test itself (the oracle, the tolerances, the points) runs here and reaches the
  student's functions only through :class:`Submission`, whose calls come back as *values*.
* **The channel is private.** Calls and answers go over two pipes opened for that child alone; the
  child's stdout and stderr are captured as text for the feedback and never parsed, so printing fake
  results does nothing. A malformed answer is a failed call.
* **Nothing the child sends is a score.** At worst a hostile child sends wrong values for its own
  functions, which is what it is graded on.
* **The assignment's rules hold.** The child refuses every import ``assignment.toml`` does not allow,
  and the graded tests' oracles (networkx, SciPy, OpenCV, ``lab``) are neither loaded there nor
  readable (:mod:`lab.grading.rules`). What it refused is recorded as it happens on a pipe the grader
  reads, so the student's code cannot erase it (:mod:`lab.grading.records`).
* **The grader imports nothing of the submission's.** A submission folder on the grader's own import
  path is refused (``python -m lab`` keeps the working directory off it: :mod:`lab`).
* **Nothing outlives its test.** Before a test's result is recorded, every process it started is gone
  (the sandbox's PID namespace is killed and, as root, every process of its uid), so nothing can
  rewrite results after the grader.
* **Limits cost points, not the grading run.** An exception, a timeout, running out of memory, a
  crash, wrong shapes or NaNs fail that test with a message; the next test starts a new child. A
  module that fails to import fails every test with the same message, found once by a first import
  probe. A total time budget bounds the whole run.

Without a working sandbox :func:`grade_submission` refuses (``SandboxUnavailable``) unless asked to
grade insecurely, and then every result says so.
"""

from __future__ import annotations

import os
import stat
import time
import traceback
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from lab.grading.assignments import Assignment
from lab.grading.child import (
    ChildLimits,
    ImportFailed,
    StudentCrash,
    StudentError,
    StudentTimeout,
    Submission,
    SubmissionProblem,
    start_child,
)
from lab.grading.isolation import (
    Sandbox,
    SandboxUnavailable,
    find_sandbox,
    make_grader_private,
    make_undumpable,
)
from lab.grading.report import INSECURE, GradeReport, TestResult
from lab.grading.rules import child_rules, importable_from_grader, oracle_folders, oracles
from lab.grading.suite import Fail, GradedTest

__all__ = [
    "Refused",
    "Submission",
    "SubmissionProblem",
    "StudentError",
    "StudentTimeout",
    "StudentCrash",
    "ImportFailed",
    "choose_sandbox",
    "find_module",
    "grade_submission",
    "read_module",
]

_OUTPUT_SHOW = 1500  # characters of what the child printed shown in a test's feedback
_MAX_MODULE_BYTES = 2 << 20  # a submitted module larger than 2 MB is refused


def _run_one(test: GradedTest, limits: ChildLimits, timeout_s: float) -> TestResult:
    t0 = time.monotonic()
    child = None
    printed = ""
    notes: list[str] = []
    try:
        cpu_s, import_deadline = limits.import_timeout_s + timeout_s, t0 + limits.import_timeout_s
        child, functions = start_child(limits, cpu_s, import_deadline)
        sub = Submission(child, limits.module, functions, timeout_s)
        note = test.func(sub)
        score, status, output = test.points, "passed", (str(note) if note else "")
    except Fail as e:
        score, status, output = 0.0, "failed", str(e)
    except SubmissionProblem as e:
        score, status, output = 0.0, "failed", str(e)
    except Exception as e:  # noqa: BLE001 - a bug in the graded test, or a value it did not foresee
        tb = traceback.format_exception_only(type(e), e)[-1].strip()
        score, status = 0.0, "failed"
        output = (
            f"GRADER ERROR: the test could not check what {test.target} returned ({tb}). "
            "Tell the instructor; this is probably not your fault."
        )
    finally:
        if child is not None:
            child.close()  # ends the child and drains its output pipe to the end first:
            printed = child.printed()  # what it printed just before answering is not lost
            notes = child.notes
    if printed.strip():
        shown = printed if len(printed) <= _OUTPUT_SHOW else printed[:_OUTPUT_SHOW] + "\n..."
        output = (output + "\n\n" if output else "") + "Your code printed:\n" + shown
    if notes:
        output = (
            (output + "\n\n" if output else "")
            + "The grader's sandbox refused:\n"
            + "\n".join(f"  - {n}" for n in notes)
        )
    if not limits.sandbox.secure:
        output = INSECURE + ("\n" + output if output else "")
    return TestResult(test, score, status, output, time.monotonic() - t0, tuple(notes))


class Refused(Exception):
    """The submission is not a module the grader will run (a link, a device, a folder, too large)."""


def _kind(mode: int) -> str:
    if stat.S_ISLNK(mode):
        return "a symbolic link"
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISREG(mode):
        return "a file"
    return "a device, pipe or socket"


def find_module(assignment: Assignment, submission: str | Path) -> Path | None:
    """The module file of a submission: the path itself if it is not a folder, else
    ``SUBMISSION/<module>`` (also one folder down, as Gradescope sometimes nests uploads). None when it
    is not there. Links are not followed: :func:`read_module` refuses what is not a regular file."""
    p = Path(submission)
    if not os.path.lexists(p):
        return None
    if not p.is_dir() or p.is_symlink():
        return p
    direct = p / assignment.module
    if os.path.lexists(direct):
        return direct
    nested = sorted(q for q in p.glob(f"*/{assignment.module}") if os.path.lexists(q))
    return nested[0] if len(nested) == 1 else None


def read_module(assignment: Assignment, path: Path) -> bytes:
    """The bytes of the submitted module, read once; :class:`Refused` unless it is a regular file
    reached without following a symbolic link."""
    name = assignment.module
    for q in (path, path.parent):
        try:
            st = os.lstat(q)
        except OSError as e:
            raise Refused(f"refused {path}: cannot read it ({e.strerror})") from None
        if q == path and not stat.S_ISREG(st.st_mode):
            raise Refused(
                f"refused {path}: it is {_kind(st.st_mode)}, not a file; submit {name} itself "
                "(links are not followed)"
            )
        if q != path and stat.S_ISLNK(st.st_mode):
            raise Refused(f"refused {path}: its folder {q.name} is a symbolic link (links are not followed)")
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except OSError as e:
        raise Refused(f"refused {path}: cannot open it without following a link ({e.strerror})") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise Refused(f"refused {path}: it is {_kind(st.st_mode)}, not a file; submit {name} itself")
        if st.st_size > _MAX_MODULE_BYTES:
            raise Refused(
                f"refused {path}: {st.st_size >> 10} KB is more than a module of {name} needs (2 MB)"
            )
        with os.fdopen(fd, "rb", closefd=False) as f:
            return f.read(_MAX_MODULE_BYTES + 1)
    finally:
        os.close(fd)


def choose_sandbox(insecure: bool = False) -> Sandbox:
    """The machine's sandbox; without one, :class:`SandboxUnavailable` unless ``insecure`` (then none)."""
    try:
        return find_sandbox()
    except SandboxUnavailable as e:
        if insecure:
            return Sandbox("none")
        raise SandboxUnavailable(
            f"refusing to grade without a sandbox: {e}; --insecure grades anyway, for practice only "
            "(every result then says so)"
        ) from None


def grade_submission(
    assignment: Assignment,
    submission: str | Path,
    *,
    jobs: int | None = None,
    timeout_scale: float = 1.0,
    insecure: bool = False,
    sandbox: Sandbox | None = None,
) -> GradeReport:
    """Run every graded test of ``assignment`` against ``submission`` (a folder or the module file).

    Parameters
    ----------
    assignment : Assignment
    submission : path
        A folder holding ``assignment.module`` (Gradescope's ``/autograder/submission``), or the file.
    jobs : int, optional
        Tests run at once (each in its own child); default ``min(4, cpu count)``.
    timeout_scale : float
        Multiplies every per-test time limit (a slow grading machine).
    insecure : bool
        Without a working sandbox, grade anyway (practice only: every result says so).
    sandbox : Sandbox, optional
        The isolation to use (default: :func:`~lab.grading.isolation.find_sandbox`).

    Returns
    -------
    GradeReport
        Never raises for anything the submission does.

    Raises
    ------
    SandboxUnavailable
        No sandbox works on this machine and ``insecure`` is False.
    """
    t0 = time.monotonic()
    sb = sandbox or choose_sandbox(insecure)
    make_undumpable()
    banned = oracle_folders(oracles(assignment))  # the graded tests' oracles: never in the child's reach
    if sb.kind == "uid":  # the child sees the grader's filesystem: close the grader's folders to it
        folder = Path(assignment.folder).resolve()
        make_grader_private([folder.parent, folder, *banned])
    suite = assignment.load_suite()
    jobs = jobs or max(1, min(4, os.cpu_count() or 1))

    def nothing_runs(msg: str, notes: list[str] = ()) -> GradeReport:
        return _nothing_runs(assignment, submission, suite, sb, t0, msg, notes)

    module_path = find_module(assignment, submission)
    if module_path is None:
        return nothing_runs(
            f"no {assignment.module} found in {submission}: submit the file {assignment.module}"
        )
    shadowing = importable_from_grader(module_path.parent)
    if shadowing:
        return nothing_runs(f"refused {submission}: {shadowing}")
    try:
        source = read_module(assignment, module_path)
    except Refused as e:
        return nothing_runs(str(e))
    limits = ChildLimits(
        source,
        assignment.module,
        assignment.memory_mb,
        assignment.import_timeout_s * timeout_scale,
        sb,
        (str(Path(assignment.folder).resolve()), *banned),
        child_rules(assignment),
    )
    # One import probe: a module that cannot be imported fails every test with the same message,
    # without paying its import timeout once per test.
    try:
        child, _ = start_child(limits, limits.import_timeout_s, t0 + limits.import_timeout_s)
        child.close()
    except ImportFailed as e:
        return nothing_runs(str(e), e.notes)
    results = _run_tests(suite.tests, assignment, limits, t0 + assignment.budget_s, timeout_scale, jobs)
    _point_at_dependencies(results)
    return GradeReport(assignment, str(submission), results, time.monotonic() - t0, None, sb.kind)


def _nothing_runs(assignment, submission, suite, sb: Sandbox, t0: float, msg: str, notes=()) -> GradeReport:
    """Every test failed with one message (no module, a refused file, a failed import)."""
    text = msg if sb.secure else f"{INSECURE}\n{msg}"
    if notes:
        text += "\n\nThe grader's sandbox refused:\n" + "\n".join(f"  - {n}" for n in notes)
    results = [TestResult(t, 0.0, "failed", text, 0.0, tuple(notes)) for t in suite.tests]
    return GradeReport(assignment, str(submission), results, time.monotonic() - t0, msg, sb.kind)


def _run_tests(tests, assignment, limits: ChildLimits, budget_end: float, timeout_scale: float, jobs: int):
    """Each test in its own child, ``jobs`` at once, until the grading's time budget ends."""

    def run(test: GradedTest) -> TestResult:
        left = budget_end - time.monotonic()
        if left < 1.0:
            return TestResult(
                test,
                0.0,
                "failed",
                f"not run: grading stopped after its time budget of {assignment.budget_s:g} s "
                "(earlier tests timed out)",
                0.0,
            )
        timeout = min((test.timeout_s or assignment.timeout_s) * timeout_scale, left)
        return _run_one(test, limits, timeout)

    with ThreadPoolExecutor(max_workers=jobs) as pool:
        return list(pool.map(run, tests))


def _point_at_dependencies(results: list[TestResult]) -> None:
    """A failed test whose function uses another failing function says so (fix that one first)."""
    failing: dict[str, list[str]] = {}
    for r in results:
        if r.status != "passed":
            failing.setdefault(r.test.target, []).append(r.test.id)
    for r in results:
        if r.status == "passed" or r.output.startswith(f"{r.test.target} is not implemented"):
            continue
        culprits = [f for f in r.test.uses if f in failing and f != r.test.target]
        if culprits:
            one = len(culprits) == 1
            r.output += f"\nNote: {r.test.target} uses {', '.join(culprits)}, which " + (
                "fails its own tests; fix it first." if one else "fail their own tests; fix those first."
            )
