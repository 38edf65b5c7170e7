"""`lab eval search`: each job's JSON is what `lab search` writes for the same object, seed and
placement (the placement drawn from the job's own seed sequence); --resume runs only what is missing;
bad input stops in one line before anything starts."""

import csv
import json

import numpy as np

from lab.cli import main
from lab.eval.search import SearchSweep
from lab.evaluation import wilson_interval
from lab.runs.placement import random_placement, searchable_objects
from lab.scene import load_scene

# two tiny trials: ideal sensing, half a second of simulated time (the first scan's start)
SWEEP = ["--objects", "toy_block,book", "--surfaces", "floor", "--seeds", "3", "--strategies", "paper",
         "--obstacles", "no", "--sensing", "ideal", "--max-time", "0.5"]  # fmt: skip
VOLATILE = ("wall_time_s", "cpu_time_s")
# what a sweep's job adds to the `lab search` JSON
ADDED = ("n_snapshots", "shortest_path_m", "obstacles_on_path", "std_position_m", "std_orientation_deg")


def _strip(d: dict) -> dict:
    d = {k: v for k, v in d.items() if k not in VOLATILE + ADDED and k != "map_snapshots"}
    d["events"] = [{k: v for k, v in e.items() if "wall" not in k} for e in d["events"]]
    return d


def test_eval_search_jobs_are_lab_search_runs_and_resume_runs_only_the_missing(tmp_path, capsys):
    out = tmp_path / "sweep"
    assert main(["eval", "search", *SWEEP, "--out", str(out)]) == 0
    rows = list(csv.DictReader((out / "results.csv").open()))
    assert [r["key"] for r in rows] == [
        "paper_free_ideal_landmarks_book_floor_s3",
        "paper_free_ideal_landmarks_toy_block_floor_s3",
    ]
    scene = load_scene("lab_room")
    for r in rows:
        job = json.loads((out / "jobs" / f"{r['key']}.json").read_text())
        # the placement: the trial's seed, the object's index in --list-objects, the floor's (0)
        rng = np.random.default_rng([3, searchable_objects().index(r["object"]), 0])
        place = random_placement(scene, r["object"], rng, "floor")
        assert job["place"] == [round(v, 4) for v in place] and job["surface"] == "floor"
        # the peer: `lab search` at that placement, same seed, same budget
        peer = tmp_path / f"{r['object']}.json"
        argv = ["search", "--object", r["object"], "--seed", "3", "--place=" + ",".join(map(repr, place)),
                "--sensing", "ideal", "--max-time", "0.5", "--json", str(peer)]  # fmt: skip
        assert main(argv) == 0
        assert _strip(job) == _strip(json.loads(peer.read_text()))
        assert r["success"] == "False" and float(r["sim_time_s"]) == job["sim_time_s"] >= 0.5
        assert job["reason"] == "time budget of 0.5 s used up"  # (not rounded to "0 s")
        assert float(r["path_length_m"]) == job["path_length_m"] and r["error"] == ""
        assert 0.0 < job["shortest_path_m"] < 8.0  # the start to local-search range, round the furniture
    report = (out / "report.md").read_text()
    assert "| paper | False | ideal | landmarks | 0/2 | [0.0, 65.8] % |" in report
    assert "tuning split" in report

    # --resume: only the job whose JSON is gone runs again, and gives the same result
    first = json.loads((out / "jobs" / "paper_free_ideal_landmarks_book_floor_s3.json").read_text())
    (out / "jobs" / "paper_free_ideal_landmarks_book_floor_s3.json").unlink()
    capsys.readouterr()
    assert main(["eval", "search", *SWEEP, "--out", str(out), "--resume"]) == 0
    assert "2 jobs, 1 done before, 1 to run on local pool" in capsys.readouterr().out
    again = json.loads((out / "jobs" / "paper_free_ideal_landmarks_book_floor_s3.json").read_text())
    assert _strip(again) == _strip(first)


