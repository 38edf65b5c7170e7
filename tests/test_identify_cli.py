"""`lab identify`: a short episode writes a JSON that keeps the command-line contract, and figures."""

import json
import subprocess
import sys

import pytest

from lab.contract import problems


def test_short_identify_episode_keeps_the_contract(tmp_path):
    out = tmp_path / "out"
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "lab",
            "identify",
            "--true-model",
            "2",
            "--seed",
            "3",
            "--mover",
            "static",
            "--planner",
            "circle",
            "--max-actions",
            "1",
            "--max-time",
            "12",
            "--json",
            str(tmp_path / "r.json"),
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert r.returncode == 0, r.stderr[-2000:]
    res = json.loads((tmp_path / "r.json").read_text())
    assert res["true_model"] == 2 and res["planner"] == "circle" and res["seed"] == 3
    assert res["sensing"] == "realistic"  # the default profile, without being asked
    assert abs(sum(res["final_posterior"]) - 1) < 1e-9
    assert res["history"] and all(h["ptu_state"] in ("tracking", "scanning") for h in res["history"])
    assert res["actions"] <= 1 and res["collisions"] == 0
    assert res["sim_time_s"] <= 12.5
    for f in ("fig5_pose_and_probabilities.png", "fig6_information_gain_ring.png", "fig7_probabilities.png"):
        assert (out / f).is_file() or f.startswith("fig6") and res["actions"] == 0
    assert problems("identify", res) == []  # lab/schemas/identify.schema.json
    summary = json.loads(r.stdout)  # the console's summary: the localization in words too
    assert summary["localization_outcome"] == "odometry alone (--localization odometry)"
    # the final pose the robot states, without a truth: in the camera, with its deviations
    est = res["pose_estimate"]
    assert summary["pose_estimate"] == est and est is not None and est["frame"] == "camera"
    best = max(range(len(res["final_posterior"])), key=res["final_posterior"].__getitem__)
    assert est["model"] == (best if res["identified_model"] is None else res["identified_model"])
    assert 0 < est["position_std_m"] < 0.5 and 0 < est["orientation_std_deg"] < 180
    assert 0.3 < est["position_m"][2] < 5.0  # in front of the camera


