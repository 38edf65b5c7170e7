"""The real room's errors (lab/sim/room_errors.py, issue 52): each has the size its docstring states in
the simulator, over many seeded draws (sample standard deviation within a few percent of the stated
sigma, the mismatch factor included where it applies); the robot's kinematics, odometry and map do
not see them; the error scale scales every one; bad input is one clear error."""

import dataclasses
import math

import numpy as np
import pytest

from lab.errors import ConfigError
from lab.geometry import Pose2D, pan_tilt_G_RP, relative_pose2d, se3_inv, wrap_angle
from lab.hardware.config import RoomConfig
from lab.robot import SIM_CAMERA
from lab.runs.room import sim_start_sigma, surveyed_map
from lab.sim import OdometryNoise, RoomErrors, SimRobot, SimWorld, sensing_profile
from lab.sim.episode import EpisodeSensing
from lab.sim.room_errors import TOLD_SIGMAS, rotation_rpy, survey_error
from lab.sim.sensing import PROFILES
from lab.training.landmarks import landmark_map_from_scene

REALISTIC = PROFILES["realistic"]
N = 4000  # draws per statistic: the sample std is within 3.5 % of sigma (3 standard errors: 3/sqrt(2N))
TOL = 0.035
LIGHT = (0.3, -0.4, 1.0)


def _only(**fields) -> dict:
    """A ``[sensing]`` table: ``ideal`` with just these room errors (mismatch 1)."""
    room = {f.name: 0.0 for f in dataclasses.fields(RoomErrors)}
    return {"profile": "ideal", "room": {**room, **fields}}


def _episodes(profile, n=N):
    cam = SIM_CAMERA.camera()
    return [EpisodeSensing(profile, s, cam, LIGHT) for s in range(n)]


def _angle_deg(R) -> float:
    return math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(R) - 1.0) / 2.0))))


def test_realistic_has_the_rooms_errors_with_their_stated_defaults():
    r = REALISTIC.room
    assert (r.survey_m, r.survey_deg, r.start_m, r.start_deg) == (0.015, 0.7, 0.05, 3.0)
    assert (r.camera_mount_deg, r.head_mount_deg, r.latency_s) == (0.5, 0.5, 0.05)
    assert (r.bump_slip_m, r.bump_slip_deg, REALISTIC.mismatch) == (0.02, 2.0, 1.5)
    # the localizer is told the start sigma a real robot's [room] start_sigma tells it
    assert (r.start_stated_m, r.start_stated_deg) == RoomConfig().start_sigma
    assert PROFILES["ideal"].room.is_none and PROFILES["ideal"].mismatch == 1.0


