"""Every notebook reads as a lesson: learning objectives, prerequisites and time at the top; at least three
exercises checked in the notebook by lab.exercises; a summary with links to the next notebook and to its
assignment at the end. Reads the committed .ipynb files (no kernel), and runs each exercise cell as a
student who has not started would: its check says "not attempted yet" and raises nothing.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import nbformat
import numpy as np
import pytest

from lab import exercises

ROOT = Path(__file__).resolve().parent.parent
NOTEBOOKS = sorted((ROOT / "notebooks").glob("[0-9][0-9]_*.ipynb"))
CHECK_CALL = re.compile(r"^(check_\w+)\((my_\w+)\)", re.M)
LINK = re.compile(r"\]\(([^)\s]+)\)")


def _cells(path):
    return nbformat.read(path, as_version=4).cells


def _exercise_cells(cells):
    return [c.source for c in cells if c.cell_type == "code" and CHECK_CALL.search(c.source)]


def test_there_are_six_notebooks():
    assert [p.name[:2] for p in NOTEBOOKS] == ["00", "01", "02", "03", "04", "05"]


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_a_notebook_opens_with_objectives_prerequisites_and_time(path):
    head = "\n".join(c.source for c in _cells(path)[:3] if c.cell_type == "markdown")
    assert "**Learning objectives.**" in head
    block = head.split("**Learning objectives.**", 1)[1].split("**Prerequisites:**", 1)[0]
    objectives = re.findall(r"^\d+\. (.+)$", block, re.M)
    assert 3 <= len(objectives) <= 5, objectives
    assert re.search(r"\*\*Prerequisites:\*\* \S", head)
    assert re.search(r"\*\*Time:\*\* about \d+ minutes", head)


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_a_notebook_has_three_checked_exercises(path):
    calls = [CHECK_CALL.search(src) for src in _exercise_cells(_cells(path))]
    assert len(calls) >= 3
    for m in calls:
        assert m.group(1) in exercises.__all__, m.group(1)
    assert len({m.group(1) for m in calls}) == len(calls)  # three different checks, not one thrice


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_an_untouched_exercise_says_not_attempted_and_raises_nothing(path):
    for src in _exercise_cells(_cells(path)):
        *body, last = src.rstrip().splitlines()
        ns = {"np": np, "math": math}
        exec("\n".join(body), ns)  # the imports and the student's stub
        fb = eval(last.split("#")[0], ns)  # the check call, the cell's last line
        assert isinstance(fb, exercises.Feedback) and fb.status is exercises.Status.NOT_ATTEMPTED, fb


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_a_notebook_ends_with_a_summary_and_its_links(path):
    cells = _cells(path)
    last = cells[-1]
    assert last.cell_type == "markdown" and last.source.startswith("## Summary")
    links = LINK.findall(last.source)
    assert any(re.fullmatch(r"\.\./assignments/\w+/README\.md", x) for x in links), links
    following = [p for p in NOTEBOOKS if p.name > path.name]
    want_next = following[0].name if following else "../docs/course.md"
    assert want_next in links, (want_next, links)
    for target in links:  # every link of the summary and the header resolves from notebooks/
        assert (path.parent / target).exists(), target
    header = cells[1].source
    for target in LINK.findall(header):
        assert (path.parent / target).exists(), target
