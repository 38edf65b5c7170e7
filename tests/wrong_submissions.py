"""The wrong submissions of ``tests/grading_wrong/<assignment>/<name>.py``, made into student modules.

Each file holds only the functions a student got wrong, and a docstring that says what the mistake
is and how it must be graded::

    Base: reference            (or: template)
    Fails: test_id, test_id    (or: *, every test)

The student's module is the base (the reference solution, or the released template whose functions
raise ``NotImplementedError``) with the file appended: its definitions replace the base's, and the
base's other functions call them. A file may keep a base function under another name before
replacing it (``_right_astar = astar``) to get a right answer and spoil one part of it. The
``Fails`` line is exact: those tests fail and every other test passes.
"""

from __future__ import annotations

import ast
import re
from dataclasses import dataclass
from pathlib import Path

from lab.grading.release import strip_solutions

FOLDER = Path(__file__).parent / "grading_wrong"
ALL = "*"


@dataclass(frozen=True)
class Wrong:
    assignment: str
    name: str
    path: Path
    base: str  # "reference" or "template"
    fails: frozenset[str]  # test ids, or {ALL}

    def source(self, reference: str) -> str:
        """The student's module: the base with this file's definitions appended."""
        base = reference if self.base == "reference" else strip_solutions(reference, self.path.name)
        return f"{base.rstrip()}\n\n\n# ---- {self.name}: the wrong definitions\n{self.path.read_text()}"

    def expected_failures(self, test_ids: set[str]) -> set[str]:
        want = set(test_ids) if ALL in self.fails else set(self.fails)
        unknown = want - set(test_ids)
        if unknown:
            raise AssertionError(f"{self.path}: Fails names tests that do not exist: {sorted(unknown)}")
        return want


def _field(doc: str, key: str, path: Path) -> str:
    m = re.search(rf"^{key}:\s*(.+?)(?=^\S+:|\Z)", doc, re.MULTILINE | re.DOTALL)
    if m is None:
        raise AssertionError(f"{path}: its docstring has no '{key}:' line")
    return " ".join(m.group(1).split())


def load(path: Path) -> Wrong:
    doc = ast.get_docstring(ast.parse(path.read_text())) or ""
    base = _field(doc, "Base", path)
    if base not in ("reference", "template"):
        raise AssertionError(f"{path}: Base must be 'reference' or 'template', not {base!r}")
    fails = frozenset(s.strip() for s in _field(doc, "Fails", path).split(",") if s.strip())
    return Wrong(path.parent.name, path.stem, path, base, fails)


def wrong_submissions(assignment: str) -> list[Wrong]:
    """Every wrong submission kept for ``assignment``, by name."""
    return [load(p) for p in sorted((FOLDER / assignment).glob("*.py"))]