# --- the survey ---------------------------------------------------------------------------------------
def test_the_surveyed_map_is_off_by_the_stated_survey_times_the_mismatch():
    true = landmark_map_from_scene("lab_room")
    d = []
    for seed in range(N // len(true) + 1):
        m = surveyed_map(true, REALISTIC, seed)
        for a, b in zip(true, m, strict=True):
            assert a.name == b.name and a.size == b.size
            d.append([*np.subtract(b.centre_W, a.centre_W), wrap_angle(b.yaw - a.yaw)])
            # the face normal follows the surveyed yaw, still facing into the room
            assert np.dot(b.normal_W, a.normal_W) == pytest.approx(math.cos(b.yaw - a.yaw), abs=1e-12)
    d = np.array(d)
    sigma = 1.5 * np.array([0.015, 0.015, 0.015, math.radians(0.7)])
    assert np.all(np.abs(d.mean(axis=0)) < 0.06 * sigma)  # 3 standard errors of the mean
    assert d.std(axis=0) == pytest.approx(sigma, rel=TOL)
    # the stated accuracy the localizer is handed, and the true map untouched (the renderer draws it)
    assert REALISTIC.room.survey_sigma == (0.015, math.radians(0.7))
    assert landmark_map_from_scene("lab_room") == true


def test_a_posters_survey_error_depends_on_the_seed_and_its_name_only():
    e = survey_error(REALISTIC.room, 1.5, 7, "poster_north")
    assert e == survey_error(REALISTIC.room, 1.5, 7, "poster_north")
    assert e != survey_error(REALISTIC.room, 1.5, 8, "poster_north")
    assert e != survey_error(REALISTIC.room, 1.5, 7, "poster_south")
    true = landmark_map_from_scene("lab_room")
    assert surveyed_map(true, PROFILES["ideal"], 7).landmarks == true.landmarks  # no survey error


# --- the operator's start ---------------------------------------------------------------------------
def test_the_start_offsets_have_the_operators_placement_sigma():
    off = np.array([e.room.start_offset for e in _episodes(REALISTIC)])
    sigma = np.array([0.05, 0.05, math.radians(3.0)])  # no mismatch: the localizer is told more
    assert off.std(axis=0) == pytest.approx(sigma, rel=TOL)
    assert np.all(np.abs(off.mean(axis=0)) < 0.06 * sigma)


def test_the_odometry_starts_where_the_operator_believes_the_robot_stands():
    start = Pose2D(1.0, -2.0, 0.4)
    with SimWorld("arena") as w:
        r = SimRobot(w, start=start, seed=11, sensing="realistic")
        dx, dy, dth = w.truth.sensing.room.start_offset
        assert w.truth.robot_pose() == start  # the robot stands on its mark
        G = relative_pose2d(start, r.odometry())  # the odometry's start seen from the true one
        assert (G[0, 3], G[1, 3], math.atan2(G[1, 0], G[0, 0])) == pytest.approx((dx, dy, dth), abs=1e-12)
        assert math.hypot(dx, dy) > 0.005
        Sigma0 = sim_start_sigma(r)
    assert np.diag(Sigma0) == pytest.approx([0.1**2, 0.1**2, math.radians(5.0) ** 2], rel=1e-12)
    with SimWorld("arena") as w:
        r = SimRobot(w, start=start, seed=11, sensing="ideal")
        assert r.odometry() == start and sim_start_sigma(r) is None


# --- the mounts -------------------------------------------------------------------------------------
def test_the_mount_rotations_have_the_stated_sigma_times_the_mismatch():
    eps = _episodes(REALISTIC)
    sigma = math.radians(1.5 * 0.5)
    for which in ("head_mount_rpy", "camera_mount_rpy"):
        rpy = np.array([getattr(e.room, which) for e in eps])
        assert rpy.std(axis=0) == pytest.approx([sigma] * 3, rel=TOL), which


@pytest.mark.parametrize("which", ["head_mount_deg", "camera_mount_deg"])
def test_the_rendered_camera_carries_the_mount_error_the_kinematics_do_not(which):
    with SimWorld("arena") as w:
        r = SimRobot(w, start=Pose2D(0.0, 0.0, 0.3), seed=4, sensing=_only(**{which: 1.0}))
        r.enable()
        r.command_pan_tilt(0.5, -0.3)
        r.step(1.5)
        pt, draw = r.pan_tilt(), w.truth.sensing.room
        G_kin = w.truth.robot_pose().G() @ r.camera.G_RC(pt.pan, pt.tilt)  # what the robot computes
        G_true = w.truth.G_WC()
    rpy = draw.head_mount_rpy if which == "head_mount_deg" else draw.camera_mount_rpy
    other = draw.camera_mount_rpy if which == "head_mount_deg" else draw.head_mount_rpy
    assert other == (0.0, 0.0, 0.0)
    # the rotation between them is the drawn one (conjugated into the camera frame: same angle)
    dR = G_kin[:3, :3].T @ G_true[:3, :3]
    assert _angle_deg(dR) == pytest.approx(_angle_deg(rotation_rpy(rpy)), abs=1e-6)
    assert 0.05 < _angle_deg(dR) < 5.0
    G_RP = pan_tilt_G_RP(pt.pan, pt.tilt, r.camera.mount_R)
    c_R = (se3_inv(w.truth.robot_pose().G()) @ G_true)[:3, 3]  # the optical centre in R
    c_kin = r.camera.G_RC(pt.pan, pt.tilt)[:3, 3]
    if which == "camera_mount_deg":  # turned about its own optical centre: it stays put
        assert c_R == pytest.approx(c_kin, abs=1e-12)
    else:  # turned about the axes' intersection
        m = G_RP[:3, 3]
        assert c_R - m == pytest.approx(rotation_rpy(rpy) @ (c_kin - m), abs=1e-12)


# --- the latency ------------------------------------------------------------------------------------
def test_an_image_shows_the_robot_where_it_was_latency_before_its_stamp():
    speed, latency = 0.3, 0.05
    with SimWorld("arena") as w:
        r = SimRobot(w, start=Pose2D(-2.0, 0.0, 0.0), seed=2, sensing=_only(latency_s=latency))
        rendered = []
        render = w.render_stereo
        w.render_stereo = lambda G, *a, **k: rendered.append(G) or render(G, *a, **k)
        r.enable()
        for _ in range(40):  # up to speed (0.5 m/s^2), then steady
            r.drive(speed, 0.0)
            r.step(0.05)
        exposed = w.truth.G_WC_exposed()  # the truth of the camera the next image is rendered from
        f = r.capture_stereo()
        now = w.truth.G_WC()
        np.testing.assert_array_equal(exposed, rendered[-1])
        assert r.truth.pose().x - (-2.0) > 0.3
        lag = now[:3, 3] - rendered[-1][:3, 3]
        assert lag == pytest.approx([speed * latency, 0.0, 0.0], abs=1e-9)  # 1.5 cm behind
        assert f.t == w.t and f.odom == r.odometry()  # the stamps are current
        r.stop()
        r.step(0.2)
        r.capture_stereo()
        assert rendered[-1] == pytest.approx(w.truth.G_WC(), abs=1e-12)  # standing still: no lag
        assert w.truth.G_WC_exposed() == pytest.approx(w.truth.G_WC(), abs=1e-12)


# --- the mismatch -----------------------------------------------------------------------------------
def test_the_world_draws_what_the_robot_is_told_at_the_mismatch_factor():
    eps = _episodes(REALISTIC)
    cam = SIM_CAMERA.camera()
    told = REALISTIC.reported_camera(cam)
    fx = np.array([e.camera.render_camera.fx / cam.fx - 1.0 for e in eps])
    base = np.array([e.camera.render_camera.baseline / cam.baseline - 1.0 for e in eps])
    zero = np.degrees([[e.pan_tilt.pan_offset, e.pan_tilt.tilt_offset] for e in eps])
    assert fx.std() == pytest.approx(1.5 * told.focal_std, rel=TOL)
    assert base.std() == pytest.approx(1.5 * 0.005, rel=TOL)
    assert zero.std(axis=0) == pytest.approx([1.5 * REALISTIC.pan_tilt.zero_offset_deg] * 2, rel=TOL)
    track = np.array([e.odometry.e_track for e in eps])
    assert track.std() == pytest.approx(1.5 * REALISTIC.odometry.track_width_error, rel=TOL)
    slip = np.array([e.odometry.slip for e in eps])  # uniform in [0, 2 x 1.5 x the stated mean]
    assert slip.mean() == pytest.approx(1.5 * REALISTIC.odometry.spin_slip, rel=TOL)
    # the camera's stated pointing: the pan-tilt's zero and both mounts, per axis, in quadrature
    assert told.pointing_std_deg == pytest.approx(math.sqrt(0.05**2 + 0.5**2 + 0.5**2))
    drawn = REALISTIC.drawn()
    assert [getattr(drawn.room, k) for k in TOLD_SIGMAS] == [
        1.5 * getattr(REALISTIC.room, k) for k in TOLD_SIGMAS
    ]
    # the odometry's errors are told too (lab.runs.room.odometry_told): all drawn at the factor
    odo = dataclasses.fields(REALISTIC.odometry)
    assert [getattr(drawn.odometry, f.name) for f in odo] == [
        1.5 * getattr(REALISTIC.odometry, f.name) for f in odo
    ]
    assert drawn.room.latency_s == REALISTIC.room.latency_s
    assert drawn.camera.noise_grey_at_mid == REALISTIC.camera.noise_grey_at_mid  # not told: as stated


# --- the slip on a bump -----------------------------------------------------------------------------
def test_the_slip_draws_have_the_stated_sigma():
    rng = np.random.default_rng(0)
    d = np.array([REALISTIC.room.slip(rng) for _ in range(N)])
    assert d.std(axis=0) == pytest.approx([0.02, 0.02, math.radians(2.0)], rel=TOL)


def test_a_bump_moves_the_true_pose_and_the_odometry_does_not_see_it():
    sensing = _only(bump_slip_m=0.02, bump_slip_deg=2.0)
    with SimWorld("arena") as w:
        r = SimRobot(
            w, start=Pose2D(4.0, 0.0, 0.0), seed=9, sensing=sensing, odometry_noise=OdometryNoise.none()
        )
        expected = EpisodeSensing(r.sensing, 9, r.camera, LIGHT).bump_slip()  # the episode's first slip
        r.enable()
        while r.collisions == 0:
            r.drive(0.3, 0.0)
            r.step(0.02)
            assert r.truth.pose().x < 5.0
        true, odo = w.truth.robot_pose(), r.odometry()
    assert odo.y == 0.0 and odo.theta == 0.0  # the odometry saw a straight drive
    G = relative_pose2d(odo, true)  # the true pose seen from where the odometry thinks it is
    jump = np.array([G[0, 3], G[1, 3], math.atan2(G[1, 0], G[0, 0])])
    assert any(jump == pytest.approx(s * np.array(expected), abs=1e-9) for s in (1.0, -1.0))
    assert np.linalg.norm(jump[:2]) > 1e-3


# --- the error scale and the file ---------------------------------------------------------------------
def test_the_error_scale_scales_every_error_of_every_section():
    k = 2.5
    s = REALISTIC.scaled(k)
    assert s.name == "realistic x2.5" and s.mismatch == REALISTIC.mismatch
    for section in ("camera", "odometry", "pan_tilt", "room"):
        a, b = getattr(REALISTIC, section), getattr(s, section)
        for f in dataclasses.fields(a):
            assert getattr(b, f.name) == pytest.approx(k * getattr(a, f.name)), (section, f.name)
    assert REALISTIC.scaled(1) is REALISTIC and PROFILES["ideal"].scaled(3).camera.is_none
    assert REALISTIC.scaled(5).camera.light_direction_deg == 90.0  # the light's tilt is capped
    for bad in (0, -1, float("nan"), float("inf"), "2", True):
        with pytest.raises(ConfigError, match="error scale must be a finite number > 0"):
            REALISTIC.scaled(bad)


def test_the_room_section_and_the_mismatch_parse_from_a_sensing_table():
    p = sensing_profile({"profile": "realistic", "room": {"survey_m": 0.02}, "mismatch": 1.2})
    assert p.name == "realistic+custom" and p.room.survey_m == 0.02 and p.mismatch == 1.2
    assert p.room.start_m == REALISTIC.room.start_m
    with pytest.raises(
        ConfigError, match=r"sensing.room: unknown key\(s\) \['survey'\]; allowed: \['survey_m'"
    ):
        sensing_profile({"profile": "realistic", "room": {"survey": 0.02}})
    with pytest.raises(ConfigError, match="sensing.room.latency_s must be a finite number >= 0"):
        sensing_profile({"room": {"latency_s": -0.1}})
    with pytest.raises(ConfigError, match=r"sensing.room.latency_s must be within \[0, 1\] s"):
        sensing_profile({"room": {"latency_s": 3.0}})
    with pytest.raises(ConfigError, match="sensing.mismatch must be a finite number >= 1"):
        sensing_profile({"profile": "realistic", "mismatch": 0.5})
