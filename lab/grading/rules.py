"""The grader's side of an assignment's rules: what the student's code may import, which modules it must
never reach (the graded tests' oracles), and whether a submission's folder could be imported by the
grader itself.

* **Imports.** ``assignment.toml`` lists the top-level modules the student's code may import
  (``imports = ["numpy", "heapq", ...]``). The child (:mod:`lab.grading.sandbox`) gets the list with
  :func:`child_rules` and refuses every other import by the student's code with an ``ImportError``
  naming the rule; a module outside the standard library that is not allowed is refused whoever asks
  for it (the student, or a library on the student's behalf), so nothing but the allowed packages is
  ever loaded there.
* **Oracles.** The packages the graded tests import to compute the right answers (networkx, SciPy,
  OpenCV) and the course library are never importable in the child: besides the import rule, their
  folders are masked in bubblewrap's filesystem and made private in the uid mode
  (:func:`oracle_folders`), so not even reading their files by hand works.
* **The grader's own imports.** A submission folder on the grader's import path (``sys.path``), or
  inside a folder that is, could put its own ``numpy.py`` in place of NumPy in the grader, which runs
  as root: :func:`importable_from_grader` says so, and grading refuses such a folder.
"""

from __future__ import annotations

import ast
import importlib.util
import os
import sys
from pathlib import Path

__all__ = ["child_rules", "oracles", "oracle_folders", "importable_from_grader"]

_CHILD_NEEDS = ("numpy",)  # the child itself runs on these: never an oracle, never hidden from it


def oracles(assignment) -> tuple[str, ...]:
    """Top-level modules the graded tests import that the student may not: outside the standard library
    and not in the assignment's ``imports`` (e.g. ``networkx``; never NumPy, which the child itself
    runs on), and always ``lab``."""
    try:
        tree = ast.parse(Path(assignment.tests_path).read_text())
    except (OSError, SyntaxError, ValueError):
        tree = ast.Module(body=[], type_ignores=[])
    names = {"lab"}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names |= {a.name.partition(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.partition(".")[0])
    allowed = {*(assignment.imports or ()), *_CHILD_NEEDS}
    return tuple(sorted(n for n in names if n not in sys.stdlib_module_names and n not in allowed))


def child_rules(assignment) -> dict:
    """What the child needs to enforce the rules (sent to it as JSON)."""
    imports = getattr(assignment, "imports", None)
    return {
        "assignment": assignment.name,
        "imports": None if imports is None else list(imports),
        "oracles": list(oracles(assignment)),
    }


def oracle_folders(names) -> tuple[str, ...]:
    """The installed folders of the packages ``names`` (found, not imported), to mask or make private."""
    found = []
    for name in names:
        try:
            spec = importlib.util.find_spec(name) if name not in sys.modules else sys.modules[name].__spec__
        except (ImportError, ValueError, AttributeError):
            continue
        for loc in (spec and spec.submodule_search_locations) or ():
            if os.path.isdir(loc):
                found.append(os.path.realpath(loc))
    return tuple(sorted(set(found)))


def _modules_in(folder: Path) -> list[str]:
    names = []
    try:
        entries = sorted(os.listdir(folder))
    except OSError:
        return names
    for e in entries:
        p = folder / e
        if p.is_dir() and e.isidentifier():
            names.append(e)
        elif e.endswith((".py", ".pyc", ".so", ".pth")) and e.split(".")[0].isidentifier():
            names.append(e.split(".")[0])
    return names


def _known(name: str, own: Path) -> bool:
    """Whether the grader has, or could import from elsewhere than ``own``, a module called ``name``."""
    if name in sys.modules or name in sys.stdlib_module_names:
        return True
    try:
        spec = importlib.util.find_spec(name)
    except (ImportError, ValueError):
        return False
    locations = [*(spec.submodule_search_locations or ()), spec.origin] if spec else []
    return any(
        loc and os.path.exists(loc) and own not in Path(loc).resolve().parents and Path(loc).resolve() != own
        for loc in locations
    )


def importable_from_grader(folder: str | Path) -> str | None:
    """Why the grader could import the submission folder's own modules in place of its own, or None.

    When ``folder`` is on ``sys.path`` (``''`` meaning the working directory), every module in it is:
    the grader (root, on Gradescope) would import the submission's ``numpy.py`` in place of NumPy.
    When it lies inside a folder on ``sys.path``, it is importable under the name of its first folder
    there, which matters when that is a name the grader uses (a folder called ``numpy``).
    ``python -m lab`` does not put the working directory there (:mod:`lab`), but ``PYTHONPATH=.``, a
    script in that folder or ``python -c`` would."""
    real = Path(os.path.realpath(folder))
    for entry in sys.path:
        p = Path(os.path.realpath(entry or os.getcwd()))
        if not p.is_dir() or not (real == p or p in real.parents):
            continue
        if real == p:
            mods = _modules_in(real)
            shadow = [m for m in mods if m in sys.modules or m in sys.stdlib_module_names]
            said = (
                f"; its {', '.join(shadow[:5])} would be imported in place of the grader's" if shadow else ""
            )
            where = "is"
        else:
            top = real.relative_to(p).parts[0]
            if not _known(top, p / top):
                continue
            said, where = (
                f"; its folder {top} would be imported in place of the grader's {top}",
                f"is inside {p}, which is",
            )
        return (
            f"the submission folder {real} {where} on the grader's import path (sys.path){said}. Grade "
            "from another folder, with the lab command (or python -P -m lab) and no PYTHONPATH "
            "pointing at submissions"
        )
    return None
