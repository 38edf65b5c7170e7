"""`lab search`: the object list, one-line errors, and a run through the Navigator that keeps the contract."""

import json
import subprocess
import sys

import numpy as np
import pytest

from lab.contract import problems
from lab.geometry import euler_zyx_to_R
from lab.search.pose_check import rest_tilt_deg


def _lab(*args, timeout=900):
    return subprocess.run(
        [sys.executable, "-m", "lab", *args], capture_output=True, text=True, timeout=timeout
    )


def test_list_objects_and_bad_input():
    r = _lab("search", "--list-objects")
    assert r.returncode == 0 and r.stdout.split() == ["cereal_box", "book", "toy_block", "glossy_cup"]
    r = _lab("search", "--object", "sofa")
    assert r.returncode == 2 and "unknown object 'sofa'; searchable objects: cereal_box" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    for place, why in (
        ("3.5,0,0,0", "outside the room or inside a wall"),
        ("2.98,0,0,0", "outside the room or inside a wall"),
        ("0,0,0.5,0", "does not stand on anything"),
    ):
        r = _lab("search", "--object", "book", "--place", place)
        assert r.returncode != 0 and why in r.stderr, (place, r.stderr)
        assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr, r.stderr
    r = _lab("search", "--object", "book", "--place", "0,0,0")
    assert r.returncode == 2 and "--place must be 4 comma-separated numbers" in r.stderr


@pytest.mark.slow
def test_search_run_finds_the_toy_block_and_keeps_the_contract(tmp_path):
    r = _lab(
        "search",
        "--object",
        "toy_block",
        "--seed",
        "1",
        "--max-time",
        "240",
        "--sensing",
        "ideal",  # realistic odometry drift puts the world-frame error past 5 cm: the localization issue
        "--json",
        str(tmp_path / "s.json"),
        "--out",
        str(tmp_path / "figs"),
    )
    assert r.returncode == 0, r.stderr[-2000:]
    steps = [line for line in r.stderr.splitlines() if line.startswith("lab search: t =")]
    assert any(" global: " in line for line in steps) and any(" local (" in line for line in steps), r.stderr
    res = json.loads((tmp_path / "s.json").read_text())
    assert res["sensing"] == "ideal"
    assert len(steps) == len(res["events"])  # one line per decision, as it happens
    assert res["found"] and res["position_error_m"] <= 0.05 and res["orientation_error_deg"] <= 10
    assert res["collisions"] == 0
    # --out: the figures and the same JSON
    figs = tmp_path / "figs"
    assert json.loads((figs / "search.json").read_text()) == res
    for name in ("fig2_global_search.png", "fig5_trial.png", "fig6_snapshots.png", "map_00.png"):
        assert (figs / name).stat().st_size > 10_000, name
    assert len(list(figs.glob("map_*.png"))) == len(res["map_snapshots"])
    assert problems("search", res) == []  # lab/schemas/search.schema.json
    summary = json.loads(r.stdout)  # the console's summary: found / success and the localization, in words
    assert summary["outcome"].startswith("found and a success")
    assert summary["localization_outcome"].startswith(f"{res['landmark_updates']} landmark update")
    # the found pose's stated deviation in W, on the console too: at least the camera frame's own
    std = res["pose_std"]
    assert summary["pose_std"] == std and std is not None
    assert std["position_m"] >= std["camera_frame_position_m"] > 0
    # the box rests on a face: the reported pose is upright and its stated orientation deviation the yaw's,
    # which may be under the camera frame's larger axis (lab.search.world_pose.rest_on_face)
    assert std["orientation_deg"] > 0 and std["camera_frame_orientation_deg"] > 0
    R_WO = euler_zyx_to_R(*np.radians(res["estimated_pose"]["euler_zyx_deg"]))
    assert rest_tilt_deg(R_WO) < 0.01


def test_outcome_in_words_says_found_success_and_the_missed_limit():
    from lab.runs.search import outcome_in_words

    base = {"found": True, "reason": "found", "position_error_m": 0.012, "orientation_error_deg": 0.8}
    assert outcome_in_words({**base, "success": True}).startswith("found and a success: 1.2 cm and 0.8 deg")
    far = {**base, "success": False, "position_error_m": 0.083}
    assert outcome_in_words(far) == "found, but 8.3 cm from the true position: the limit is 5 cm"
    both = {**far, "orientation_error_deg": 37.9}
    assert outcome_in_words(both) == (
        "found, but 8.3 cm from the true position: the limit is 5 cm; "
        "and 37.9 deg off the true orientation: the limit is 10 deg"
    )
    assert outcome_in_words({"found": False, "reason": "time budget of 240 s used up"}) == (
        "not found: time budget of 240 s used up"
    )
    robot = {"found": True, "position_error_m": None, "orientation_error_deg": None}
    assert outcome_in_words(robot) == "found (no true pose to score it against)"


