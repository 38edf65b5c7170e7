"""The odometry at an image's stamp: interpolation on the constant-velocity arc, the history of readings,
and the localizer using a late frame at its image's stamp.

Peers: the closed-form pose of a base driven at constant wheel speeds (an arc), the hardware's linear
interpolation (``lab.hardware.frame_time.pose_at``, equal on a straight line), and the measurement
model at the true pose of the image's stamp.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from nav_fakes import KinematicRobot

from lab.errors import ConfigError
from lab.geometry import Pose2D, wrap_angle
from lab.hardware.frame_time import pose_at
from lab.localization import (
    Landmark,
    LandmarkObservation,
    LocalizationMode,
    LocalizedRobot,
    measurement_model,
)
from lab.localization.stamps import OdometryHistory, interpolate_pose
from lab.robot import PanTiltState, StereoFrame

START = Pose2D(0.4, -1.2, 0.3)


def _arc(t: float, v: float = 0.3, w: float = 0.8, start: Pose2D = START) -> Pose2D:
    """The pose at ``t`` [s] of a base driven from ``start`` at constant ``v`` [m/s] and ``w`` [rad/s]."""
    th = start.theta + w * t
    if w == 0.0:
        return Pose2D(start.x + v * t * math.cos(th), start.y + v * t * math.sin(th), th)
    r = v / w
    return Pose2D(
        start.x + r * (math.sin(th) - math.sin(start.theta)),
        start.y - r * (math.cos(th) - math.cos(start.theta)),
        wrap_angle(th),
    )


def _close(a: Pose2D, b: Pose2D, atol: float) -> bool:
    return abs(a.x - b.x) < atol and abs(a.y - b.y) < atol and abs(wrap_angle(a.theta - b.theta)) < atol


@pytest.mark.parametrize("w", [0.8, -1.5, 2e-6, 0.0])  # 2e-6: the series near 0
@pytest.mark.parametrize("t", [1.0, 1.03, 1.07, 1.1])
def test_the_pose_between_two_readings_of_a_constant_velocity_drive_is_exact(w, t):
    """Readings 100 ms apart of a base at 0.3 m/s turning at ``w``: the pose at any stamp between them
    is the arc's, to rounding (and to the first reading at t_a, the second at t_b)."""
    a, b = (1.0, _arc(1.0, w=w)), (1.1, _arc(1.1, w=w))
    assert _close(interpolate_pose(t, a, b), _arc(t, w=w), 1e-10)  # the closed form loses digits near w = 0


def test_on_a_straight_line_it_is_the_hardwares_linear_interpolation_and_on_an_arc_it_is_not():
    a, b = (0.0, _arc(0.0, w=0.0)), (0.1, _arc(0.1, w=0.0))
    assert _close(interpolate_pose(0.04, a, b), pose_at(0.04, a, b), 1e-12)
    a, b = (0.0, _arc(0.0, v=1.0, w=3.0)), (0.5, _arc(0.5, v=1.0, w=3.0))  # a fast, tight turn
    lin = pose_at(0.25, a, b)
    assert _close(interpolate_pose(0.25, a, b), _arc(0.25, v=1.0, w=3.0), 1e-12)
    assert math.hypot(lin.x - _arc(0.25, v=1.0, w=3.0).x, lin.y - _arc(0.25, v=1.0, w=3.0).y) > 0.01


def test_the_history_interpolates_between_the_readings_around_a_stamp_and_keeps_a_short_span():
    h = OdometryHistory(span_s=0.5)
    with pytest.raises(ValueError, match="no reading"):
        h.at(0.0)
    for k in range(21):  # readings every 50 ms for 1 s; in between, the base turns faster (not linear)
        h.add(0.05 * k, _arc(0.05 * k))
    assert _close(h.at(0.93), _arc(0.93), 1e-12) and _close(h.at(0.95), _arc(0.95), 1e-15)
    assert h.t[0] >= 1.0 - 0.5 - 0.05 and len(h) <= 12  # older readings dropped
    assert h.at(0.1) == h.poses[0] and h.at(5.0) == _arc(1.0)  # beyond the kept span: the nearest reading
    h.add(0.3, _arc(0.3))  # out of order: ignored
    assert h.t[-1] == 1.0
    with pytest.raises(ConfigError, match="span_s"):
        OdometryHistory(span_s=0.0)


