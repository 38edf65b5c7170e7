"""The grader's isolation: the student's code runs only in child processes, each misbehaviour costs the
test it happens in (with a message that says what happened), and nothing the code prints or writes
changes the grade. A small "toy" assignment written here keeps these tests fast and independent of the
real assignments.
"""

import json
import sys
import textwrap

import numpy as np
import pytest
from grade_modes import *  # noqa: F403  (the fixtures grading_mode and any_mode)

from lab.grading import get_assignment, grade_submission
from lab.grading.sandbox import WireError, decode, encode

TOY_TESTS = """
import numpy as np
from lab.grading.suite import TestSuite, as_array, as_float, check_close, fail

suite = TestSuite("toy")

def _make(name):
    def check(sub):
        x = np.arange(4.0)
        y = as_array(getattr(sub, name)(x), f"{name}(x)", (4,))
        check_close(y, 2 * x, f"{name}(x)")

    check.__name__ = name
    return check


for _name in FUNCTIONS:
    suite.test(f"{_name} returns 2 * x", points=1, target=_name)(_make(_name))
"""

FUNCTIONS = [
    "good",
    "raises",
    "loops",
    "hogs_memory",
    "exits",
    "hard_exits",
    "segfaults",
    "unsendable",
    "nan",
    "wrong_shape",
    "imports_lab",
    "garbles_channel",
    "good_after",
]

MISBEHAVING = """
import os, sys
import numpy as np

def good(x):
    return 2 * np.asarray(x)

def raises(x):
    raise ValueError("I am not finished")

def loops(x):
    while True:
        pass

def hogs_memory(x):
    return np.ones(10**10)  # 80 GB

def exits(x):
    sys.exit(0)

def hard_exits(x):
    os._exit(3)

def segfaults(x):
    import ctypes
    return ctypes.string_at(0)

def unsendable(x):
    return lambda: 2 * x

def nan(x):
    y = 2 * np.asarray(x)
    y[1] = np.nan
    return y

def wrong_shape(x):
    return (2 * np.asarray(x)).reshape(2, 2)

def imports_lab(x):
    from lab.estimation import models  # the library has it; the assignment is to write it
    return 2 * np.asarray(x)

def garbles_channel(x):
    for fd in range(3, 1024):  # the answer pipe keeps the grader's number for it, which may be high
        try:
            os.write(fd, b"\\x00\\x00\\x00\\x10{not json at all}")
        except OSError:
            pass
    return 2 * np.asarray(x)

def good_after(x):
    return 2 * np.asarray(x)
"""


def _toy(
    tmp_path,
    functions=FUNCTIONS,
    limits="timeout_s = 2\nimport_timeout_s = 3\nmemory_mb = 1024\nbudget_s = 40",
):
    root = tmp_path / "assignments"
    (root / "toy").mkdir(parents=True)
    (root / "toy" / "assignment.toml").write_text(
        'title = "toy"\nmodule = "toy.py"\nrelease = ["toy.py"]\ntests = "hidden_tests.py"\n'
        f"[limits]\n{limits}\n"
    )
    (root / "toy" / "toy.py").write_text(
        "import numpy as np\n\n"
        + "".join(f"def {f}(x):\n    return 2 * np.asarray(x)\n\n\n" for f in functions)
    )
    (root / "toy" / "hidden_tests.py").write_text(f"FUNCTIONS = {functions!r}\n" + TOY_TESTS)
    return get_assignment("toy", root)


def _submit(tmp_path, source, name="student"):
    d = tmp_path / name
    d.mkdir()
    (d / "toy.py").write_text(textwrap.dedent(source))
    return d


def test_each_misbehaviour_costs_its_own_test_and_says_what_happened(tmp_path, grading_mode):
    toy = _toy(tmp_path)
    assert grade_submission(toy, toy.module_path).score == len(FUNCTIONS)  # the toy reference passes
    report = grade_submission(toy, _submit(tmp_path, MISBEHAVING))
    out = {r.test.id: r.output for r in report.tests}
    assert report.failed_ids() == set(FUNCTIONS) - {"good", "good_after"}, report.summary()
    assert "raises raised ValueError: I am not finished" in out["raises"]
    assert "at toy.py line 9, in raises: raise ValueError" in out["raises"]  # points at the student's line
    assert "did not return within this test's limit of 2 s" in out["loops"]
    assert "ran out of memory" in out["hogs_memory"]
    assert "exits raised SystemExit" in out["exits"]
    assert "exited with status 3" in out["hard_exits"]
    assert "SIGSEGV" in out["segfaults"]
    assert "cannot send a value of type function" in out["unsendable"]
    assert "non-finite value(s)" in out["nan"] and "index (1,)" in out["nan"]
    assert "returned shape (2, 2); expected shape (4,)" in out["wrong_shape"]
    assert "importing 'lab' is not allowed in a submission" in out["imports_lab"]
    assert "cannot read" in out["garbles_channel"] or "answer" in out["garbles_channel"]


def test_the_scoring_process_never_runs_the_submission(tmp_path, any_mode):
    import builtins

    toy = _toy(tmp_path, ["good"])
    src = """
    import builtins
    import numpy as np
    builtins.LAB_TEST_IMPORTED_HERE = True  # module-level code: where does it run?
    def good(x):
        return 2 * np.asarray(x)
    """
    report = grade_submission(toy, _submit(tmp_path, src))
    assert report.score == 1.0
    assert not hasattr(builtins, "LAB_TEST_IMPORTED_HERE")  # the import probe and the test ran elsewhere
    assert "toy" not in sys.modules


