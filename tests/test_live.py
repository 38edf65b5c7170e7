"""Live views, recordings and the teleoperation panel (issue 12).

* A short identification run with ``record`` writes an animation with one frame per step (read back),
  whose pictures (not only their time stamps) change over the run; ``lab search --record`` likewise,
  one frame per event.
* The view redraws at its rate in *sim* time; without a view nothing is drawn.
* The same view runs on the HardwareRobot over the device emulators, and its camera panel shows the
  robot's own frame.
* The teleoperation panel's buttons drive the teleop mover's carrier (pose and box yaw change in the
  simulator as commanded).
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from lab.errors import ConfigError
from lab.geometry import Pose2D
from lab.training import box_model_names, get_database
from lab.viz.live import (
    IdentificationPanels,
    LiveView,
    SearchPanels,
    TeleopPanel,
    identification_inliers,
    in_background,
)
from lab.viz.live.identification import ellipse_xy
from lab.viz.recorder import read_animation

STAMP_ROWS = 40  # the recorder's time stamp sits in the bottom rows of each frame


def _changed(a: np.ndarray, b: np.ndarray) -> bool:
    """Do two frames differ above the time stamp (the picture itself, not its stamp)?"""
    return bool(np.any(a[:-STAMP_ROWS] != b[:-STAMP_ROWS]))


def test_identify_record_has_one_frame_per_step_and_the_picture_changes(tmp_path):
    """In the background, as a notebook runs it: the recording's view, a chained notebook view at 2 Hz,
    and the teleop panel turning the box from the start of the run."""
    from lab.runs.identify import run_identify

    seen = {}

    def attach(agent, carrier):
        seen["view"] = LiveView.for_identification(agent)  # chained after the recording's view
        seen["widget"] = seen["view"].widget
        seen["carrier"], seen["yaw0"] = carrier, carrier.box_yaw
        TeleopPanel(carrier.mover).buttons["box left"].click()

    run = in_background(
        run_identify, 2, seed=3, mover="teleop", planner="circle", max_actions=1, max_time_s=3.0,
        figures=False, record=tmp_path / "run.gif", attach=attach,
    )  # fmt: skip
    res = run.result(timeout=900)
    frames = read_animation(res["recording"])
    n = len(res["history"])
    assert len(frames) == n >= 10
    assert len({f.shape for f in frames}) == 1
    changed = [_changed(a, b) for a, b in zip(frames, frames[1:], strict=False)]
    assert sum(changed) >= 0.8 * len(changed)  # the scene, camera and probabilities move every step
    view = seen["view"]
    assert view.n_calls == n and 2 <= view.n_draws <= n // 2 + 1  # 2 Hz of sim time at 5 steps/s
    assert seen["widget"].value[:8] == b"\x89PNG\r\n\x1a\n"
    turned = seen["carrier"].box_yaw - seen["yaw0"]  # truth, for the test only
    rate = TeleopPanel(seen["carrier"].mover).speeds.box_turn_rate
    assert turned == pytest.approx(rate * res["sim_time_s"])


@pytest.mark.slow
def test_lab_search_record_has_one_frame_per_event(tmp_path):
    r = subprocess.run(
        [
            sys.executable, "-m", "lab", "search", "--object", "toy_block", "--seed", "1", "--max-time", "30",
            "--json", str(tmp_path / "s.json"), "--record", str(tmp_path / "s.gif"),
        ],
        capture_output=True, text=True, timeout=900,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr[-2000:]
    res = json.loads((tmp_path / "s.json").read_text())
    frames = read_animation(res["recording"])
    assert len(frames) == len(res["events"]) >= 2
    assert all(_changed(a, b) for a, b in zip(frames, frames[1:], strict=False))


class _Clock:
    """A stand-in agent for the rate test: the view only needs its steps to draw nothing expensive."""

    def __init__(self):
        self.robot = SimpleNamespace(now=lambda: 0.0)


def test_the_view_redraws_at_its_rate_in_sim_time(monkeypatch):
    monkeypatch.setattr(LiveView, "render", lambda self: np.zeros((4, 4, 3), np.uint8))
    for rate, dt, n_steps, expected in ((2.0, 0.2, 51, 21), (None, 0.2, 51, 51), (1.0, 0.1, 30, 3)):
        view = LiveView(IdentificationPanels(_Clock()), rate_hz=rate, widget=False)
        for k in range(n_steps):
            view(None, SimpleNamespace(t=k * dt))
        assert (view.n_calls, view.n_draws) == (n_steps, expected)  # 10 s at 2 Hz: 21 draws incl. t = 0
    with pytest.raises(ConfigError, match=r"rate_hz must be within \[0.05, 50\]"):
        LiveView(IdentificationPanels(_Clock()), rate_hz=500)


def test_uncertainty_ellipse_is_the_two_sigma_contour():
    cov = np.array([[0.04, 0.015], [0.015, 0.01]])
    pts = ellipse_xy(np.array([1.0, -2.0]), cov)
    d = pts - [1.0, -2.0]
    m = np.einsum("ni,ij,nj->n", d, np.linalg.inv(cov), d)  # squared Mahalanobis distance
    np.testing.assert_allclose(m, 4.0, rtol=1e-9)


def _run_steps(agent, view, n: int):
    frames = []
    agent.robot.enable()
    for _ in range(n):
        agent.step()
        frames.append(view.panels.last_frame)
    return frames


def _sim_agent(world):
    from lab.identification.agent import IdentificationAgent
    from lab.sim import SimRobot, load_box_models

    models = load_box_models()
    world.add_carrier(models[1], Pose2D(0.0, 0.0, 0.0))
    robot = SimRobot(world, start=Pose2D(-1.0, 0.0, 0.0), seed=0)
    return IdentificationAgent(robot, [get_database(m.name) for m in models], planner="circle")


def test_view_in_a_widget_on_the_simulator(tmp_path):
    from lab.sim import SimWorld

    with SimWorld("arena") as world:  # the same run without a view: the reference
        plain = _sim_agent(world)
        plain.robot.enable()
        for _ in range(8):
            plain.step()
    with SimWorld("arena") as world:
        agent = _sim_agent(world)
        view = LiveView.for_identification(agent, rate_hz=None)
        assert isinstance(view.panels, IdentificationPanels)
        w = view.widget
        frames = _run_steps(agent, view, 8)
        assert view.n_draws == 8 and agent.on_step is view
        # watching does not change the run: the same posteriors, bit for bit
        np.testing.assert_array_equal([s.posterior for s in agent.steps], [s.posterior for s in plain.steps])
        pic = cv2.imdecode(np.frombuffer(w.value, np.uint8), cv2.IMREAD_COLOR)
        assert pic.shape == (540, 960, 3)
        np.testing.assert_array_equal(cv2.cvtColor(pic, cv2.COLOR_BGR2RGB), view.render())
        # the matches drawn are the frame's features, and as many as the EKF update used
        i = view.panels.top_model()
        assert i is not None  # the box is 1 m ahead: some model has a pose estimate after 8 frames
        matched, used = identification_inliers(agent, i)
        uv = agent.last_features.uv
        assert len(used) and all(np.any(np.all(uv == p, axis=1)) for p in used)
        assert len(used) <= agent.last_observation.updates[i].n_used <= len(agent.last_features)
        # the camera panel is the last frame with the estimated pose drawn over it (a few pixels)
        diff = np.any(view.camera_image != frames[-1].left, axis=2)
        assert 0 < diff.mean() < 0.2
        view.close()
        assert agent.on_step is None


def test_view_works_the_same_on_the_hardware_emulators(tmp_path):
    from hw_helpers import EMULATED_TOML

    from lab.hardware.camera import ReplayStereoSource
    from lab.hardware.config import load_config
    from lab.hardware.emulators import start_emulators
    from lab.hardware.robot import HardwareRobot
    from lab.identification.agent import IdentificationAgent

    emu = start_emulators(tmp_path)
    try:
        cfg = load_config(EMULATED_TOML).with_ports(base=emu.base_port, ptu=emu.ptu_port)
        cam = ReplayStereoSource.synthetic(cfg.camera.width, cfg.camera.height)
        with HardwareRobot(cfg, camera_source=cam) as robot:
            agent = IdentificationAgent(robot, [get_database(n) for n in box_model_names()], planner="circle")
            view = LiveView.for_identification(agent, rate_hz=None)
            w = view.widget
            frames = _run_steps(agent, view, 4)
            robot.stop()
        assert view.n_draws == 4 == len(agent.steps)
        pic = cv2.imdecode(np.frombuffer(w.value, np.uint8), cv2.IMREAD_COLOR)
        assert pic.shape == (540, 960, 3)  # the same picture as on the simulator
        # random dots show no box: no pose to draw, so the camera panel is exactly the robot's frame
        assert all(e is None for e in agent.bank.estimates)
        np.testing.assert_array_equal(view.camera_image, frames[-1].left)
        assert agent.steps[-1].head_mode == "scanning"
    finally:
        emu.close()


def test_teleop_panel_buttons_drive_the_carrier():
    from lab.sim import SimWorld, load_box_models
    from lab.sim.movers import make_mover

    with SimWorld("arena") as world:
        c = world.add_carrier(load_box_models()[0], Pose2D(0.0, 0.0, 0.0))
        c.mover = make_mover("teleop", c)
        panel = TeleopPanel(c.mover)
        b = panel.buttons
        assert set(b) == set(TeleopPanel.BUTTONS)
        b["forward"].click()
        world.step(2.0)
        assert c.pose.x == pytest.approx(2.0 * panel.speeds.speed, abs=1e-6) and abs(c.pose.y) < 1e-6
        b["left"].click()
        world.step(1.0)
        assert c.pose.theta == pytest.approx(panel.speeds.turn_rate, abs=1e-6)
        x = c.pose.x
        b["box left"].click()  # turn the box on the carrier; the carrier keeps turning on the spot
        world.step(1.0)
        assert c.box_yaw == pytest.approx(panel.speeds.box_turn_rate, abs=1e-6)
        assert c.pose.x == pytest.approx(x, abs=1e-6)
        b["stop"].click()
        before = (c.pose.x, c.pose.y, c.pose.theta, c.box_yaw)
        world.step(1.0)
        assert (c.pose.x, c.pose.y, c.pose.theta, c.box_yaw) == pytest.approx(before, abs=1e-9)
        assert panel.command == (0.0, 0.0, 0.0) and "v = +0.00 m/s" in panel._label.value
        with pytest.raises(ConfigError, match="unknown teleop button 'jump'; buttons: forward"):
            panel.press("jump")
        with pytest.raises(ConfigError, match="drives a teleop mover"):
            TeleopPanel(make_mover("static", c))


def test_search_view_follows_the_robot_between_events_at_its_rate(monkeypatch):
    """A kinematic robot drives for 3 s of sim time between the agent's events: the view redraws at
    2 Hz from the robot's steps, drawing the robot where its odometry says; close() unwraps the robot."""
    from nav_fakes import KinematicRobot

    import lab.search.agent as agent_mod
    from lab.navigation import GridSpec
    from lab.search.agent import SearchAgent, SearchEvent
    from lab.search.budget import BudgetedRobot
    from lab.search.probability_map import ProbabilityMap

    monkeypatch.setattr(agent_mod, "make_matcher", lambda db: None)
    robot = BudgetedRobot(KinematicRobot(Pose2D(0.0, -2.0, math.pi / 2)), 60.0)
    robot.enable()
    db = SimpleNamespace(name="toy_block")
    agent = SearchAgent(
        robot, db, lambda *a: None, ProbabilityMap(GridSpec.from_bounds(-3, -4, 3, 4, 0.2)),
        rng=np.random.default_rng(0),
    )  # fmt: skip
    view = LiveView.for_search(agent, rate_hz=2.0)
    assert isinstance(view.panels, SearchPanels)
    w = view.widget
    assert agent.observer is view and "step" in vars(robot)
    agent._event("global", detail="scripted")  # an event draws at once (t = 0)
    robot.drive(0.2, 0.0)
    for _ in range(30):
        robot.drive(0.2, 0.0)
        robot.step(0.1)
    assert view.n_calls == 1 and view.n_draws == 7  # t = 0 (event), then 0.5, 1.0, ..., 3.0 s
    p = robot.odometry()
    assert p.y > -1.5
    x, y = view.panels.a["map_robot"].get_data()
    assert (x[0], y[0]) == (p.x, p.y)
    assert cv2.imdecode(np.frombuffer(w.value, np.uint8), cv2.IMREAD_COLOR).shape == (540, 960, 3)
    view.close()
    assert agent.observer is None and "step" not in vars(robot)
    robot.step(0.1)
    assert view.n_draws == 7
    assert isinstance(agent._events[0], SearchEvent)


def test_bad_record_path_is_one_clear_line_before_the_run(tmp_path):
    r = subprocess.run(
        [sys.executable, "-m", "lab", "search", "--object", "toy_block", "--record", str(tmp_path / "r.avi")],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    assert "r.avi: the file must end in .gif or .mp4" in r.stderr
