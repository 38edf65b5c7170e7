"""The Gradescope autograder bundle of one assignment: ``lab assignments gradescope NAME --out FILE.zip``.

Gradescope builds a Docker image from the zip (unpacked into ``/autograder/source``, ``setup.sh`` run
once as root) and, for every submission, runs ``run_autograder``, which must leave
``/autograder/results/results.json``. The bundle holds

* ``setup.sh``: a Python 3.12 and the dependency versions of ``requirements.txt`` in ``/opt/lab-venv``
  (through uv, into folders every uid can read: the uid mode's children run that Python), then
  ``lab grade --check-sandbox``; when no isolation mode works there it fails, and so does the image
  build, instead of grading without a sandbox;
* ``run_autograder``: ``lab grade NAME /autograder/submission --json .../results.json``; whatever
  happens (a crash, a missing Python) it leaves a results.json, with score 0 and the reason if
  grading itself failed;
* ``requirements.txt``: the versions of ``uv.lock`` (``uv export --locked``), what CI tested;
* the ``lab`` package, and the assignment with its template (solutions stripped, as students get it)
  in place of the reference solution: the reference never enters the container. Its graded tests do
  (they are the grader), made private by the uid mode (:func:`~lab.grading.isolation.make_private`).

``AUTOGRADER_ROOT`` (default ``/autograder``) moves the whole layout, and ``LAB_AUTOGRADER_PYTHON``
names a Python that already has the packages (setup then installs nothing): both for testing the
bundle outside Gradescope.
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
import zipfile
from pathlib import Path

from lab.errors import ConfigError
from lab.grading.assignments import Assignment
from lab.grading.release import release, solution_lines
from lab.io import atomic_output

__all__ = ["build_bundle", "SETUP_SH", "RUN_AUTOGRADER"]

SETUP_SH = r"""#!/usr/bin/env bash
# Gradescope runs this once, as root, when it builds the autograder's image (lab assignments gradescope).
# It installs a Python and the pinned packages where every uid can read them, then checks that the
# student's code can be isolated here; if not, it fails and so does the build (no grading unisolated).
set -euo pipefail
ROOT="${AUTOGRADER_ROOT:-/autograder}"
SRC="$ROOT/source"
if [ -n "${LAB_AUTOGRADER_PYTHON:-}" ]; then
    PY="$LAB_AUTOGRADER_PYTHON"  # a Python that has the packages already (testing the bundle)
    echo "setup.sh: using $PY (LAB_AUTOGRADER_PYTHON); nothing installed"