class _LateCameraRobot(KinematicRobot):
    """A base driven along the arc ``_arc`` whose images are ``latency`` old: exposed at ``now - latency``,
    the head and odometry read ``now``. ``stamped``: the frame's ``t`` is the image's exposure (a camera
    that stamps its frames), else ``now`` (the simulator's: the robot is told the latency)."""

    def __init__(self, latency: float, stamped: bool):
        super().__init__(START)
        self.latency, self.stamped = latency, stamped

    def odometry(self) -> Pose2D:
        return _arc(self._t)

    def step(self, dt: float) -> None:
        self._t += dt

    def capture_stereo(self, after=None):
        cam = self.camera
        img = np.zeros((cam.height, cam.width, 3), np.uint8)
        t = self._t - self.latency if self.stamped else self._t
        return StereoFrame(t, img, img, cam, PanTiltState(0.0, 0.0, self._t), _arc(self._t))


class _TrueObserver:
    """Sees one poster in every frame, exactly, from the true pose when the image was exposed."""

    def __init__(self, base: _LateCameraRobot):
        self.base = base
        self.lm = Landmark("p", (0.0, 3.94, 1.5), 0.0, (1.4, 0.02, 1.0), (0.0, -1.0))

    def candidates(self, x, frame):
        return [self.lm]

    def observe(self, frame, candidates):
        z = measurement_model(_arc(self.base.now() - self.base.latency).as_array(), self.lm.planar)
        return [LandmarkObservation(self.lm, np.eye(4), z, np.diag([1e-6, 1e-6, 1e-6]), 30)]


@pytest.mark.parametrize("stamped", [True, False])
@pytest.mark.parametrize("latency", [0.03, 0.08])
def test_a_late_frame_is_used_at_its_images_stamp(latency, stamped):
    """The robot drives (0.3 m/s, 0.8 rad/s; the localizer steps every 50 ms) and its camera's images are
    ``latency`` old: stamped so, or stamped now with the latency told to the localizer. The frame's
    wheels and ``odom`` are the pose when the image was exposed (to 1e-9; the newest reading is 2.4 cm
    and 3.8 deg from it at 80 ms), so an exact sighting from there is accepted with a zero innovation
    and leaves the estimate on the truth, also once it is predicted on to now."""
    base = _LateCameraRobot(latency, stamped)
    robot = LocalizedRobot(base, "odometry", camera_latency_s=0.0 if stamped else latency)
    robot.mode = LocalizationMode.LANDMARKS  # the observer below stands in for a trained map
    robot.observer = _TrueObserver(base)
    for k in range(40):
        robot.step(0.05)
        if k % 10 == 9:
            frame = robot.capture_stereo()
            t_img = base.now() - latency  # when the image was exposed
            assert _close(frame.wheel_odom, _arc(t_img), 1e-9) and _close(frame.odom, _arc(t_img), 1e-9)
            rec = robot.localizer.history[-1]
            assert rec.accepted and rec.nis < 1e-9
            assert _close(robot.odometry(), _arc(base.now()), 1e-9)
    late = _arc(base.now())
    assert math.hypot(late.x - _arc(base.now() - latency).x, late.y - _arc(base.now() - latency).y) > 0.008


def test_the_camera_latency_must_be_a_plausible_number_of_seconds():
    base = _LateCameraRobot(0.05, False)
    for bad in (-0.01, 2.0, math.nan):
        with pytest.raises(ConfigError, match="camera_latency_s must be within"):
            LocalizedRobot(base, "odometry", camera_latency_s=bad)


class _SlowHeadRobot(_LateCameraRobot):
    """The late camera on a standing base with a head that pans at 1 rad/s; ``arrived`` is when it
    reached its target."""

    def __init__(self, latency: float):
        super().__init__(latency, stamped=False)
        self.pan, self.target, self.arrived = 0.0, 0.0, 0.0

    def odometry(self) -> Pose2D:
        return START

    def command_pan_tilt(self, pan, tilt, speed=None) -> None:
        self.target = pan

    def pan_tilt(self) -> PanTiltState:
        return PanTiltState(self.pan, 0.0, self._t, self.target, 0.0, self.pan != self.target)

    def capture_stereo(self, after=None):
        img = np.zeros((self.camera.height, self.camera.width, 3), np.uint8)
        return StereoFrame(self._t, img, img, self.camera, self.pan_tilt(), START)

    def step(self, dt: float) -> None:
        self._t += dt
        if self.pan != self.target:
            self.pan = min(self.pan + dt, self.target)
            self.arrived = self._t


@pytest.mark.parametrize("latency", [0.0, 0.05])
def test_after_the_head_stops_the_localized_robot_waits_until_an_image_shows_it_stopped(latency):
    """``wait_pan_tilt`` returns when the head has arrived and, with a camera latency, once the next
    frame's image (exposed ``latency`` before its stamp) is exposed after the arrival; without one it
    returns at the arrival, as the plain robot does."""
    base = _SlowHeadRobot(latency)
    robot = LocalizedRobot(base, "odometry", camera_latency_s=latency)
    robot.command_pan_tilt(0.5, 0.0)
    state = robot.wait_pan_tilt(dt=0.01)
    assert not state.moving and state.pan == 0.5
    assert base.now() - latency >= base.arrived - 1e-12 and base.now() - base.arrived < latency + 1e-9


