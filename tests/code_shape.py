"""The shape of ``lab/``'s code, checked by reading the source (docs/architecture.md, "Code shape").

Four rules keep the package readable for whoever carries it on:

* **no private names across modules**: no ``from lab.x import _name``, and no ``obj._name`` read on an
  object of another module (``_name`` is not assigned or defined in the reading module). A remaining
  one carries a ``# private-ok: <why>`` comment on its line;
* **functions of at most** :data:`MAX_FUNCTION_LINES` lines (argument parsers excepted);
* **modules of at most** :data:`MAX_MODULE_LINES` lines, unless the module holds one idea, named in
  the test's allow-list;
* **no tuning record in the code**: a docstring or comment does not name a seed or a trial count;
  how a value was chosen lives in ``docs/tuning/``.

Each check returns one line per finding: ``path:line: what``.
"""

from __future__ import annotations

import ast
import io
import re
import tokenize
from pathlib import Path

MAX_FUNCTION_LINES = 80
MAX_MODULE_LINES = 600
JUSTIFIED = "private-ok:"

#: A seed named by number ("seed 3", "seeds 100000-100004", a report seed such as 101200) or a count
#: of trials.
_TUNING = re.compile(
    r"\bseeds?\s+\d|\b\d{5,6}\s*[-–]\s*\d|\b10\d{4}\b"
    r"|\b\d+\s+(?:of\s+\d+\s+)?(?:[a-z-]+\s+)?(?:trials|episodes|placements|drives|runs)\b",
    re.IGNORECASE,
)


def _modules(root: Path):
    for path in sorted(root.rglob("*.py")):
        yield path, path.read_text(encoding="utf-8")


def _rel(root: Path, path: Path) -> str:
    return str(path.relative_to(root.parent))


def private_imports(root: Path) -> list[str]:
    """``from lab.x import _name`` (or ``import lab.x._mod``) anywhere in the package."""
    found = []
    for path, text in _modules(root):
        lines = text.splitlines()
        for node in ast.walk(ast.parse(text)):
            if (
                isinstance(node, ast.ImportFrom)
                and (node.module or "").startswith("lab")
                or (isinstance(node, ast.ImportFrom) and node.level)
            ):
                for alias in node.names:
                    if alias.name.startswith("_") and not alias.name.startswith("__"):
                        if JUSTIFIED not in lines[node.lineno - 1]:
                            found.append(
                                f"{_rel(root, path)}:{node.lineno}: imports private {alias.name} "
                                f"from {'.' * node.level}{node.module or ''}"
                            )
    return found


def _own_private_names(tree: ast.AST) -> set[str]:
    """Private names a module defines: functions, classes, attributes it assigns, fields it declares."""
    own = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            own.add(node.name)
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
            own.add(node.attr)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            own.add(node.id)
        elif isinstance(node, ast.arg):
            own.add(node.arg)
        elif isinstance(node, ast.ImportFrom):
            own.update(a.asname or a.name for a in node.names)
        elif isinstance(node, ast.keyword) and node.arg:
            own.add(node.arg)
    return {n for n in own if n.startswith("_")}


def private_attribute_reads(root: Path) -> list[str]:
    """``obj._name`` where ``obj`` is not ``self``/``cls`` and the module does not define ``_name``."""
    found = []
    for path, text in _modules(root):
        tree = ast.parse(text)
        own = _own_private_names(tree)
        lines = text.splitlines()
        for node in ast.walk(tree):
            if not isinstance(node, ast.Attribute):
                continue
            a = node.attr
            if not a.startswith("_") or a.startswith("__") or a in own:
                continue
            if isinstance(node.value, ast.Name) and node.value.id in ("self", "cls"):
                continue
            if JUSTIFIED in lines[node.lineno - 1]:
                continue
            found.append(f"{_rel(root, path)}:{node.lineno}: reads {ast.unparse(node)}")
    return found


def long_functions(root: Path, limit: int = MAX_FUNCTION_LINES) -> list[str]:
    """Functions longer than ``limit`` lines (decorators and docstring included), parsers excepted."""
    found = []
    for path, text in _modules(root):
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                n = node.end_lineno - node.lineno + 1
                if n > limit and "parser" not in node.name:
                    found.append(f"{_rel(root, path)}:{node.lineno}: {node.name} has {n} lines")
    return found


def long_modules(root: Path, limit: int = MAX_MODULE_LINES) -> dict[str, int]:
    """Modules longer than ``limit`` lines: ``{path: lines}``."""
    return {_rel(root, p): n for p, t in _modules(root) if (n := len(t.splitlines())) > limit}


def _docstrings(tree: ast.AST):
    for node in ast.walk(tree):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                if isinstance(body[0].value.value, str):
                    yield body[0].lineno, body[0].value.value


def tuning_records(root: Path) -> list[str]:
    """Docstrings and comments that name a seed or a count of trials."""
    found = []
    for path, text in _modules(root):
        texts = list(_docstrings(ast.parse(text)))
        for tok in tokenize.generate_tokens(io.StringIO(text).readline):
            if tok.type == tokenize.COMMENT:
                texts.append((tok.start[0], tok.string))
        for line0, s in texts:
            for k, line in enumerate(s.splitlines()):
                if m := _TUNING.search(line):
                    found.append(f"{_rel(root, path)}:{line0 + k}: names {m.group(0)!r}")
    return found