else
    export UV_PYTHON_INSTALL_DIR=/opt/lab-python  # not under /root: the uid mode's children run it
    export UV_LINK_MODE=copy  # the venv's own files, not links into root's cache
    if ! command -v uv >/dev/null 2>&1; then
        python3 -m pip install --quiet uv 2>/dev/null \
            || python3 -m pip install --quiet --break-system-packages uv 2>/dev/null \
            || { curl -LsSf https://astral.sh/uv/install.sh | env UV_INSTALL_DIR=/usr/local/bin sh; }
    fi
    uv venv --quiet --python 3.12 /opt/lab-venv
    uv pip install --quiet --python /opt/lab-venv/bin/python -r "$SRC/requirements.txt"
    chmod -R a+rX /opt/lab-venv
    if [ -d /opt/lab-python ]; then chmod -R a+rX /opt/lab-python; fi
    PY=/opt/lab-venv/bin/python
fi
cd "$SRC"
if ! PYTHONPATH="$SRC" LAB_ASSIGNMENTS="$SRC/assignments" "$PY" -m lab grade --check-sandbox; then
    echo "setup.sh: no isolation mode works in this image (see the BAD lines above); refusing to build" >&2
    exit 1
fi
"""

RUN_AUTOGRADER = r"""#!/usr/bin/env bash
# Gradescope runs this for every submission: grade it into $ROOT/results/results.json. It always leaves
# a results.json, also when grading itself fails (score 0, with the reason, for the instructor to see).
ROOT="${AUTOGRADER_ROOT:-/autograder}"
SRC="$ROOT/source"
PY="${LAB_AUTOGRADER_PYTHON:-/opt/lab-venv/bin/python}"
RESULTS="$ROOT/results/results.json"
mkdir -p "$ROOT/results"
rm -f "$RESULTS"
LOG="$(mktemp)"
cd "$SRC" && PYTHONPATH="$SRC" LAB_ASSIGNMENTS="$SRC/assignments" \
    "$PY" -m lab grade "@ASSIGNMENT@" "$ROOT/submission" --json "$RESULTS" >"$LOG" 2>&1
status=$?
cat "$LOG"
if [ ! -s "$RESULTS" ]; then
    why="$(tail -n 3 "$LOG" | tr -c '[:alnum:] ._:/()=,-' ' ')"
    msg="The autograder could not grade this submission (exit status $status): $why."
    msg="$msg Tell the instructor; this is probably not your fault."
    {
        printf '{"score": 0, "output": "%s", "visibility": "visible", "stdout_visibility": "hidden",' "$msg"
        printf ' "tests": [], "extra_data": {"assignment": "@ASSIGNMENT@", "sandbox": "unknown",'
        printf ' "secure": false, "grading_failed": true}}\n'
    } >"$RESULTS.tmp" && mv "$RESULTS.tmp" "$RESULTS"
fi
rm -f "$LOG"
exit 0
"""


def _requirements(repo: Path) -> str:
    """The dependency versions of ``uv.lock`` (no dev tools, not the project itself), as
    requirements.txt lines with their environment markers."""
    if not (repo / "uv.lock").is_file():
        raise ConfigError(f"no uv.lock in {repo}: build the Gradescope bundle from a clone of the repository")
    uv = shutil.which("uv") or shutil.which("uv", path=str(repo / ".tools" / "bin"))
    if uv is None:
        raise ConfigError("the Gradescope bundle pins versions with uv: run make setup (or pip install uv)")
    r = subprocess.run(
        [uv, "export", "--locked", "--no-hashes", "--no-dev", "--no-emit-project", "--quiet"],
        cwd=repo,
        capture_output=True,
        text=True,
        timeout=300,
    )
    if r.returncode != 0:
        last = (r.stderr.strip().splitlines() or ["no message"])[-1]
        raise ConfigError(f"uv export --locked failed in {repo}: {last}")
    return r.stdout


def _package_files(pkg: Path):
    for p in sorted(pkg.rglob("*")):
        if p.is_file() and "__pycache__" not in p.parts and p.suffix not in (".pyc", ".pyo"):
            yield p


def build_bundle(assignment: Assignment, out: str | Path) -> Path:
    """Write the Gradescope autograder zip of ``assignment`` to ``out`` (atomically); returns its path.

    The reference solution is replaced by the student template, checked to hold no solution line."""
    from lab.paths import repo_root

    repo = repo_root()
    pkg = Path(__file__).resolve().parent.parent
    out = Path(out)
    requirements = _requirements(repo)
    with tempfile.TemporaryDirectory(prefix="lab-bundle-") as d:
        (released,) = release([assignment], d)  # the template, checked: no marker, no solution line
        template = (released / assignment.module).read_text()
        secret = solution_lines(assignment.module_path.read_text(), str(assignment.module_path))
        if secret & {ln.strip() for ln in template.splitlines()}:  # release checked it; never ship one
            raise ConfigError(f"the template of {assignment.name} holds solution code; not bundled")
        files: dict[str, bytes | Path] = {
            "setup.sh": SETUP_SH.encode(),
            "run_autograder": RUN_AUTOGRADER.replace("@ASSIGNMENT@", assignment.name).encode(),
            "requirements.txt": requirements.encode(),
        }
        for p in _package_files(pkg):
            files[f"lab/{p.relative_to(pkg).as_posix()}"] = p
        a_dir = f"assignments/{assignment.name}"
        for p in sorted(assignment.folder.iterdir()):
            if p.is_file() and p.suffix != ".pyc" and p.name != assignment.module:
                files[f"{a_dir}/{p.name}"] = p
        files[f"{a_dir}/{assignment.module}"] = template.encode()
        with atomic_output(out) as tmp, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
            for name, data in files.items():
                info = zipfile.ZipInfo(name, date_time=(2024, 1, 1, 0, 0, 0))
                info.compress_type = zipfile.ZIP_DEFLATED
                mode = 0o755 if name in ("setup.sh", "run_autograder") else 0o644
                info.external_attr = (0o100000 | mode) << 16
                z.writestr(info, data if isinstance(data, bytes) else data.read_bytes())
    return out