def test_a_frame_taken_while_the_head_slews_carries_the_heads_angle_when_its_image_was_exposed():
    """The head pans at 1 rad/s, the localizer steps every 10 ms and its camera's images are 50 ms old:
    a frame taken mid-slew carries the pan of 50 ms before (exact: the slew is linear), not the newest
    reading (2.9 deg further); without a latency the frame's own reading is kept."""
    base = _SlowHeadRobot(0.05)
    robot = LocalizedRobot(base, "odometry", camera_latency_s=0.05)
    robot.command_pan_tilt(1.0, 0.0)
    for _ in range(30):
        robot.step(0.01)
    frame = robot.capture_stereo()
    assert abs(base.pan - 0.3) < 1e-12
    assert abs(frame.pan_tilt.pan - 0.25) < 1e-9 and abs(frame.pan_tilt.t - (base.now() - 0.05)) < 1e-12
    plain = LocalizedRobot(_SlowHeadRobot(0.0), "odometry")
    plain.command_pan_tilt(1.0, 0.0)
    plain.step(0.1)
    assert plain.capture_stereo().pan_tilt.pan == plain.base.pan


class _SeenFromTheTruePan:
    """Sees one poster in every frame from the standing base, exactly, through the head's true angle
    when the image was exposed: the robot turns the sighting into R with the pan its frame carries, so a
    pan off by ``d`` turns the observation by ``d`` (``z = [Rot(d) z_xy, z_yaw + d]``)."""

    def __init__(self, base: _SlowHeadRobot):
        self.base = base
        self.lm = Landmark("p", (0.0, 3.94, 1.5), 0.0, (1.4, 0.02, 1.0), (0.0, -1.0))
        self.pan_errors: list[float] = []

    def candidates(self, x, frame):
        return [self.lm]

    def observe(self, frame, candidates):
        t_img = self.base.now() - self.base.latency
        d = frame.pan_tilt.pan - np.interp(t_img, *zip(*self.base.pans, strict=True))  # believed - true
        self.pan_errors.append(d)
        z = measurement_model(START.as_array(), self.lm.planar)
        c, s = math.cos(d), math.sin(d)
        z = np.array([c * z[0] - s * z[1], s * z[0] + c * z[1], wrap_angle(z[2] + d)])
        return [LandmarkObservation(self.lm, np.eye(4), z, np.diag([1e-8, 1e-8, 1e-8]), 30)]


@pytest.mark.parametrize("latency", [0.0, 0.05])
def test_a_re_localizations_views_carry_the_angle_the_head_stood_at_when_the_image_was_exposed(latency):
    """Active re-localization on a standing base whose head pans at 1 rad/s to the poster (1.35 rad):
    each view's frame carries the pan at its image's exposure, to 1e-9, with or without a camera
    latency, and the exact sighting leaves the estimate on the truth. Before, with a latency, the wait
    for the head stepped the base alone, the swing never reached the head's history, and the pan was
    interpolated between a reading from before the swing and one after it: 0.048 rad (2.8 deg) short, the
    heading turned by as much."""
    base = _SlowHeadRobot(latency)
    base.pans = [(0.0, 0.0)]
    step = base.step

    def logged_step(dt):
        step(dt)
        base.pans.append((base.now(), base.pan))

    base.step = logged_step
    robot = LocalizedRobot(base, "odometry", camera_latency_s=latency, Sigma0=np.diag([0.1, 0.1, 0.2]) ** 2)
    robot.mode = LocalizationMode.LANDMARKS  # the observer below stands in for a trained map
    robot.observer = _SeenFromTheTruePan(base)
    z = measurement_model(START.as_array(), robot.observer.lm.planar)
    robot.landmark_views = lambda tilt_max: [(math.atan2(z[1], z[0]), 0.0, "p")]
    for _ in range(5):
        robot.step(0.05)
    robot.relocalize()  # one view: the heading's floor (0.75 deg) stays above the threshold (0.5 deg)
    assert [r.accepted for r in robot.localizer.history] == [True]
    assert len(robot.observer.pan_errors) == 1 and abs(robot.observer.pan_errors[0]) < 1e-9
    x = robot.localizer.x
    assert math.hypot(x[0] - START.x, x[1] - START.y) < 1e-4 and abs(wrap_angle(x[2] - START.theta)) < 1e-4
    assert abs(base.pan) < 1e-12  # the head put back
