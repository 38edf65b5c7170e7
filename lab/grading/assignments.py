"""Where the assignments live and what each one is made of (its ``assignment.toml``).

An assignment is a folder ``assignments/NAME/`` holding

* ``assignment.toml``: title, the student's module, the files a student receives, limits;
* the module (e.g. ``ekf.py``): the reference solution, its solution code between
  ``### BEGIN SOLUTION`` / ``### END SOLUTION`` markers (stripped by the release command);
* public tests (``test_*.py``, pytest, shipped to students);
* ``hidden_tests.py``: the graded tests (a :class:`~lab.grading.suite.TestSuite` called ``suite``),
  never shipped.

The folder is ``$LAB_ASSIGNMENTS`` if set, else ``assignments/`` next to the ``lab`` package.
"""

from __future__ import annotations

import importlib.util
import os
import sys
import tomllib
from dataclasses import dataclass
from pathlib import Path

from lab.errors import ConfigError
from lab.grading.suite import TestSuite
from lab.paths import repo_root

__all__ = ["Assignment", "assignments_dir", "list_assignments", "get_assignment"]

_DEFAULTS = {"timeout_s": 5.0, "import_timeout_s": 10.0, "memory_mb": 1024, "budget_s": 50.0}


@dataclass(frozen=True)
class Assignment:
    """One assignment, as described by its ``assignment.toml``.

    Attributes
    ----------
    name : str
        The folder name (``lab grade NAME ...``).
    folder : Path
    title : str
    module : str
        File name of the module students implement and submit (``ekf.py``).
    release : tuple of str
        Files copied into the student release (the module with its solutions stripped).
    tests_file : str
        The graded tests (never released).
    order : int
        Position in listings.
    timeout_s : float
        Default wall time [s] the student's code may take in one test.
    import_timeout_s : float
        Wall time [s] allowed for importing the module.
    memory_mb : int
        Address-space limit of the child process [MB].
    budget_s : float
        Total grading time [s] for one submission; tests not started by then fail as "not run".
    imports : tuple of str or None
        The top-level modules the student's code may import (``imports`` in ``assignment.toml``); the
        sandboxed child refuses every other (:mod:`lab.grading.rules`). None when the file declares
        none: then only ``lab`` and the graded tests' oracles are refused.
    """

    name: str
    folder: Path
    title: str
    module: str
    release: tuple[str, ...]
    tests_file: str
    order: int
    timeout_s: float
    import_timeout_s: float
    memory_mb: int
    budget_s: float
    imports: tuple[str, ...] | None = None

    @property
    def module_path(self) -> Path:
        """The reference solution (the module with its solution blocks)."""
        return self.folder / self.module

    @property
    def tests_path(self) -> Path:
        return self.folder / self.tests_file

    def load_suite(self) -> TestSuite:
        """Import the graded tests (instructor code, run in the grading process)."""
        key = f"_lab_graded_tests_{self.name}"
        if key in sys.modules and getattr(sys.modules[key], "__file__", None) == str(self.tests_path):
            return sys.modules[key].suite
        spec = importlib.util.spec_from_file_location(key, self.tests_path)
        mod = importlib.util.module_from_spec(spec)
        try:
            spec.loader.exec_module(mod)
        except ImportError as e:
            raise ConfigError(
                f"the graded tests of {self.name!r} need a package that is missing: {e} "
                "(install the grading dependencies: pip install networkx)"
            ) from None
        sys.modules[key] = mod
        suite = getattr(mod, "suite", None)
        if not isinstance(suite, TestSuite) or not suite.tests:
            raise ConfigError(f"{self.tests_path} must define a non-empty TestSuite called 'suite'")
        return suite


def assignments_dir(root: str | Path | None = None) -> Path:
    """``root``, else ``$LAB_ASSIGNMENTS``, else ``<repo>/assignments``."""
    if root is not None:
        return Path(root)
    return Path(os.environ.get("LAB_ASSIGNMENTS", repo_root() / "assignments"))


def _load(folder: Path) -> Assignment:
    path = folder / "assignment.toml"
    try:
        cfg = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{path}: {e}") from None
    for key in ("title", "module", "release"):
        if key not in cfg:
            raise ConfigError(f"{path}: missing field {key!r}")
    limits = {**_DEFAULTS, **cfg.get("limits", {})}
    unknown = set(limits) - set(_DEFAULTS)
    if unknown:
        raise ConfigError(f"{path}: unknown [limits] {sorted(unknown)}; allowed: {sorted(_DEFAULTS)}")
    a = Assignment(
        name=folder.name,
        folder=folder,
        title=str(cfg["title"]),
        module=str(cfg["module"]),
        release=tuple(cfg["release"]),
        tests_file=str(cfg.get("tests", "hidden_tests.py")),
        order=int(cfg.get("order", 99)),
        timeout_s=float(limits["timeout_s"]),
        import_timeout_s=float(limits["import_timeout_s"]),
        memory_mb=int(limits["memory_mb"]),
        budget_s=float(limits["budget_s"]),
        imports=_imports(cfg, path),
    )
    if a.module not in a.release:
        raise ConfigError(f"{path}: the module {a.module!r} must be listed in 'release'")
    if a.tests_file in a.release:
        raise ConfigError(f"{path}: the graded tests {a.tests_file!r} must not be released")
    for f in a.release + (a.tests_file,):
        if not (folder / f).is_file():
            raise ConfigError(f"{path}: {f!r} does not exist in {folder}")
    return a


def _imports(cfg: dict, path: Path) -> tuple[str, ...] | None:
    """The ``imports`` field: a list of top-level module names (``numpy``, ``heapq``), or absent."""
    if "imports" not in cfg:
        return None
    names = cfg["imports"]
    if not isinstance(names, list) or not all(isinstance(n, str) and n.isidentifier() for n in names):
        raise ConfigError(
            f'{path}: \'imports\' must be a list of top-level module names (e.g. ["numpy", "heapq"]), '
            f"not {names!r}"
        )
    if "lab" in names:
        raise ConfigError(f"{path}: 'imports' may not allow 'lab' (the assignments are to be written)")
    return tuple(sorted(set(names)))


def list_assignments(root: str | Path | None = None) -> list[Assignment]:
    """Every folder of the assignments directory that has an ``assignment.toml``, in order."""
    base = assignments_dir(root)
    if not base.is_dir():
        raise ConfigError(f"no assignments folder at {base} (set $LAB_ASSIGNMENTS or pass --assignments)")
    found = [_load(p.parent) for p in sorted(base.glob("*/assignment.toml"))]
    return sorted(found, key=lambda a: (a.order, a.name))


def get_assignment(name: str, root: str | Path | None = None) -> Assignment:
    """The assignment called ``name``; ConfigError listing the available ones otherwise."""
    found = {a.name: a for a in list_assignments(root)}
    if name not in found:
        raise ConfigError(f"unknown assignment {name!r}; available: {', '.join(found) or 'none'}")
    return found[name]
