"""`lab grade` and `lab assignments` from the command line: results.json that passes the contract, a
readable summary, batch grading into one CSV, the release command, one-line errors."""

import csv
import json
import shutil
import subprocess
import sys

import pytest
from grade_modes import *  # noqa: F403  (the fixtures grading_mode and any_mode)

from lab.contract import problems
from lab.grading import get_assignment


def _lab(*args, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "lab", *map(str, args)], capture_output=True, text=True, timeout=600, cwd=cwd
    )


def test_grade_writes_gradescope_results_and_a_summary(tmp_path, any_mode):
    a = get_assignment("stereo")
    sub = tmp_path / "submission"
    sub.mkdir()
    shutil.copy(a.module_path, sub / a.module)
    out = tmp_path / "results" / "results.json"
    r = _lab("grade", "stereo", sub, "--json", out)
    assert r.returncode == 0, r.stderr
    assert "PASS" in r.stdout and "score: 6 / 6 (100 %)" in r.stdout
    data = json.loads(out.read_text())
    assert problems("grade", data) == []  # lab/schemas/grade.schema.json
    assert data["score"] == 6.0 and data["execution_time"] < 60
    assert {"name", "score", "max_score", "output", "visibility"} <= set(data["tests"][0])


def test_batch_grades_a_class_into_one_csv(tmp_path, any_mode):
    stereo, planning = get_assignment("stereo"), get_assignment("planning")
    released = tmp_path / "release"
    assert _lab("assignments", "release", released, "stereo", "planning").returncode == 0
    klass = tmp_path / "class"
    for student, src in (("alice", None), ("bob", released)):
        (klass / student).mkdir(parents=True)
        for a in (stereo, planning):
            shutil.copy(a.module_path if src is None else src / a.name / a.module, klass / student / a.module)
    (klass / "carol").mkdir()  # submitted nothing
    scores, each = tmp_path / "scores.csv", tmp_path / "each"
    r = _lab("grade", "stereo,planning", klass, "--batch", "--csv", scores, "--out", each)
    assert r.returncode == 0, r.stderr
    assert "alice: stereo 6/6, planning 14/14; total 20/20" in r.stdout
    rows = list(csv.DictReader(scores.open()))
    assert [row["student"] for row in rows] == ["alice", "bob", "carol"]
    assert {row["sandbox"] for row in rows} == {any_mode}  # the isolation mode, named for each student
    assert [row["total"] for row in rows] == ["20", "0", "0"] and rows[0]["max_score"] == "20"
    header = rows[0].keys()
    assert "stereo:triangulate_matches_opencv" in header and "planning:posterior_log_space" in header
    assert rows[0]["planning:posterior_log_space"] == "2" and rows[1]["planning:posterior_log_space"] == "0"
    results = json.loads((each / "carol" / "stereo.json").read_text())
    assert results["extra_data"]["sandbox"] == any_mode and results["extra_data"]["secure"] is True
    assert results["score"] == 0 and "no stereo.py found" in results["tests"][0]["output"]


def test_assignments_list_and_release(tmp_path):
    r = _lab("assignments", "list")
    assert r.returncode == 0
    for name in ("stereo", "ekf", "planning", "search"):
        assert name in r.stdout
    r = _lab("assignments", "release", tmp_path / "out")
    assert r.returncode == 0 and "no solution code" in r.stdout
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["ekf", "planning", "search", "stereo"]
    again = _lab("assignments", "release", tmp_path / "out")
    assert again.returncode == 2 and len(again.stderr.strip().splitlines()) == 1 and "--force" in again.stderr


@pytest.mark.parametrize(
    "args, message",
    [
        (["grade", "kalman", "."], "unknown assignment 'kalman'; available: stereo, ekf, planning, search"),
        (["grade", "ekf", "/no/such/folder"], "submission /no/such/folder does not exist"),
        (["grade", "all", "."], "grade one assignment at a time"),
        (["grade", "ekf", ".", "--batch", "--json", "x.json"], "--json is for one submission"),
        (["assignments", "release"], "needs OUT_DIR"),
    ],
)
def test_grade_errors_are_one_line(args, message):
    r = _lab(*args)
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and message in r.stderr, r.stderr
