"""The rehearsal: HardwareRobot on the device emulators with a camera that renders the simulator's world
from the emulators' true state (lab/runs/rehearsal.py), and the identification agent on it.

Peers: the simulator's own rendering of the ideal rectified pair at the true camera pose (what the adapter's
rectification of the raw pair must reproduce, measured with OpenCV's phase correlation), and the emulators'
true state (base pose, head angles).
"""

from __future__ import annotations

import dataclasses
import math
import re

import cv2
import numpy as np
import pytest
from hw_helpers import REPO, wait_until

from lab.errors import ConfigError
from lab.geometry import Pose2D
from lab.hardware.camera import make_camera_source
from lab.hardware.config import load_config
from lab.hardware.frame_time import pan_tilt_at, pose_at
from lab.robot import PanTiltState
from lab.runs.rehearsal import rehearsal
from lab.vision.rectify import StereoCalibration

REHEARSAL_TOML = REPO / "hardware" / "rehearsal.toml"


def _shift_px(a: np.ndarray, b: np.ndarray, margin: int = 40) -> float:
    """Translation [px] between two RGB images' centres (OpenCV phase correlation)."""
    ga, gb = (np.float32(cv2.cvtColor(x, cv2.COLOR_RGB2GRAY)[margin:-margin, margin:-margin]) for x in (a, b))
    (dx, dy), _ = cv2.phaseCorrelate(ga, gb)
    return math.hypot(dx, dy)


def test_rehearsal_toml_selects_the_rendered_camera():
    cfg = load_config(REHEARSAL_TOML)
    assert cfg.camera.source == "sim" and cfg.sim.world == "arena"
    assert cfg.robot.cmd_timeout_s == 0.5  # the real robot's watchdog, not a relaxed one
    with pytest.raises(ConfigError, match=r'source = "sim" .*rehearsal\(\)'):
        make_camera_source(cfg)  # it needs the emulators' truth: only a rehearsal can build it


