"""The assignments as graded: references score 100 %, untouched templates 0 %, and each realistic wrong
submission loses exactly the tests it should, with a message that points at the mistake.

Grading runs the real pipeline (a child process per test). Every report is also checked for what the
issue asks of a grading run: under 60 s (guaranteed by the per-submission time budget, so this is not
a flaky timing assertion) and a results.json that passes the command-line contract.
"""

import json
import subprocess
import sys

import pytest
from grade_cases import ALL, CASES
from grade_modes import *  # noqa: F403  (the fixtures grading_mode and any_mode)

from lab.contract import problems
from lab.grading import get_assignment, grade_submission, list_assignments
from lab.grading.release import release

NAMES = ["stereo", "ekf", "planning", "search"]


def test_the_assignments_are_there_with_their_graded_tests():
    found = {a.name: a for a in list_assignments()}
    assert set(NAMES) <= set(found)
    for name in NAMES:
        suite = found[name].load_suite()
        assert len(suite.tests) >= 5 and suite.max_score >= 6
        assert {t.visibility.value for t in suite.tests} >= {"visible", "after_due_date"}


@pytest.fixture(scope="module")
def released(tmp_path_factory):
    out = tmp_path_factory.mktemp("release")
    release([get_assignment(n) for n in NAMES], out)
    return out


def _check_report(report, tmp_path):
    # how long grading takes is measured in benchmarks/bench_grade.py, not asserted here
    path = report.write_json(tmp_path / f"{report.assignment.name}.json")
    data = json.loads(path.read_text())
    assert problems("grade", data) == []  # lab/schemas/grade.schema.json
    assert data["score"] == pytest.approx(sum(t["score"] for t in data["tests"]))
    for t in data["tests"]:
        assert t["visibility"] in ("visible", "hidden", "after_due_date", "after_published")
        assert t["status"] in ("passed", "failed")
        assert 0 <= t["score"] <= t["max_score"]
    assert "execution_time" in data


@pytest.mark.parametrize("name", NAMES)
def test_reference_solution_scores_100_percent(name, tmp_path, any_mode):
    a = get_assignment(name)
    report = grade_submission(a, a.module_path)
    assert report.score == report.max_score, report.summary()
    _check_report(report, tmp_path)


@pytest.mark.parametrize("name", NAMES)
def test_untouched_template_scores_0_with_not_implemented(name, released, tmp_path, any_mode):
    a = get_assignment(name)
    report = grade_submission(a, released / name)
    assert report.score == 0.0, report.summary()
    for r in report.tests:
        assert "is not implemented yet" in r.output, r.output
    _check_report(report, tmp_path)


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_wrong_submission_loses_exactly_the_tests_it_should(case, tmp_path, any_mode):
    a = get_assignment(case.assignment)
    sub = tmp_path / "student"
    sub.mkdir()
    (sub / a.module).write_text(case.source(a.module_path.read_text()))
    report = grade_submission(a, sub)
    ids = {t.id for t in a.load_suite().tests}
    want = ids if ALL in case.fails else set(case.fails)
    assert want <= ids, "a case names a test that does not exist"
    assert report.failed_ids() == want, report.summary()
    results = report.by_id()
    for test_id, words in case.says.items():
        for i in ids if test_id == ALL else [test_id]:
            assert words in results[i].output, (i, results[i].output)
    _check_report(report, tmp_path)


@pytest.mark.parametrize("name", NAMES)
def test_public_tests_pass_on_the_reference_and_fail_on_the_template(name, released):
    a = get_assignment(name)
    public = [f for f in a.release if f.startswith("test_")]
    assert public
    env_cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *public]
    ok = subprocess.run(env_cmd, cwd=a.folder, capture_output=True, text=True, timeout=300)
    assert ok.returncode == 0, ok.stdout[-2000:]
    bad = subprocess.run(
        env_cmd + ["--rootdir", str(released / name)],
        cwd=released / name,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert bad.returncode == 1 and " passed" not in bad.stdout.splitlines()[-1], bad.stdout[-2000:]
    assert "NotImplementedError" in bad.stdout
