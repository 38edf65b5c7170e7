"""The student release: each assignment's shipped files, solution code stripped, graded tests left out.

Solution code sits between marker lines (nbgrader's convention)::

    def measurement_model(X, b_O):
        \"\"\"...\"\"\"
        ### BEGIN SOLUTION
        R = rotation_zyx(X[3], X[4], X[5])
        return b_O @ R.T + X[:3]
        ### END SOLUTION

Inside a function the block becomes ``raise NotImplementedError`` (with a "your code here" comment) at
the marker's indentation; at module level (a helper only the solution needs) it is removed. Only the
files an assignment lists under ``release`` are copied, never its graded tests. :func:`verify_release`
re-reads what was written and fails if a marker, a line of solution code or a graded-tests file made it
into the release.
"""

from __future__ import annotations

import ast
import shutil
from pathlib import Path

from lab.errors import ConfigError
from lab.grading.assignments import Assignment

__all__ = ["BEGIN", "END", "strip_solutions", "solution_lines", "release", "verify_release"]

BEGIN = "### BEGIN SOLUTION"
END = "### END SOLUTION"
_STUB = "# YOUR CODE HERE (see the docstring)\n"
_RAISE = "raise NotImplementedError\n"
_MIN_DISTINCTIVE = 12  # solution lines at least this long (stripped) must not appear in a release


def _blocks(source: str, filename: str):
    """Yield (kind, lines) pieces: ("code", line) outside blocks, ("solution", indent, lines) inside."""
    inside, indent, block, start = False, "", [], 0
    for lineno, line in enumerate(source.splitlines(keepends=True), 1):
        s = line.strip()
        if s in (BEGIN, END) or "BEGIN SOLUTION" in s or "END SOLUTION" in s:
            if s not in (BEGIN, END):
                raise ConfigError(
                    f"{filename}:{lineno}: malformed solution marker {s!r}; use {BEGIN!r} / {END!r}"
                )
            if s == BEGIN:
                if inside:
                    raise ConfigError(
                        f"{filename}:{lineno}: {BEGIN!r} inside the block opened at line {start}"
                    )
                inside, indent, block, start = True, line[: len(line) - len(line.lstrip())], [], lineno
            else:
                if not inside:
                    raise ConfigError(f"{filename}:{lineno}: {END!r} without a {BEGIN!r}")
                inside = False
                yield ("solution", indent, block)
            continue
        if inside:
            block.append(line)
        else:
            yield ("code", line)
    if inside:
        raise ConfigError(f"{filename}:{start}: {BEGIN!r} is never closed")


def strip_solutions(source: str, filename: str = "<source>") -> str:
    """The student template of ``source``: every solution block replaced (see the module docstring).

    Raises ConfigError for unbalanced or misspelt markers, or when the result is not valid Python.
    """
    out = []
    for piece in _blocks(source, filename):
        if piece[0] == "code":
            out.append(piece[1])
        elif piece[1]:  # inside a function: keep it callable, make it say what is missing
            out.append(piece[1] + _STUB)
            out.append(piece[1] + _RAISE)
    text = "".join(out)
    if filename.endswith(".py"):
        try:
            ast.parse(text, filename)
        except SyntaxError as e:
            raise ConfigError(f"{filename}: the stripped template is not valid Python ({e})") from None
    return text


def solution_lines(source: str, filename: str = "<source>") -> set[str]:
    """Distinctive lines of solution code (stripped): long enough, and not also outside the blocks."""
    inside, outside = set(), set()
    for piece in _blocks(source, filename):
        if piece[0] == "code":
            outside.add(piece[1].strip())
        else:
            inside.update(ln.strip() for ln in piece[2])
    return {ln for ln in inside - outside if len(ln) >= _MIN_DISTINCTIVE and not ln.startswith("#")}


def release(assignments: list[Assignment], out_dir: str | Path, force: bool = False) -> list[Path]:
    """Write the student release of ``assignments`` into ``out_dir/NAME/``; returns the folders.

    Refuses to write into an existing assignment folder unless ``force`` (which replaces it).
    """
    out = Path(out_dir)
    written = []
    for a in assignments:
        dest = out / a.name
        if dest.exists():
            if not force:
                raise ConfigError(f"{dest} exists; pass --force to replace it")
            shutil.rmtree(dest)
        dest.mkdir(parents=True)
        for rel in a.release:
            src = a.folder / rel
            text = src.read_text()
            if rel.endswith(".py") or BEGIN in text:
                text = strip_solutions(text, str(src))
            target = dest / rel
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text(text)
        written.append(dest)
    verify_release(assignments, out)
    return written


def verify_release(assignments: list[Assignment], out_dir: str | Path) -> None:
    """Fail (ConfigError) if the release holds a marker, solution code, or any file not meant for it."""
    out = Path(out_dir)
    for a in assignments:
        dest = out / a.name
        secret = set()
        for p in a.folder.rglob("*.py"):
            secret |= solution_lines(p.read_text(), str(p))
        allowed = set(a.release)
        for f in sorted(dest.rglob("*")):
            if f.is_dir():
                continue
            rel = f.relative_to(dest).as_posix()
            if rel not in allowed:
                raise ConfigError(
                    f"release {dest}: unexpected file {rel} (only {sorted(allowed)} are shipped)"
                )
            text = f.read_text()
            if "BEGIN SOLUTION" in text or "END SOLUTION" in text:
                raise ConfigError(f"release {f}: still holds a solution marker")
            leaked = sorted(secret & {ln.strip() for ln in text.splitlines()})
            if leaked:
                raise ConfigError(f"release {f}: holds solution code: {leaked[0]!r}")
        if (dest / a.tests_file).exists():
            raise ConfigError(f"release {dest}: holds the graded tests {a.tests_file}")