def test_progress_prints_each_event_and_keeps_the_observer_before_it(capsys):
    from types import SimpleNamespace

    from lab.runs.search import _with_progress
    from lab.search.agent import SearchEvent

    seen = []
    agent = SimpleNamespace(observer=lambda a, e: seen.append(e))
    attached = []
    _with_progress(attached.append)(agent)
    assert attached == [agent]
    e = SearchEvent(27.8, "local", (4, 13), "found: 4 confirming updates")
    agent.observer(agent, e)
    assert seen == [e]
    assert capsys.readouterr().err == "lab search: t =   27.8 s  local (4, 13): found: 4 confirming updates\n"


def test_localization_in_words_says_the_mode_the_updates_and_what_the_odometry_learned():
    from lab.runs.room import localization_in_words

    cal = {
        "turn_scale": 0.96,
        "turn_scale_sd": 0.006,
        "curvature_rad_per_m": 0.012,
        "curvature_sd_rad_per_m": 0.004,
    }
    run = {"localization": "landmarks", "landmark_updates": 54, "odometry_calibration": cal}
    assert localization_in_words({**run, "localization_error_m": 0.0071}) == (
        "54 landmark updates; the wheels over-count turns by 4.2 % (turn scale 0.960 +- 0.006) and drift "
        "0.012 +- 0.004 rad per metre; 0.7 cm from the true pose at the end"
    )
    # with the spin's slip in the state, what a spin over-counts beyond a drive's turn
    slip = {**run, "odometry_calibration": {**cal, "spin_slip": 0.0512, "spin_slip_sd": 0.012}}
    assert localization_in_words(slip) == (
        "54 landmark updates; the wheels over-count turns by 4.2 % (turn scale 0.960 +- 0.006), spins "
        "5.1 +- 1.2 % more, and drift 0.012 +- 0.004 rad per metre"
    )
    # on the robot there is no truth; a base that under-counts its turns says so
    under = {**run, "odometry_calibration": {**cal, "turn_scale": 1.05}, "localization_error_m": None}
    assert localization_in_words(under).startswith(
        "54 landmark updates; the wheels under-count turns by 4.8 %"
    )
    assert localization_in_words({**run, "odometry_calibration": None, "landmark_updates": 1}) == (
        "1 landmark update"
    )
    # a robot the gate had lost, re-found by sightings that agreed (lab.localization.refind)
    for n, said in ((1, "once"), (2, "2 times")):
        lost = {**run, "odometry_calibration": None, "landmark_refinds": n}
        assert localization_in_words(lost) == f"54 landmark updates (lost and re-found {said})"
    # what it learned of the camera: its yaw on the base and its ranges' scale
    cam = {"yaw_deg": -0.412, "yaw_sd_deg": 0.081, "range_scale": -0.00476, "range_scale_sd": 0.0011}
    assert localization_in_words({**run, "odometry_calibration": None, "camera_estimate": cam}) == (
        "54 landmark updates; the camera sits -0.41 +- 0.08 deg turned on the base; the stereo's ranges "
        "come out 0.48 +- 0.11 % short"
    )
    tour = {"stands": [[0, 0]] * 4, "sightings": [{"a": 2, "b": 1}, {"b": 3, "c": 1}], "n_sightings": 7}
    toured = {**run, "odometry_calibration": None, "survey_tour": {**tour, "sim_time_s": 207.6}}
    assert localization_in_words(toured) == (
        "a survey tour of 4 stands first (7 sightings of 3 posters, 208 s); 54 landmark updates"
    )
    fallback = {
        **run,
        "landmark_updates": 0,
        "localization_note": "no landmark was seen: the pose is odometry alone",
    }
    assert localization_in_words(fallback) == "no landmark was seen: the pose is odometry alone"
    assert localization_in_words({"localization": "odometry"}) == "odometry alone (--localization odometry)"
    no_map = {"localization": "odometry", "localization_note": "no landmark map: the pose is odometry alone"}
    assert localization_in_words(no_map) == no_map["localization_note"]  # asked for landmarks, fell back