def test_printing_or_writing_fake_results_does_not_change_the_grade(tmp_path, any_mode):
    from lab.cli import main

    toy = _toy(tmp_path, ["good", "other"])
    results = tmp_path / "results.json"
    fake = json.dumps({"score": 100.0, "tests": [{"name": "good", "score": 100.0, "max_score": 1.0}]})
    src = f"""
    import os, sys
    import numpy as np
    FAKE = {fake!r}
    print(FAKE)
    sys.stderr.write(FAKE + "\\n")
    os.write(1, FAKE.encode())

    def _forge():
        try:
            with open({str(results)!r}, "w") as f:
                f.write(FAKE)
        except OSError as e:
            print("could not forge:", e)

    _forge()

    def good(x):
        print(FAKE)
        _forge()
        return 3 * np.asarray(x)  # wrong

    def other(x):
        return 2 * np.asarray(x)
    """
    sub = _submit(tmp_path, src)
    assert (
        main(["grade", "toy", str(sub), "--json", str(results), "--assignments", str(toy.folder.parent)]) == 0
    )
    data = json.loads(results.read_text())
    assert data["score"] == 1.0 and [t["score"] for t in data["tests"]] == [0.0, 1.0]
    good = data["tests"][0]["output"]
    assert "good(x) is wrong" in good
    assert "Your code printed" in good and "could not forge" in good
    assert "sandbox refused" in good and "results.json: not in the sandbox" in good


def test_a_module_that_hangs_on_import_fails_every_test_once(tmp_path, any_mode):
    toy = _toy(tmp_path, ["a", "b", "c", "d"])
    report = grade_submission(toy, _submit(tmp_path, "while True:\n    pass\n"))
    assert report.score == 0.0
    for r in report.tests:
        assert "importing toy.py did not finish within 3 s" in r.output
    # one import timeout, not one per test: four would take at least 4 x 3 s (a bound of behaviour,
    # not of speed: the time of one timeout plus any load stays far below it)
    assert report.execution_time_s < 4 * 3


def test_a_bug_in_a_graded_test_is_reported_as_a_grader_error(tmp_path, any_mode):
    toy = _toy(tmp_path, ["a", "b"])
    tests = toy.tests_path.read_text()
    toy.tests_path.write_text(
        tests + "\n\n@suite.test('c is checked', points=1, target='a')\ndef c(sub):\n"
        "    return {}['missing']\n"
    )
    report = grade_submission(toy, toy.module_path)
    assert report.failed_ids() == {"c"}
    assert report.by_id()["c"].output.startswith("GRADER ERROR") and "KeyError" in report.by_id()["c"].output


def test_a_submitted_file_under_another_name_is_graded_as_the_module(tmp_path, any_mode):
    toy = _toy(tmp_path, ["good", "bad"])
    upload = tmp_path / "alice_hw3 (1).py"
    upload.write_text("def good(x):\n    return [2 * v for v in x]\n\ndef bad(x):\n    return 1 / 0\n")
    report = grade_submission(toy, upload)
    assert report.failed_ids() == {"bad"}
    assert "at toy.py line 5, in bad: return 1 / 0" in report.by_id()["bad"].output


def test_a_missing_module_fails_every_test_with_what_to_submit(tmp_path, any_mode):
    toy = _toy(tmp_path, ["a", "b"])
    (tmp_path / "empty").mkdir()
    report = grade_submission(toy, tmp_path / "empty")
    assert report.score == 0.0 and all("no toy.py found" in r.output for r in report.tests)


def test_the_time_budget_bounds_a_submission_that_loops_everywhere(tmp_path, any_mode):
    toy = _toy(tmp_path, ["a", "b", "c", "d", "e"], "timeout_s = 2\nimport_timeout_s = 3\nbudget_s = 5")
    src = "def a(x):\n    while True: pass\n\nb = c = d = e = a\n"
    report = grade_submission(toy, _submit(tmp_path, src), jobs=1)
    assert report.score == 0.0
    # the budget stopped it (running every test to its own limit would take 5 x 2 s)
    assert any("not run: grading stopped after its time budget of 5 s" in r.output for r in report.tests)


@pytest.mark.parametrize(
    "value",
    [
        None,
        [1, 2.5, "x", True],
        {"a": [np.arange(6.0).reshape(2, 3), np.int64(4)], "b": np.array([True, False])},
        np.array([np.nan, np.inf, -1.0]),
        np.zeros((0, 2), dtype=int),
        (np.float32(1.5), 3 + 4j),
    ],
)
def test_wire_format_round_trips_values(value):
    back = decode(encode(value))

    def same(a, b):
        if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
            return (
                np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True)
                and np.asarray(a).shape == np.asarray(b).shape
            )
        if isinstance(a, dict):
            return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
        if isinstance(a, (list, tuple)):
            return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
        return a == b or np.asarray(a) == np.asarray(b)

    assert same(value, back)


@pytest.mark.parametrize(
    "raw",
    [
        b'{"__ndarray__": "AAAA", "dtype": "|O", "shape": [1]}',  # object arrays would unpickle
        b'{"__ndarray__": "AAAA", "dtype": "<f8", "shape": [7]}',  # data and shape disagree
        b'{"__ndarray__": "!!", "dtype": "<f8", "shape": [1]}',
        b"[" * 100000,
        b"\xff\xfe",
    ],
)
def test_wire_format_refuses_malformed_or_dangerous_input(raw):
    with pytest.raises(WireError):
        decode(raw)


def test_wire_format_refuses_to_send_objects():
    with pytest.raises(WireError, match="cannot send a value of type object"):
        encode(object())
    with pytest.raises(WireError, match="dtype object"):
        encode(np.array([object()]))
