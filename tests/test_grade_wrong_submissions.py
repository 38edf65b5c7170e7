"""Wrong submissions score less than the reference: each loses exactly the graded tests it should
(issue 48, "graded tests that need the right answer").

The submissions live in ``tests/grading_wrong/<assignment>/`` (see ``tests/wrong_submissions.py``):
the do-nothing answers of the issue (a map update returning the map, a heuristic of 0, an A* that
never finds a path, zeros of the right shape), NaN answers (an A* path whose total cost is NaN,
everything NaN), a stereo pair that undoes itself without being right and one that remembers what it
was asked, and realistic mistakes (transposed blocks, alpha and beta swapped, log2, a missing
normalisation, corner cutting, stopping when the goal is first seen, ...).

Each assignment's set is graded in one test, through :func:`grade_submission` in the strongest
isolation mode the machine has, as ``lab grade`` does. The reference scoring 100 % and the template
0 % are tests of ``tests/test_grade_assignments.py``; here every wrong submission scores below the
maximum, one built on the template scores 0 like the template, and no failure is a grader error.
"""

from __future__ import annotations

import pytest
from grade_modes import *  # noqa: F403  (the fixtures grading_mode and any_mode)
from wrong_submissions import ALL, wrong_submissions

from lab.grading import get_assignment, grade_submission

NAMES = ["stereo", "ekf", "planning", "search"]


def test_every_assignment_keeps_wrong_submissions_with_the_issues_cases():
    kept = {n: {w.name for w in wrong_submissions(n)} for n in NAMES}
    for n in NAMES:
        assert {"do_nothing", "nan_everywhere"} <= kept[n], n
        assert len(kept[n]) >= 5, n
        assert all(
            w.base == "template" and ALL in w.fails for w in wrong_submissions(n) if w.name == "do_nothing"
        )
    assert {"stateless_pair", "remembering_pair"} <= kept["stereo"]
    assert {"map_update_unchanged", "heuristic_zero", "astar_never_finds_a_path", "astar_nan_total"} <= kept[
        "search"
    ]


@pytest.mark.parametrize("name", NAMES)
def test_wrong_submissions_lose_exactly_the_tests_they_should(name, tmp_path, any_mode):
    a = get_assignment(name)
    ids = {t.id for t in a.load_suite().tests}
    reference = a.module_path.read_text()
    problems = []
    for w in wrong_submissions(name):
        folder = tmp_path / w.name
        folder.mkdir()
        (folder / a.module).write_text(w.source(reference))
        report = grade_submission(a, folder)
        failed, want = report.failed_ids(), w.expected_failures(ids)
        line = f"{w.name}: {report.score:g}/{report.max_score:g}"
        if failed != want:
            problems.append(f"{line}: fails {sorted(failed)}, should fail {sorted(want)}")
        if not report.score < report.max_score:
            problems.append(f"{line}: not below the reference's {report.max_score:g}")
        if w.base == "template" and report.score != 0:
            problems.append(f"{line}: built on the template, it must score 0 like the template")
        problems += [
            f"{line}: {r.test.id}: {r.output[:300]}" for r in report.tests if "GRADER ERROR" in r.output
        ]
    assert problems == [], "\n".join(problems)