def test_identify_bad_input_is_one_line():
    r = subprocess.run(
        [sys.executable, "-m", "lab", "identify", "--planner", "oracle"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert (
        r.returncode == 2
        and "invalid choice: 'oracle'" in r.stderr
        and len(r.stderr.strip().splitlines()) == 1
    )
    r = subprocess.run(
        [sys.executable, "-m", "lab", "identify", "--true-model", "7", "--max-time", "1"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 2 and "unknown true model 7; models: 0..3" in r.stderr


def test_unknown_mover_and_planner_names_are_refused_clearly():
    """Through the command line (argparse choices) and the Python API (ConfigError naming the choices)."""
    import pytest

    from lab.errors import ConfigError
    from lab.identification.agent import IdentificationAgent
    from lab.sim.movers import make_mover

    r = subprocess.run(
        [sys.executable, "-m", "lab", "identify", "--mover", "teleport"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 2 and "invalid choice: 'teleport'" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    with pytest.raises(
        ConfigError, match="unknown mover 'teleport'; movers: static, scripted, random, evasive"
    ):
        make_mover("teleport", carrier=None)
    with pytest.raises(ConfigError, match="unknown planner 'oracle'; planners: lut, mc, random, circle"):
        IdentificationAgent(None, [], planner="oracle")


def test_the_agent_is_handed_its_parts_and_refuses_to_plan_without_them():
    """The agent's constructor renders, trains and loads nothing: no databases, or the lut / mc planner
    without its evaluator, is a clear error naming what to build it with."""
    import numpy as np
    import pytest

    from lab.errors import ConfigError
    from lab.identification.agent import IdentificationAgent
    from lab.identification.synthetic import synthetic_box_databases

    dbs = synthetic_box_databases(4, np.random.default_rng(0))
    with pytest.raises(ConfigError, match="needs a sequence of FeatureDatabase"):
        IdentificationAgent(None, ("M0", "M1"), planner="circle")
    for planner in ("lut", "mc"):
        with pytest.raises(ConfigError, match=f"the {planner} planner needs an expected-entropy evaluator"):
            IdentificationAgent(None, dbs, planner=planner)


def test_an_unknown_sensing_profile_is_one_clear_line(tmp_path):
    """On the command line (argparse's choices) and in the Python API (the profile's ConfigError)."""
    import pytest

    from lab.errors import ConfigError
    from lab.runs.identify import run_identify

    r = subprocess.run(
        [sys.executable, "-m", "lab", "identify", "--sensing", "perfect"], capture_output=True, text=True
    )
    assert r.returncode == 2 and "argument --sensing: unknown sensing profile 'perfect'" in r.stderr
    assert "allowed: realistic, ideal, sensors, room (realistic's former name), or a .toml file" in r.stderr
    assert len(r.stderr.strip().splitlines()) <= 2  # usage + error
    bad_file = tmp_path / "room.toml"
    bad_file.write_text('[sensing]\nprofile = "realistic"\n[sensing.odometry]\nspin_slip = -0.1\n')
    r = subprocess.run(
        [sys.executable, "-m", "lab", "identify", "--sensing", str(bad_file)], capture_output=True, text=True
    )
    assert (
        r.returncode == 2 and "room.toml: sensing.odometry.spin_slip must be a finite number >= 0" in r.stderr
    )
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    with pytest.raises(ConfigError, match="perfect"):
        run_identify(2, seed=0, planner="circle", max_actions=0, figures=False, sensing="perfect")
    with pytest.raises(ConfigError, match="must be a finite number >= 0, got -1"):
        bad = {"camera": {"blur_sigma_px": -1}}
        run_identify(2, planner="circle", max_actions=0, figures=False, sensing=bad)


@pytest.mark.slow
def test_identify_hands_its_figures_the_robots_track(tmp_path, monkeypatch):
    """The episode records the robot's track for Fig. 6 (odometry, localized estimate, truth): it ends
    where the JSON's final errors were scored, and it starts at the episode's true start. (That the
    estimate is the localizer's, not the odometry's, the search's track test shows with landmarks in
    view.)"""
    import numpy as np

    import lab.viz.identification as viz
    from lab.runs.identify import run_identify

    seen = {}
    draw = viz.save_episode_figures

    def spy(out, agent, true_poses, true_model, track=None):
        seen["track"] = track
        return draw(out, agent, true_poses, true_model, track=track)

    monkeypatch.setattr(viz, "save_episode_figures", spy)
    res = run_identify(
        2,
        seed=3,
        mover="static",
        planner="circle",
        max_actions=1,
        max_time_s=12.0,
        out=tmp_path,
        localization="landmarks",
    )
    tr = seen["track"]
    assert tr is not None and tr.localization == res["localization"] and tr.truth is not None
    assert res["localization"] == "landmarks" and tr.localized  # (12 s on the box: no poster in view)
    assert len(tr) >= 20 and tr.t[-1] - tr.t[0] == pytest.approx(res["sim_time_s"], abs=0.3)
    end_odo = float(np.hypot(*(tr.odometry[-1, :2] - tr.truth[-1, :2])))
    end_loc = float(np.hypot(*(tr.estimate[-1, :2] - tr.truth[-1, :2])))
    assert end_odo == pytest.approx(res["odometry_error_m"], abs=1e-4)
    assert end_loc == pytest.approx(res["localization_error_m"], abs=1e-4)
    assert set(res["odometry_calibration"]) == {
        "turn_scale",
        "turn_scale_sd",
        "curvature_rad_per_m",
        "curvature_sd_rad_per_m",
        "spin_slip",  # the realistic profile states a spin slip: the localizer estimates it
        "spin_slip_sd",
    }
    assert tr.truth[0, 0] == pytest.approx(-1.2, abs=1e-6) and abs(tr.truth[0, 1]) <= 0.1  # the start
    assert (tmp_path / "fig5_pose_and_probabilities.png").is_file()
