"""``lab check ASSIGNMENT FOLDER`` (issue 47): a student runs the public tests on their folder, on any
OS, with no sandbox and no grader files, and is told that the grade may differ."""

import shutil

from lab.cli import main
from lab.grading import get_assignment
from lab.grading.release import release
from lab.grading.selfcheck import DIFFERS, public_tests


def test_the_check_passes_the_reference_fails_the_template_and_says_the_grade_may_differ(tmp_path, capsys):
    stereo = get_assignment("stereo")
    (folder,) = release([stereo], tmp_path / "release")
    assert main(["check", "stereo", str(folder)]) == 1  # the template: NotImplementedError
    out = capsys.readouterr().out
    assert "failed" in out and DIFFERS in out
    mine = tmp_path / "mine"
    mine.mkdir()
    shutil.copy(stereo.module_path, mine / "stereo.py")  # a finished module, without the public tests
    assert main(["check", "stereo", str(mine)]) == 0
    out = capsys.readouterr().out
    assert "passed" in out and "failed" not in out and DIFFERS in out


def test_the_check_runs_only_public_tests(tmp_path):
    a = get_assignment("ekf")
    tests = public_tests(a, tmp_path)
    assert [t.name for t in tests] == ["test_ekf.py"] and a.tests_file not in {t.name for t in tests}


def test_a_folder_without_the_module_is_one_line(tmp_path, capsys):
    assert main(["check", "ekf", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no ekf.py in" in err