def test_check_explains_the_rendered_camera_and_the_room(tmp_path, capsys):
    """`lab hardware check --emulate`: the camera line, then the room's lines (lab.runs.room.check_room)
    before the summary, which counts them."""
    from lab.cli import main

    text = REHEARSAL_TOML.read_text().replace("/tmp/lab-emulators", str(tmp_path / "links"))
    text = text.replace('"calibration/', f'"{REPO}/hardware/calibration/')
    p = tmp_path / "r.toml"
    p.write_text(text)
    capsys.readouterr()
    assert main(["hardware", "check", "--config", str(p), "--emulate"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert any(ln.startswith("PASS  camera: rendered by the simulator (world 'arena')") for ln in lines)
    kinds = [ln.split(":")[0] for ln in lines]
    assert kinds[-3:-1] == ["PASS  landmark map", "PASS  start"], lines
    n = sum(ln.startswith(("PASS", "FAIL")) for ln in lines)
    assert lines[-1] == f"all checks passed ({n}/{n})"


def test_unknown_world_is_one_clear_line(tmp_path):
    text = REHEARSAL_TOML.read_text().replace('world = "arena"', 'world = "moon"')
    text = text.replace('"calibration/', f'"{REPO}/hardware/calibration/')
    p = tmp_path / "r.toml"
    p.write_text(text)
    with pytest.raises(ConfigError, match=r"\[sim\] world 'moon' is not a world; worlds: .*arena"):
        load_config(p)


def test_frames_follow_the_emulators_true_head_and_base():
    cfg = load_config(REHEARSAL_TOML)
    cfg = dataclasses.replace(cfg, ptu=dataclasses.replace(cfg.ptu, pan_sign=-1, tilt_zero_offset_deg=2.0))
    with rehearsal(cfg, true_model=0, box_yaw=0.0) as r:
        robot, create = r.robot, r.emulators.create
        f0 = robot.capture_stereo()
        t0 = r.truth()
        start = cfg.sim.robot_start
        assert (t0.base_W.x, t0.base_W.y, t0.base_W.theta) == pytest.approx((start[0], start[1], 0.0))
        assert (f0.odom.x, f0.odom.y) == (0.0, 0.0)
        robot.enable()
        robot.set_pan_tilt(0.4, -0.2, wait=True, timeout=5.0)
        for _ in range(12):  # a short arc
            robot.drive(0.2, 0.5)
            robot.step(0.05)
        robot.stop()
        f1 = robot.capture_stereo()
        t1 = r.truth()
        # the head's true angles (emulator steps through the config's sign and offset) are what it reports
        assert t1.pan == pytest.approx(0.4, abs=1e-3) and t1.tilt == pytest.approx(-0.2, abs=1e-3)
        assert f1.pan_tilt.pan == pytest.approx(t1.pan, abs=1e-3)
        # the base's true pose is start + the emulator's pose; odometry (encoders) agrees with it
        assert math.hypot(create.x, create.y) > 0.05
        s = Pose2D(start[0], start[1], 0.0)
        assert t1.base_W.x == pytest.approx(s.x + create.x, abs=1e-3)
        assert (f1.odom.x, f1.odom.y) == pytest.approx((create.x, create.y), abs=0.01)
        assert f1.odom.theta == pytest.approx(create.theta, abs=0.02)
        # the frame is the simulator's view from the true camera pose
        left, right = r.world.render_stereo(t1.G_WC, robot.camera)
        assert _shift_px(f1.left, left) < 0.3 and np.abs(f1.left.astype(int) - left).mean() < 3.0


@pytest.mark.parametrize("profile", ["ideal", "realistic"])
def test_the_rendered_camera_follows_the_sensing_profile_and_the_result_says_so(profile):
    """Two captures from the same standing pose: identical under ``ideal``; under ``realistic`` they
    differ by the capture noise (a couple of grey levels, the profile's figure, smoothed a little by the
    rectification) and the episode's calibration and light move the image off the ideal render."""
    from lab.runs.robots import make_robot

    with make_robot(REHEARSAL_TOML, true_model=0, seed=5, sensing=profile) as session:
        a, b = session.robot.capture_stereo(), session.robot.capture_stereo()
        ideal_left, _ = session.world.render_stereo(session.rehearsal.truth().G_WC, session.robot.camera)
        assert session.sensing == profile  # the JSON's "sensing"
        assert session.sensing_applies_to == ["camera"]  # odometry and head are the emulators'
    diff = a.left.astype(float) - b.left.astype(float)
    off_ideal = np.abs(a.left.astype(float) - ideal_left).mean()
    if profile == "ideal":
        assert not diff.any() and off_ideal < 1.0
    else:
        assert 0.8 < diff.std() / math.sqrt(2) < 3.0  # each capture's own noise
        assert off_ideal > 2.0


def test_raw_pair_of_a_real_calibration_is_rectified_to_the_simulators_view(tmp_path):
    """A calibration with unequal intrinsics and a rotated, offset right camera: the source renders the raw
    pinhole pair, the adapter rectifies it, and the result is the ideal rectified pair at the true pose."""
    K1 = np.array([[200.0, 0, 158.0], [0, 201.0, 122.0], [0, 0, 1]])
    K2 = np.array([[206.0, 0, 162.0], [0, 205.0, 117.0], [0, 0, 1]])
    R, _ = cv2.Rodrigues(np.array([0.01, -0.02, 0.008]))
    calib = StereoCalibration.from_intrinsics(
        K1, np.zeros(5), K2, np.zeros(5), R, [-0.12, 0.004, 0.002], (320, 240)
    )
    calib.save(tmp_path / "calib.yml")
    cfg = load_config(REHEARSAL_TOML)
    cfg = dataclasses.replace(
        cfg, camera=dataclasses.replace(cfg.camera, calibration=str(tmp_path / "calib.yml"))
    )
    with rehearsal(cfg, true_model=2, box_yaw=0.0) as r:
        frame = r.robot.capture_stereo()
        raw = r.source.read()  # the same view (nothing moved), unrectified
        truth = r.truth()
        ideal_l, ideal_r = r.world.render_stereo(truth.G_WC, r.robot.camera)
    assert _shift_px(frame.left, ideal_l) < 0.5 and _shift_px(frame.right, ideal_r) < 0.5
    assert _shift_px(raw.right, ideal_r) > 2.0  # the raw right image is not (the check sees the difference)


def test_head_and_odometry_are_read_at_the_frames_time():
    a = PanTiltState(0.0, 0.1, t=10.0, pan_target=1.0, tilt_target=0.1, moving=True)
    b = PanTiltState(0.4, 0.1, t=10.2, pan_target=1.0, tilt_target=0.1, moving=True)
    s = pan_tilt_at(10.05, a, b)
    assert s.pan == pytest.approx(0.1) and s.tilt == pytest.approx(0.1) and s.t == 10.05 and s.moving
    assert pan_tilt_at(9.0, a, b).pan == 0.0 and pan_tilt_at(11.0, a, b).pan == 0.4  # clamped
    p = pose_at(1.5, (1.0, Pose2D(0.0, 0.0, 3.0)), (2.0, Pose2D(0.2, -0.2, -3.0)))
    assert (p.x, p.y) == pytest.approx((0.1, -0.1))
    assert abs(abs(p.theta) - math.pi) < 1e-9  # across the +-pi seam, the short way
    q = pose_at(5.0, (1.0, Pose2D(1, 2, 0.1)), (1.0, Pose2D(3, 4, 0.2)))  # no interval: the first reading
    assert (q.x, q.y, q.theta) == pytest.approx((1, 2, 0.1))


def _small_lookup_tables(camera):
    """The lookup-table evaluator on tables of four training poses (one render each): the planner's
    machinery as it runs, without the minutes the full tables take to build (`lab tables`); this test
    is about the hardware path, not about how good the plan is."""
    from lab.identification import LookupTableEvaluator, LookupTables, shared_features
    from lab.training import TableParams, build_model_tables, get_database

    names = ("M0", "M1", "M2", "M3")
    dbs = [get_database(n, progress=False) for n in names]
    rows = (0, 9, 18, 27)  # the unique face and the three shared ones
    built = [build_model_tables(n, dbs, TableParams(repeats=1), viewpoint_indices=rows) for n in names]
    shared = shared_features(dbs)
    return LookupTableEvaluator(LookupTables.from_model_tables(built, shared=shared), camera, shared=shared)


@pytest.mark.slow
def test_identification_agent_unchanged_on_the_emulators_with_rendered_frames():
    """Two planning actions of the unchanged IdentificationAgent through HardwareRobot (emulators, wall
    clock); the base and head move in the emulators' truth, and the beliefs are sensible."""
    from lab.identification.agent import AgentConfig, IdentificationAgent
    from lab.training import get_database

    true_model = 1
    with rehearsal(REHEARSAL_TOML, true_model=true_model, mover="static", seed=0) as r:
        robot, create, ptu = r.robot, r.emulators.create, r.emulators.ptu
        agent = IdentificationAgent(
            robot,
            [get_database(n, progress=False) for n in ("M0", "M1", "M2", "M3")],
            planner="lut",
            seed=0,
            config=AgentConfig(max_actions=2, max_time_s=300.0),  # wall clock: room for a loaded machine
            evaluator=_small_lookup_tables(robot.camera),
        )
        # the whole episode: two goals, then the final look from the last one with the base at rest (the
        # wall-clock rehearsal's frames lag the head under load while it moves: the pose is checked at rest)
        agent.run()
        truth = r.truth()
        moved = math.hypot(create.x, create.y)
        head_moves = [c for c in ptu.command_names() if re.match(r"^[PT]P[-+]?\d+$", c, re.IGNORECASE)]
        est = agent.bank.estimates[true_model]
        # run() stopped the base on the way out (the emulator reads its serial line in its own thread,
        # which a loaded machine can hold back for a moment: a liveness wait, returns at once when seen)
        assert wait_until(lambda: create.wheel_speeds() == (0, 0), 2.0), create.wheel_speeds()
    assert agent.n_actions >= 2
    assert moved > 0.1, "the base did not move (emulator truth)"
    assert len(head_moves) >= 5  # the head tracked: position commands reached the PTU
    assert abs(truth.pan) > 0.05 or abs(truth.tilt) > 0.05, "the head did not move (emulator truth)"
    P = agent.P
    assert np.all(P >= 0) and P.sum() == pytest.approx(1.0)
    assert agent.identified in (None, true_model)  # never a wrong model
    # the true model's filter has the box where it truly is (camera frame at the last frame)
    assert est is not None
    G_CO_true = np.linalg.inv(truth.G_WC) @ truth.G_WO
    assert np.linalg.norm(est.G_CO[:3, 3] - G_CO_true[:3, 3]) < 0.1
