"""`lab eval search --moving`: every trial twice on the same placement, seed and motion (the map's
prediction step and the static-map baseline), each job the `lab search --moving` run it names, and the
report grouped by motion, map and surface; a table-top placement drives on the table's top; bad moving
sweeps refused in one line."""

import csv
import json

import numpy as np
from test_eval_search import _strip

from lab.cli import main
from lab.runs.placement import check_placement, random_placement, searchable_objects
from lab.scene import load_scene

SWEEP = ["--objects", "toy_block", "--seeds", "3", "--strategies", "paper", "--obstacles", "no",
         "--sensing", "ideal", "--max-time", "0.5", "--moving", "random"]  # fmt: skip


def test_a_moving_sweep_runs_both_maps_on_the_same_trials(tmp_path):
    out = tmp_path / "sweep"
    assert main(["eval", "search", *SWEEP, "--out", str(out)]) == 0
    rows = list(csv.DictReader((out / "results.csv").open()))
    base = "paper_free_ideal_landmarks_toy_block_floor_s3_moving-random"
    assert [r["key"] for r in rows] == [f"{base}-predict", f"{base}-static"]
    jobs = [json.loads((out / "jobs" / f"{r['key']}.json").read_text()) for r in rows]
    assert jobs[0]["place"] == jobs[1]["place"] and jobs[0]["surface"] == "floor"
    assert [j["moving"]["predict"] for j in jobs] == [True, False]
    assert all(j["truth_time_s"] == j["moving"]["truth_time_s"] for j in jobs)
    assert [r["map"] for r in rows] == ["predict", "static"] and {r["moving"] for r in rows} == {"random"}
    # the peer: `lab search --moving random` at that placement, same seed and budget
    rng = np.random.default_rng([3, searchable_objects().index("toy_block"), 0])
    place = ",".join(map(repr, random_placement(load_scene("lab_room"), "toy_block", rng, "floor")))
    for job, extra in zip(jobs, ([], ["--static-map"]), strict=True):
        peer = tmp_path / "peer.json"
        argv = ["search", "--object", "toy_block", "--seed", "3", "--place=" + place, "--sensing", "ideal",
                "--max-time", "0.5", "--moving", "random", *extra, "--json", str(peer)]  # fmt: skip
        assert main(argv) == 0
        got = {k: v for k, v in job.items() if k != "truth_time_s"}
        assert _strip(got) == _strip(json.loads(peer.read_text()))
    report = (out / "report.md").read_text()
    for m in ("predict", "static"):
        assert f"| random | {m} | floor | paper |" in report


def test_the_baseline_is_added_later_on_the_same_trials(tmp_path):
    """``--maps predict`` runs the prediction step alone; ``--maps predict,static --resume`` in the same
    folder then runs only the baseline, and the report has both on the same trial."""
    out = tmp_path / "sweep"
    assert main(["eval", "search", *SWEEP, "--maps", "predict", "--out", str(out)]) == 0
    base = "paper_free_ideal_landmarks_toy_block_floor_s3_moving-random"
    first = (out / "jobs" / f"{base}-predict.json").read_text()
    assert [r["map"] for r in csv.DictReader((out / "results.csv").open())] == ["predict"]
    assert main(["eval", "search", *SWEEP, "--maps", "predict,static", "--resume", "--out", str(out)]) == 0
    assert (out / "jobs" / f"{base}-predict.json").read_text() == first  # not run again
    rows = list(csv.DictReader((out / "results.csv").open()))
    assert [r["key"] for r in rows] == [f"{base}-predict", f"{base}-static"]


def test_bad_moving_sweeps_are_refused_in_one_line(tmp_path, capsys):
    out = tmp_path / "o"
    cases = [
        ([*SWEEP, "--surfaces", "table,shelf", "--out", str(out)], "a moving object rides on the floor or a"),
        ([*SWEEP, "--object-speed", "0", "--out", str(out)], "--object-speed must be a finite number > 0"),
        ([*SWEEP, "--pause", "-1", "--out", str(out)], "--pause must be a finite number >= 0"),
        ([*SWEEP, "--maps", "predict,kf", "--out", str(out)], "unknown --maps kf; maps: predict,static"),
    ]
    for argv, msg in cases:
        assert main(["eval", "search", *argv]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and msg in err[0], (argv, err)
        assert not out.exists()


def test_lab_search_moving_refuses_what_it_cannot_do(capsys):
    assert main(["search", "--object", "book", "--static-map", "--max-time", "1"]) == 2
    assert "--static-map is the baseline for a moving object" in capsys.readouterr().err
    bad = ["search", "--object", "book", "--moving", "random", "--place=-2.7,2.6,1.2,0"]  # on the shelf
    assert main(bad) == 2
    err = capsys.readouterr().err
    assert "--moving puts the object on the floor or a table's top; --place put it on the shelf" in err
    assert main(["search", "--object", "book", "--surface", "table", "--max-time", "1"]) == 2
    assert "--surface is where a moving object's carrier drives: give --moving too" in capsys.readouterr().err
    both = ["--moving", "random", "--surface", "table", "--place", "1.9,2.6,0.75,0"]
    assert main(["search", "--object", "book", *both]) == 2
    assert "--place puts the object itself" in capsys.readouterr().err


def test_a_table_top_sweep_drives_on_the_tables_top(tmp_path):
    """``--surfaces table``: the placement is the seeded one on a table (``random_placement``'s), the
    job's result says the carrier drove on that table's top, and the object's truth at the end stands
    on it (``check_placement``, the peer that places objects)."""
    out = tmp_path / "sweep"
    argv = [*SWEEP, "--max-time", "20", "--surfaces", "table", "--out", str(out)]  # the last --max-time
    assert main(["eval", "search", *argv]) == 0
    rows = list(csv.DictReader((out / "results.csv").open()))
    base = "paper_free_ideal_landmarks_toy_block_table_s3_moving-random"
    assert [r["key"] for r in rows] == [f"{base}-predict", f"{base}-static"]
    rng = np.random.default_rng([3, searchable_objects().index("toy_block"), 1])
    place = random_placement(load_scene("lab_room"), "toy_block", rng, "table")
    scene = load_scene("lab_room").with_pose("toy_block", place)
    for r in rows:
        job = json.loads((out / "jobs" / f"{r['key']}.json").read_text())
        assert job["surface"] == "table" and np.allclose(job["place"], place, atol=1e-4)
        m = job["moving"]
        assert m["support"] == check_placement(scene, "toy_block", place).name  # the table it stood on
        assert m["legs"] >= 1 and m["path_length_m"] > 0.1  # it drove there
        x, y, z = job["true_pose"]["position_m"]
        yaw = job["true_pose"]["euler_zyx_deg"][0]
        end = check_placement(scene, "toy_block", (x, y, place[2], yaw), clearance_m=0.0)
        assert end.name == m["support"] and abs(z - place[2] - 0.075) < 1e-6  # still on its top
    assert "| random | predict | table | paper |" in (out / "report.md").read_text()
