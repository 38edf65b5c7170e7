"""The robot's track (lab.runs.tracks): wheel odometry, estimate and truth sampled as the robot steps."""

import math

import numpy as np
import pytest
from nav_fakes import KinematicRobot

from lab.errors import ConfigError
from lab.geometry import Pose2D
from lab.localization import LocalizedRobot
from lab.robot import RobotWrapper
from lab.runs.tracks import TrackedRobot


class DriftingOdometry(RobotWrapper):
    """The kinematic robot with wheels that read 3 % long: odometry integrates the true increments
    scaled by 1.03 (the kinematic robot's pose is the truth)."""

    def __init__(self, base: KinematicRobot):
        super().__init__(base)
        self._last = base.odometry()
        self._odom = np.array(self._last.as_array())

    def step(self, dt: float) -> None:
        self.base.step(dt)
        now = self.base.odometry()
        c, s = math.cos(self._last.theta), math.sin(self._last.theta)
        dx, dy = now.x - self._last.x, now.y - self._last.y
        fwd, side = c * dx + s * dy, -s * dx + c * dy  # in the last pose's frame
        th = self._odom[2]
        self._odom += 1.03 * np.array(
            [math.cos(th) * fwd - math.sin(th) * side, math.sin(th) * fwd + math.cos(th) * side, 0.0]
        )
        self._odom[2] += now.theta - self._last.theta
        self._last = now

    def odometry(self) -> Pose2D:
        return Pose2D(*(float(v) for v in self._odom))


def _drive(tracked, seconds: float, v=0.3, omega=0.2, dt=0.05):
    tracked.enable()
    for _ in range(round(seconds / dt)):
        tracked.drive(v, omega)
        tracked.step(dt)


def test_track_holds_odometry_estimate_and_truth_at_the_sample_times():
    kin = KinematicRobot(Pose2D(0.5, -1.0, 0.3))
    truths = []

    def truth_pose():
        p = kin.odometry()  # the kinematic robot's own pose is the truth
        truths.append((kin.now(), p))
        return p

    robot = LocalizedRobot(DriftingOdometry(kin), "odometry", log=lambda m: None)
    tracked = TrackedRobot(robot, truth_pose, record_every_s=0.5)
    _drive(tracked, 6.0)
    tr = tracked.track()
    assert tr.localization == "odometry" and not tr.localized
    assert len(tr) == len(truths) and 12 <= len(tr) <= 14  # one sample at the start, then every 0.5 s
    assert np.all(np.diff(tr.t) >= 0.5 - 1e-9)
    # the truth is what the callable gave, at the times it gave it
    assert tr.t.tolist() == [t for t, _ in truths]
    assert tr.truth == pytest.approx(np.array([p.as_array() for _, p in truths]))
    # the odometry drifted from the truth by the wheels' 3 % (of the distance from the start)
    d_true = np.linalg.norm(tr.truth[-1, :2] - tr.truth[0, :2])
    assert np.linalg.norm(tr.odometry[-1, :2] - tr.odometry[0, :2]) == pytest.approx(1.03 * d_true, rel=1e-6)
    assert np.linalg.norm(tr.odometry[-1, :2] - tr.truth[-1, :2]) > 0.02
    # in odometry mode the estimate is the odometry; the robot the agent sees reports it, not the truth
    assert tr.estimate == pytest.approx(tr.odometry)
    tracked.record(force=True)
    assert tracked.odometry().as_array() == pytest.approx(tracked.track().odometry[-1])
    assert np.linalg.norm(tracked.odometry().as_array()[:2] - kin.odometry().as_array()[:2]) > 0.02


def test_no_truth_is_none_and_a_forced_sample_comes_at_once():
    kin = KinematicRobot(Pose2D(0.0, 0.0, 0.0))
    tracked = TrackedRobot(LocalizedRobot(kin, "odometry", log=lambda m: None), lambda: None)
    _drive(tracked, 0.1)  # less than the spacing: no new sample
    assert len(tracked.track()) == 1
    tracked.record(force=True)
    tr = tracked.track()
    assert len(tr) == 2 and tr.truth is None
    assert tr.odometry[-1] == pytest.approx(kin.odometry().as_array())
    assert TrackedRobot(LocalizedRobot(kin, "odometry", log=lambda m: None)).track().truth is None


def test_bad_arguments_name_what_is_allowed():
    kin = KinematicRobot(Pose2D(0.0, 0.0, 0.0))
    with pytest.raises(ConfigError, match="LocalizedRobot's poses, got KinematicRobot"):
        TrackedRobot(kin)
    with pytest.raises(ConfigError, match="record_every_s must be a finite number of seconds > 0"):
        TrackedRobot(LocalizedRobot(kin, "odometry", log=lambda m: None), record_every_s=0.0)
