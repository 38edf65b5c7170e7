"""Every tolerance check of the graded tests is written so that NaN fails (issue 48).

Every ordering comparison with NaN is False. So ``if err > tol: fail(...)`` lets a NaN error pass,
and so does ``ok = not (abs(a - b) > tol)``: an A* whose total cost was NaN passed every A* test that
way. The safe forms say when a value *passes*: ``if not err <= tol: fail(...)``,
``if np.all(err <= tol): return``, or a helper of :mod:`lab.grading.suite` (``check_close``).

The scanner reads the graded tests (``assignments/*/hidden_tests.py``) and the check helpers
(``lab/grading/suite.py``) and finds, by reading the source:

* a condition that fails the test (its branch calls ``fail`` or raises) holding an ordering comparison
  (``<``, ``<=``, ``>``, ``>=``, also inside ``np.any(...)``) under an even number of ``not`` / ``~``:
  NaN makes the comparison False, so the test does not fail;
* a condition that passes the test (its branch returns or continues, or an ``assert``) holding one
  under an odd number: NaN makes it True, so the test passes;
* a negated ordering comparison anywhere else (``ok = not (err > tol)``): True for NaN.

Comparisons of counts and shapes (``len(...)``, ``.size``, ``.ndim``, ``.shape``) cannot be NaN and
are left alone; ``np.allclose`` and ``math.isclose`` are False for NaN and not comparisons here.
"""

from __future__ import annotations

import ast
import textwrap
from pathlib import Path

import pytest

from lab.grading import list_assignments
from lab.paths import repo_root

ORDERING = (ast.Lt, ast.LtE, ast.Gt, ast.GtE)
COUNTS = ("size", "ndim", "shape")


def _is_count(node: ast.AST) -> bool:
    """``len(x)``, ``x.size``, ``x.ndim``, ``x.shape[k]``: integers, never NaN."""
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "len":
        return True
    if isinstance(node, ast.Subscript):
        node = node.value
    return isinstance(node, ast.Attribute) and node.attr in COUNTS


def _comparisons(node: ast.AST, negations: int = 0):
    """``(comparison, negations above it)`` for every ordering comparison a condition's truth hangs on.
    ``and``/``or``/``&``/``|`` keep the count, ``not``/``~`` add one, calls (``np.all(err <= tol)``)
    are looked into; other expressions are values, not conditions."""
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.Not | ast.Invert):
        yield from _comparisons(node.operand, negations + 1)
    elif isinstance(node, ast.BoolOp):
        for v in node.values:
            yield from _comparisons(v, negations)
    elif isinstance(node, ast.BinOp) and isinstance(node.op, ast.BitAnd | ast.BitOr):
        yield from _comparisons(node.left, negations)
        yield from _comparisons(node.right, negations)
    elif isinstance(node, ast.Call):
        for a in node.args:
            yield from _comparisons(a, negations)
    elif isinstance(node, ast.Compare):
        if any(isinstance(op, ORDERING) for op in node.ops) and not any(
            _is_count(x) for x in (node.left, *node.comparators)
        ):
            yield node, negations


def _walk_here(stmts):
    """The nodes of ``stmts``, not entering function or class definitions nested in them."""
    todo = list(stmts)
    while todo:
        node = todo.pop()
        yield node
        if not isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef | ast.Lambda):
            todo.extend(ast.iter_child_nodes(node))


def _fails(stmts) -> bool:
    return any(
        isinstance(n, ast.Raise)
        or (isinstance(n, ast.Call) and isinstance(n.func, ast.Name) and n.func.id == "fail")
        for n in _walk_here(stmts)
    )


def _passes(stmts) -> bool:
    return bool(stmts) and not _fails(stmts) and isinstance(stmts[-1], ast.Return | ast.Continue)


def nan_unsafe(source: str, filename: str = "<source>") -> list[str]:
    """One line per tolerance check that NaN gets through: ``file:line: what``."""
    found = []
    tree = ast.parse(source, filename)
    in_checks: set[int] = set()  # the comparisons judged as a check's condition

    def judge(test: ast.AST, fail_when_true: bool, kind: str) -> None:
        for cmp, negations in _comparisons(test):
            in_checks.add(id(cmp))
            # failing on True: NaN (False) must become True, so an odd count; passing on True: even
            if (negations % 2 == 1) != fail_when_true:
                text = ast.get_source_segment(source, cmp) or "?"
                why = (
                    "NaN makes it False, so NaN does not fail; say when a value passes and negate that: "
                    "`if not err <= tol: fail(...)`"
                    if fail_when_true
                    else "it is negated, so NaN makes the condition True and gets through"
                )
                found.append(f"{filename}:{cmp.lineno}: {text!r} in a condition that {kind}: {why}")

    for node in ast.walk(tree):
        if isinstance(node, ast.If):
            if _fails(node.body):
                judge(node.test, True, "fails the test")
            elif _passes(node.body):
                judge(node.test, False, "passes the test")
            elif _fails(node.orelse) and not (len(node.orelse) == 1 and isinstance(node.orelse[0], ast.If)):
                judge(node.test, False, "skips a failure")
        elif isinstance(node, ast.Assert):
            judge(node.test, False, "passes an assert")
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.UnaryOp)
            and isinstance(node.op, ast.Not | ast.Invert)
            and isinstance(node.operand, ast.Compare)
            and id(node.operand) not in in_checks
            and any(_comparisons(node.operand))
        ):
            text = ast.get_source_segment(source, node) or "?"
            found.append(f"{filename}:{node.lineno}: {text!r} is True for NaN")
    return found