def test_bad_search_sweeps_are_refused_in_one_line_before_anything_starts(tmp_path, capsys):
    out = tmp_path / "o"
    bad_file = tmp_path / "s.toml"
    bad_file.write_text('[sweep]\nobjects = ["book"]\nstrategy = ["paper"]\n')
    cases = [
        (["--seeds", "", "--out", str(out)], "the seed range is empty"),
        (["--seeds", "5-3", "--out", str(out)], "5-3"),
        (
            ["--sweep", str(bad_file), "--out", str(out)],
            "unknown field(s) strategy; fields: objects, surfaces",
        ),
        ([*SWEEP, "--objects", "teapot", "--out", str(out)], "unknown object 'teapot'; searchable objects:"),
        ([*SWEEP, "--surfaces", "roof", "--out", str(out)], "unknown surface 'roof'; surfaces: floor"),
        ([*SWEEP, "--strategies", "dfs", "--out", str(out)], "unknown strategy 'dfs'; strategies: paper"),
        ([*SWEEP, "--obstacles", "some", "--out", str(out)], "obstacles must be one of no, yes, both"),
        (
            [*SWEEP, "--localization", "gps", "--out", str(out)],
            "unknown localization 'gps'; allowed: landmarks, odometry",
        ),
        ([*SWEEP, "--scheduler", "tcp://127.0.0.1:9", "--out", str(out)], "cannot reach the Dask scheduler"),
        ([*SWEEP, "--job-timeout", "0", "--out", str(out)], "--job-timeout must be > 0 s"),
        ([*SWEEP, "--sensing", "foggy", "--out", str(out)], "unknown sensing profile 'foggy'; profiles:"),
        ([*SWEEP, "--sensing", str(tmp_path / "no.toml"), "--out", str(out)], "no.toml not found"),
        (
            [*SWEEP, "--sensing", str(bad_file), "--out", str(out)],
            "sensing",
        ),  # a sweep file, not a sensing one
    ]
    for argv, msg in cases:
        assert main(["eval", "search", *argv]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and msg in err[0], (argv, err)
        assert not out.exists()


def test_a_sensing_file_is_a_sweeps_profile_named_by_its_stem(tmp_path, monkeypatch):
    """``--sensing my_room.toml``: each job is ``lab search --sensing my_room.toml`` (the file read by
    every worker from its absolute path), its key and report row named by the file's stem."""
    room = tmp_path / "survey_only.toml"
    room.write_text('[sensing]\nprofile = "ideal"\n[sensing.room]\nsurvey_m = 0.03\n')
    monkeypatch.chdir(tmp_path)  # a relative path, as a user types it
    out = tmp_path / "sweep"
    argv = [*SWEEP, "--objects", "book", "--sensing", "survey_only.toml", "--out", str(out)]
    assert main(["eval", "search", *argv]) == 0
    (row,) = csv.DictReader((out / "results.csv").open())
    assert row["key"] == "paper_free_survey_only_landmarks_book_floor_s3" and row["sensing"] == "survey_only"
    job = json.loads((out / "jobs" / f"{row['key']}.json").read_text())
    peer = tmp_path / "peer.json"
    rng = np.random.default_rng([3, searchable_objects().index("book"), 0])
    place = ",".join(map(repr, random_placement(load_scene("lab_room"), "book", rng, "floor")))
    assert main(["search", "--object", "book", "--seed", "3", "--place=" + place, "--sensing", str(room),
                 "--max-time", "0.5", "--json", str(peer)]) == 0  # fmt: skip
    assert _strip(job) == _strip(json.loads(peer.read_text()))
    assert "| paper | False | survey_only | landmarks | 0/1 |" in (out / "report.md").read_text()


def _eval_search_script():
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "benchmarks" / "eval_search.py"
    spec = importlib.util.spec_from_file_location("eval_search_script", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_the_report_counts_confidently_wrong_poses_and_misses_at_the_object():
    """benchmarks/eval_search.py report: a found pose > 10 deg off while its found event claims < 5 deg is
    confidently wrong (the search issue's count); a not-found trial says how many of its local searches
    answered for the object's true cell (the searched cell within neighbour_radius_m of it)."""
    es = _eval_search_script()
    found = "found: 4 confirming updates, std 0.51 cm, {} deg; the pose explains 17 of 180"

    def trial(err_deg, std_deg):
        events = [{"kind": "local", "cell": [3, 4], "detail": found.format(std_deg)}]
        return {"found": True, "orientation_error_deg": err_deg, "events": events}

    assert es.claimed_std(trial(12.8, 2.3)) == (0.51, 2.3)
    assert es.confidently_wrong(trial(12.8, 2.3))
    assert not es.confidently_wrong(trial(12.8, 6.0))  # wrong, but the filter said it was unsure
    assert not es.confidently_wrong(trial(8.0, 2.3))  # within the success limit
    assert not es.confidently_wrong({"found": False, "orientation_error_deg": None, "events": []})

    from lab.runs.search import map_spec

    spec = map_spec(load_scene("lab_room"))
    place = (1.93, 1.16, 0.0, 148.0)
    i, j = spec.world_to_cell(*place[:2])
    cells = [(i + 2, j), (i, j), (i + 3, j), (i - 10, j - 10)]  # 0.4 m: answered for; 0.6 m: not
    events = [{"kind": "local", "cell": list(c), "detail": "not found"} for c in cells]
    events.append({"kind": "global", "cell": None, "detail": "scan"})
    assert es.local_searches_at_object({"place": list(place), "events": events}) == (2, 4)


def test_the_report_counts_the_successes_a_shorter_budget_would_have_kept():
    """benchmarks/eval_search.py report: the successes that ended within 90 s and 300 s of simulated time
    (a failure, or a success after the shorter budget, does not count), with their Wilson intervals."""
    es = _eval_search_script()
    rows = [
        {"success": True, "sim_time_s": 40.0},
        {"success": True, "sim_time_s": 90.0},
        {"success": True, "sim_time_s": 350.0},
        {"success": False, "sim_time_s": 20.0},
    ]
    line = es.within_line(rows)
    lo, hi = wilson_interval(2, 4)
    assert f"<= 90 s: 2 (50.0 %, [{100 * lo:.1f}, {100 * hi:.1f}])" in line
    assert "<= 300 s: 2 (50.0 %" in line


def test_the_report_pairs_strategies_on_the_same_trials(capsys):
    """benchmarks/eval_search.py report: rate / paper path length over the trials both got right (a trial
    only one strategy ran, or one failed, is left out of the first median; the second counts the other
    strategy's failures as driven)."""
    es = _eval_search_script()

    def trial(strategy, seed, path, success=True):
        d = {"object": "book", "surface": "shelf", "seed": seed, "obstacles": False, "strategy": strategy}
        return d | {"path_length_m": path, "success": success}

    rows = [trial("rate", 1, 4.0), trial("paper", 1, 8.0), trial("rate", 2, 9.0), trial("paper", 2, 6.0)]
    rows += [trial("rate", 3, 3.0), trial("paper", 3, 30.0, success=False), trial("rate", 4, 1.0)]
    es.paired_path_ratio(rows, {es.key(d): d for d in rows}, "rate", "paper")
    out = capsys.readouterr().out
    assert "path length rate / paper, same trials: median 1.000 over the 2 both got right" in out
    assert "over the 3 the rate strategy got right" in out and "median 0.500" in out


def test_the_evaluation_budget_is_lab_searchs_own():
    """``lab eval search`` stops a trial where ``lab search`` and ``run_search`` stop a
    run by default: the evaluation measures what a user's run does."""
    import inspect

    from lab.cli.parser import build_parser
    from lab.eval.search import SEARCH_MAX_TIME_S, SearchSweep
    from lab.runs.search import run_search

    assert SearchSweep().max_time == SEARCH_MAX_TIME_S
    assert inspect.signature(run_search).parameters["max_time"].default == SEARCH_MAX_TIME_S
    args = build_parser().parse_args(["search", "--object", "book"])
    assert args.max_time == SEARCH_MAX_TIME_S


def test_half_runs_every_placement_once_with_the_boxes_on_every_other_one():
    """Issue 52's "placements, half with obstacles": ``--obstacles half`` gives each placement one trial,
    the boxes on half of them, balanced over the objects and the surfaces."""
    from collections import Counter

    both = SearchSweep(seeds=(100, 101), strategies=("paper",), obstacles="both").jobs()
    half = SearchSweep(seeds=(100, 101), strategies=("paper",), obstacles="half").jobs()
    place = lambda j: (j.kwargs["object"], j.kwargs["surface"], j.kwargs["seed"])  # noqa: E731
    assert len(both) == 2 * len(half) == 36
    assert sorted(map(place, half)) == sorted(set(map(place, both)))  # every placement, once
    on = [j for j in half if j.kwargs["obstacles"]]
    assert len(on) == len(half) // 2
    assert set(Counter(j.kwargs["object"] for j in on).values()) == {3}
    assert set(Counter(j.kwargs["surface"] for j in on).values()) == {3}
    assert {j.key for j in half} <= {j.key for j in both}  # the same jobs as `both` runs: --resume finds them


def test_survey_tour_jobs_are_the_same_trials_keyed_apart_and_the_flag_reaches_them():
    """``--survey-tour`` (flag or sweep file) runs the same placements with the tour before each search;
    their keys end in ``_tour``, so a resume in the same --out never takes one for the other; without it
    the jobs are unchanged (no ``survey_tour`` argument)."""
    from lab.cli.parser import build_parser
    from lab.eval.cli import search_sweep

    plain = SearchSweep(seeds=(5,), strategies=("paper",)).jobs()
    toured = SearchSweep(seeds=(5,), strategies=("paper",), survey_tour=True).jobs()
    assert [j.key + "_tour" for j in plain] == [j.key for j in toured]
    assert all("survey_tour" not in j.kwargs for j in plain)
    assert all(j.kwargs["survey_tour"] is True for j in toured)
    argv = ["eval", "search", "--seeds", "5", "--strategies", "paper", "--out", "x"]
    assert search_sweep(build_parser().parse_args([*argv, "--survey-tour"])).survey_tour is True
    assert search_sweep(build_parser().parse_args(argv)).survey_tour is False
    assert build_parser().parse_args(["search", "--object", "book", "--survey-tour"]).survey_tour is True
