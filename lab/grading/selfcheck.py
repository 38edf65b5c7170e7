"""A student's self-check before submitting: ``lab check ASSIGNMENT FOLDER``.

It runs the assignment's *public* tests (the ``test_*.py`` a student receives in the release) on the
module in ``FOLDER``, with pytest, on any OS: no sandbox, no graded tests, no reference solution.
The module and the public tests are copied into a fresh temporary folder first, so that ``import ekf``
in the tests finds the student's file and nothing else of the course. The public tests come from the
course's assignment folder when it is there (the originals, in case the student's copies were
edited), else from ``FOLDER``.

The graded tests are other tests, run by the grader in a sandbox with time and memory limits, so the
grade can differ from what this says; the command says so every time.
"""

from __future__ import annotations

import fnmatch
import importlib.util
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from lab.errors import ConfigError
from lab.grading.assignments import Assignment

__all__ = ["public_tests", "self_check", "DIFFERS"]

DIFFERS = (
    "This ran the public tests only, on this machine, without the grader's sandbox or limits. The graded "
    "tests are other tests (more cases, time and memory limits), so your grade may differ."
)


def public_tests(assignment: Assignment, folder: Path) -> list[Path]:
    """The public test files of ``assignment`` (its released ``test_*.py``): the course's originals if
    they are there, else the student's copies in ``folder``."""
    names = [r for r in assignment.release if fnmatch.fnmatch(Path(r).name, "test_*.py")]
    found = []
    for name in names:
        for base in (assignment.folder, folder):
            if (base / name).is_file():
                found.append(base / name)
                break
    return found


def self_check(assignment: Assignment, folder: str | Path, quiet: bool = False) -> int:
    """Run the public tests of ``assignment`` on ``folder/<module>``; pytest's exit status (0: all
    passed). Prints pytest's report and :data:`DIFFERS`."""
    folder = Path(folder)
    module = folder / assignment.module if folder.is_dir() else folder
    if not module.is_file():
        raise ConfigError(f"no {assignment.module} in {folder}: lab check {assignment.name} FOLDER_WITH_IT")
    if importlib.util.find_spec("pytest") is None:
        raise ConfigError("lab check runs the public tests with pytest: pip install pytest")
    tests = public_tests(assignment, folder)
    if not tests:
        raise ConfigError(f"{assignment.name} has no public tests (test_*.py) to run")
    with tempfile.TemporaryDirectory(prefix=f"lab-check-{assignment.name}-") as d:
        work = Path(d)
        shutil.copyfile(module, work / assignment.module)
        for t in tests:
            shutil.copyfile(t, work / t.name)
        cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:xdist"]
        cmd += ["--rootdir", d]
        r = subprocess.run([*cmd, *(t.name for t in tests)], cwd=work, capture_output=True, text=True)
    if not quiet:
        print(f"lab check {assignment.name}: the public tests on {module}")
        out = r.stdout.replace(d, ".")
        print(out.rstrip())
        if r.returncode not in (0, 1):
            print(r.stderr.replace(d, ".").rstrip(), file=sys.stderr)
        print(DIFFERS)
    return r.returncode
