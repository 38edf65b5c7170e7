"""The student release: solution blocks stripped, only the listed files shipped, no graded tests, and
no line of solution code left anywhere in it."""

import ast
import re

import pytest

from lab.errors import ConfigError
from lab.grading import list_assignments
from lab.grading.release import release, strip_solutions, verify_release

REFERENCE = '''import numpy as np

### BEGIN SOLUTION
def _helper(x):
    return x * 41.5
### END SOLUTION


def f(x):
    """Docstring stays."""
    y = np.asarray(x)
    ### BEGIN SOLUTION
    y = _helper(y) + 0.5
    ### END SOLUTION
    return y


class K:
    def g(self):
        ### BEGIN SOLUTION
        return "secret"
        ### END SOLUTION
'''


def test_strip_solutions_turns_blocks_into_not_implemented_and_drops_module_level_helpers():
    out = strip_solutions(REFERENCE, "m.py")
    assert "_helper" not in out and "41.5" not in out and "secret" not in out and "SOLUTION" not in out
    assert '"""Docstring stays."""' in out and "    y = np.asarray(x)\n    # YOUR CODE HERE" in out
    assert "    raise NotImplementedError\n    return y" in out
    assert "        raise NotImplementedError\n" in out  # at the method's indentation
    ns = {}
    exec(compile(out, "m.py", "exec"), ns)
    with pytest.raises(NotImplementedError):
        ns["f"](1.0)


@pytest.mark.parametrize(
    "source, message",
    [
        ("def f():\n    ### BEGIN SOLUTION\n    return 1\n", "is never closed"),
        ("def f():\n    return 1\n    ### END SOLUTION\n", "without a"),
        (
            "def f():\n    ## BEGIN SOLUTION\n    return 1\n    ### END SOLUTION\n",
            "malformed solution marker",
        ),
        ("### BEGIN SOLUTION\n### BEGIN SOLUTION\n### END SOLUTION\n", "inside the block opened at line 1"),
        ("def f():\n### BEGIN SOLUTION\n    return 1\n### END SOLUTION\n", "not valid Python"),
    ],
)
def test_strip_solutions_refuses_bad_markers(source, message):
    with pytest.raises(ConfigError, match=message):
        strip_solutions(source, "m.py")


_BLOCK = re.compile(r"### BEGIN SOLUTION\n(.*?)### END SOLUTION", flags=re.S)


def _solution_lines(text):
    """Lines of solution code (found here independently of lab.grading.release): between the markers,
    at least 12 characters long, and not also present outside the blocks."""
    outside = {ln.strip() for ln in _BLOCK.sub("", text).splitlines()}
    inside = {ln.strip() for block in _BLOCK.findall(text) for ln in block.splitlines()}
    return sorted(ln for ln in inside - outside if len(ln) >= 12 and not ln.startswith("#"))


def test_release_ships_only_the_student_files_without_solution_code(tmp_path):
    assignments = list_assignments()
    release(assignments, tmp_path)
    for a in assignments:
        dest = tmp_path / a.name
        shipped = {p.relative_to(dest).as_posix() for p in dest.rglob("*") if p.is_file()}
        assert shipped == set(a.release)
        assert a.tests_file not in shipped and not any("hidden" in f for f in shipped)
        secret = _solution_lines(a.module_path.read_text())
        assert len(secret) >= 5, f"{a.name}: the reference has no solution blocks"
        for f in shipped:
            text = (dest / f).read_text()
            assert "SOLUTION" not in text
            present = {ln.strip() for ln in text.splitlines()}
            assert not [ln for ln in secret if ln in present], f"{a.name}/{f} leaks solution code"
        template = (dest / a.module).read_text()
        tree = ast.parse(template)
        functions = [n for n in tree.body if isinstance(n, ast.FunctionDef)]
        assert functions and all(isinstance(n.body[-1], ast.Raise) for n in functions)


def test_release_refuses_to_overwrite_and_verify_catches_a_leak(tmp_path):
    a = next(x for x in list_assignments() if x.name == "ekf")
    release([a], tmp_path)
    with pytest.raises(ConfigError, match="exists; pass --force"):
        release([a], tmp_path)
    release([a], tmp_path, force=True)
    module = tmp_path / "ekf" / a.module
    module.write_text(module.read_text() + "\n    return Rz @ Ry @ Rx\n")
    with pytest.raises(ConfigError, match="holds solution code"):
        verify_release([a], tmp_path)
    module.unlink()
    (tmp_path / "ekf" / a.tests_file).write_text("")
    with pytest.raises(ConfigError, match="unexpected file"):
        verify_release([a], tmp_path)
