"""`lab grade CLASS/ --scheduler ADDRESS`: a generated class (reference, template, seeded bugs, an
empty folder) graded one submission per job on a real Dask cluster gets the scores and the messages of
grading it on this machine; bad input stops in one line before anything is graded."""

import csv
import json

import pytest
from grade_cases import make_class
from grade_modes import *  # noqa: F403  (the fixture any_mode)

from lab.cli import main

pytest.importorskip("distributed")
pytestmark = pytest.mark.usefixtures("any_mode")  # grading needs an isolation mode (skips without one)

VOLATILE = ("execution_time",)


def _results(each):
    """Every results.json without the timings (the whole run's, each test's duration)."""
    out = {}
    for p in sorted(each.glob("*/*.json")):
        d = {k: v for k, v in json.loads(p.read_text()).items() if k not in VOLATILE}
        for t in d["tests"]:
            t["extra_data"].pop("duration_s")
        out[f"{p.parent.name}/{p.name}"] = d
    return out


def test_a_class_graded_through_dask_gets_the_local_scores(tmp_path, capsys):
    from dask.distributed import LocalCluster

    klass = tmp_path / "class"
    students = make_class(klass, ("stereo",))
    (klass / "zoe_empty").mkdir()  # submitted nothing
    assert len(students) == 4  # reference, template, two seeded bugs
    local_csv, local_each = tmp_path / "local.csv", tmp_path / "local"
    assert main(["grade", "stereo", str(klass), "--batch", "--csv", str(local_csv), "--out", str(local_each),
                 "--quiet"]) == 0  # fmt: skip
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as c:
        dask_csv, dask_each = tmp_path / "dask.csv", tmp_path / "dask"
        argv = ["grade", "stereo", str(klass), "--scheduler", c.scheduler_address, "--csv", str(dask_csv),
                "--out", str(dask_each)]  # fmt: skip
        assert main(argv) == 0
    assert "5 submissions (5 students) to grade on Dask scheduler" in capsys.readouterr().out
    assert dask_csv.read_text() == local_csv.read_text()
    rows = {r["student"]: float(r["total"]) for r in csv.DictReader(local_csv.open())}
    assert rows.pop("stereo_reference") == 6 and rows.pop("stereo_template") == rows.pop("zoe_empty") == 0
    assert len(rows) == 2 and all(0 < v < 6 for v in rows.values()), rows  # the seeded bugs lose some
    a, b = _results(local_each), _results(dask_each)
    assert len(a) == 5 and a == b  # every test's score, status and message; the sandbox too
    assert {d["extra_data"]["sandbox"] for d in b.values()} != {"none"}


def test_bad_class_grading_is_refused_in_one_line_before_anything_starts(tmp_path, capsys):
    klass = tmp_path / "class"
    (klass / "alice").mkdir(parents=True)
    scores = klass / "scores.csv"
    cases = [
        (["--scheduler", "tcp://127.0.0.1:9"], "cannot reach the Dask scheduler at 'tcp://127.0.0.1:9'"),
        (["--scheduler", "127.0.0.1:8786"], "--scheduler must be 'local' or an address like tcp://HOST:8786"),
        (["--workers", "0"], "--workers must be a positive integer, got 0"),
        (["--workers", "2", "--job-timeout", "-1"], "--job-timeout must be > 0 s"),
        (["--workers", "2", "--json", "r.json"], "--json is for one submission"),
    ]
    for extra, msg in cases:
        assert main(["grade", "stereo", str(klass), *extra]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and msg in err[0], (extra, err)
        assert not scores.exists()
    assert main(["grade", "stereo", str(tmp_path / "nobody"), "--workers", "2"]) == 2
    assert "does not exist" in capsys.readouterr().err


class _LosesAlice:
    """An executor whose worker dies under alice's job; the others are graded here, in this process."""

    name = "a test executor"

    def run(self, jobs):
        from lab.eval.executor import Outcome

        for j in jobs:
            if j.key.startswith("alice:"):
                yield Outcome(j, None, "KilledWorker: the worker died", 1.0)
            else:
                yield Outcome(j, j.fn(**j.kwargs), None, 1.0)


def test_a_submission_that_cannot_be_graded_costs_that_student_only(tmp_path, capsys):
    import argparse

    from lab.eval.grade import grade_class
    from lab.grading import get_assignment

    a = get_assignment("stereo")
    klass = tmp_path / "class"
    for student in ("alice", "bob"):
        (klass / student).mkdir(parents=True)
        (klass / student / a.module).write_text(a.module_path.read_text())
    args = argparse.Namespace(assignments=None, jobs=1, timeout_scale=1.0, insecure=False, quiet=False,
                              out=None, csv=tmp_path / "scores.csv")  # fmt: skip
    assert grade_class(args, [a], klass, _LosesAlice()) == 1
    rows = list(csv.DictReader((tmp_path / "scores.csv").open()))
    assert [(r["student"], r["total"]) for r in rows] == [("bob", "6")]  # alice's grade is not made up
    err = capsys.readouterr().err
    assert "alice: stereo FAILED to grade: KilledWorker" in err and "left out of" in err and "alice" in err