def _graded_files() -> list[Path]:
    files = [a.tests_path for a in list_assignments()]
    return files + [repo_root() / "lab" / "grading" / "suite.py"]


# ------------------------------------------------------------------------------ the repaired files
def test_every_graded_test_and_check_helper_is_nan_safe():
    files = _graded_files()
    assert len(files) >= 5  # four assignments and the helpers
    found = [line for f in files for line in nan_unsafe(f.read_text(), str(f.relative_to(repo_root())))]
    assert found == [], "\n".join(found)


def test_the_issues_bug_put_back_into_the_search_tests_is_found():
    """The check that let a NaN total through, restored in the real file, is caught on its line."""
    path = next(a.tests_path for a in list_assignments() if a.name == "search")
    source = path.read_text()
    safe = "if not abs(acc - total) <= 1e-9 * max(1.0, acc):"
    assert source.count(safe) == 1
    for unsafe in ("if abs(acc - total) > 1e-9 * max(1.0, acc):", "if not (not (abs(acc - total) > 1e-9)):"):
        planted = source.replace(safe, unsafe)
        line = planted[: planted.index(unsafe)].count("\n") + 1
        found = nan_unsafe(planted, "search/hidden_tests.py")
        assert [f for f in found if f.startswith(f"search/hidden_tests.py:{line}:")], found


# ------------------------------------------------------------------------- planted snippets, judged
UNSAFE = {
    "fail_on_greater": "if abs(a - b) > tol:\n    fail('off')",
    "fail_on_less": "if h < 0:\n    fail('negative')",
    "raise_on_greater": "if err > tol:\n    raise Fail('off')",
    "any_greater": "if np.any(err > tol):\n    fail('off')",
    "or_of_two": "if a.ndim != 1 or err.max() > tol:\n    fail('off')",
    "elif": "if x is None:\n    pass\nelif err > tol:\n    fail('off')",
    "negated_pass": "if not (abs(a - b) > tol):\n    return",
    "continue_on_negated": "for k in ks:\n    if not err[k] > tol:\n        continue\n    fail('off')",
    "ok_flag": "ok = not (abs(a - b) > tol)\nif not ok:\n    fail('off')",
    "inverted_mask": "bad = ~(err <= tol)",
    "assert_negated": "assert not (err > tol)",
    "else_fails": "if not err > tol:\n    note = 'fine'\nelse:\n    fail('off')",
    "double_negation": "if not (not (err > tol)):\n    fail('off')",
}

SAFE = {
    "fail_unless_within": "if not abs(a - b) <= tol:\n    fail('off')",
    "pass_when_within": "if np.all(err <= tol):\n    return\nfail('off')",
    "continue_when_within": "for k in ks:\n    if abs(g[k] - w[k]) <= tol:\n        continue\n    fail('k')",
    "chained_band": "if not (lo <= mean <= hi and err_mm <= 10):\n    fail('off')",
    "allclose": "if not np.allclose(a, b):\n    fail('off')",
    "diagnostic_isclose": "if math.isclose(got, -want):\n    fail('wrong sign')",
    "count_comparison": "if len(path) > 100 or a.ndim < 2 or a.shape[0] >= 3:\n    fail('shape')",
    "positive_required": "if not points > 0:\n    raise ValueError('points')",
    "else_passes": "if not err <= tol:\n    fail('off')\nelse:\n    note = 'ok'",
    "no_check": "big = err > tol\nworst = max(worst, err)",
    "assert_within": "assert err <= tol",
}


@pytest.mark.parametrize("name", UNSAFE)
def test_the_scanner_finds_each_unsafe_form(name):
    source = "def check(sub):\n" + textwrap.indent(UNSAFE[name], "    ")
    assert nan_unsafe(source), UNSAFE[name]


@pytest.mark.parametrize("name", SAFE)
def test_the_scanner_leaves_each_safe_form_alone(name):
    source = "def check(sub):\n" + textwrap.indent(SAFE[name], "    ")
    assert nan_unsafe(source) == [], SAFE[name]


def test_the_safe_and_unsafe_forms_do_what_the_scanner_says_with_nan():
    """The scanner's premise, run: with err = NaN the unsafe form does not fail, the safe one does."""
    err, tol = float("nan"), 1e-9
    assert not (err > tol)  # the unsafe form's condition: `if err > tol: fail(...)` does not fail
    assert not (err <= tol)  # the safe form's: `if not err <= tol: fail(...)` fails
