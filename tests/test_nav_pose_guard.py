"""A drive stops when the pose becomes too uncertain to map on, re-localizes and drives on.

The navigator places every frame it maps with the robot's pose; after 88 s of driving without a
landmark a search's costmap held a slanted copy of a wall and the robot stood in it
(docs/tuning/room-errors.md). These tests drive the real navigator, the real localizer's covariance
(a kinematic base, no camera: the frames' mapping is recorded, and a re-localization is a landmark fix
stood in for by shrinking the covariance) and the search's :class:`RelocalizingNavigate`.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from nav_fakes import KinematicRobot

from lab.errors import ConfigError
from lab.geometry import Pose2D
from lab.localization import LocalizationMode, LocalizedRobot, LocalizerConfig
from lab.navigation import GridSpec, Navigator, NavOutcome
from lab.robot import PanTiltState
from lab.search.navigate import NavigatorAdapter
from lab.search.records import NavigationResult
from lab.search.report_policy import POSE_UNCERTAIN, ReportPolicy


class _HeadedRobot(KinematicRobot):
    """The kinematic base with a head that turns at once (the navigator points it along the path)."""

    head = (0.0, 0.0)

    def command_pan_tilt(self, pan, tilt, speed=None) -> None:
        self.head = (pan, tilt)

    def pan_tilt(self) -> PanTiltState:
        return PanTiltState(*self.head, self.now())


FIX_SIGMA = np.diag([0.01**2, 0.01**2, math.radians(0.3) ** 2])  # what a landmark fix leaves


class _FixingRobot(LocalizedRobot):
    """A localized kinematic robot whose re-localization is a landmark fix when ``landmark_in_view``
    (the covariance back to 1 cm / 0.3 deg; the mean is exact: the kinematic base has no odometry
    error) and does nothing otherwise."""

    def __init__(self, base, config=None, landmark_in_view=True):
        super().__init__(base, "odometry", config=config, log=lambda msg: None)
        self.mode = LocalizationMode.LANDMARKS  # the re-localization below stands in for a trained map
        self.landmark_in_view = landmark_in_view
        self.relocalizations: list[float] = []  # the position deviation [m] each started from
        self.messages: list[str] = []
        self.log = self.messages.append

    def relocalize(self, *args, **kwargs) -> bool:
        est = self.pose_estimate()
        c = self.config
        if est.sigma_xy_m <= c.relocalize_sigma_m and est.sigma_theta_rad <= c.relocalize_sigma_rad:
            return True
        self.relocalizations.append(est.sigma_xy_m)
        if self.landmark_in_view:
            self.localizer.Sigma = FIX_SIGMA
        return self.landmark_in_view


def _navigator(robot) -> Navigator:
    """An empty 10 m x 4 m room; the frames it would map are recorded with the pose's deviation."""
    nav = Navigator(robot, GridSpec((-1.0, -2.0), 0.1, (100, 40)))
    nav.mapped = []  # (x, position deviation [m], heading deviation [rad]) of each frame mapped

    def observe(frame=None):
        if not hasattr(robot, "pose_estimate"):  # the bare base: no deviation
            nav.mapped.append((robot.odometry().x, 0.0, 0.0))
            return
        est = robot.pose_estimate()
        nav.mapped.append((est.pose.x, est.sigma_xy_m, est.sigma_theta_rad))

    nav.observe = observe
    robot.capture_stereo = lambda after=None: None
    return nav


def test_the_drive_guard_names_the_deviation_that_passed_its_threshold():
    """The localizer's covariance grows as the wheels roll; the guard says so once it passes the drive's
    thresholds, naming both, and never on odometry alone (no landmark would help)."""
    cfg = LocalizerConfig(drive_sigma_m=0.10, drive_sigma_rad=math.radians(10.0))
    base = _HeadedRobot(Pose2D(0.0, 0.0, 0.0))
    robot = _FixingRobot(base, cfg)
    base.enable()
    assert robot.drive_guard() is None
    first = None
    for _ in range(400):
        base.drive(0.3, 0.0)
        base.step(0.1)
        why = robot.drive_guard()
        est = robot.pose_estimate()
        passed = est.sigma_xy_m > cfg.drive_sigma_m or est.sigma_theta_rad > cfg.drive_sigma_rad
        assert (why is not None) == passed
        if why is not None:
            first = why
            break
    assert first is not None and "past the drive's 10 cm / 10.0 deg" in first, first
    plain = LocalizedRobot(KinematicRobot(Pose2D(0.0, 0.0, 0.0)), "odometry", config=cfg)
    plain.localizer.Sigma = np.eye(3)  # 1 m, 57 deg: odometry mode has no guard
    assert plain.drive_guard() is None
    with pytest.raises(ConfigError, match="drive_sigma_rad must be > 0 rad"):
        LocalizerConfig(drive_sigma_rad=0.0)


def test_the_navigator_stops_before_mapping_a_frame_its_guard_refuses():
    """With a guard the drive ends POSE_UNCERTAIN with the guard's reason, without mapping the frame it
    refused; without one the same drive arrives."""
    base = _HeadedRobot(Pose2D(0.0, 0.0, 0.0))
    base.enable()
    nav = _navigator(base)
    nav.pose_guard = lambda: "too far" if base.odometry().x > 2.0 else None
    r = nav.go_to((6.0, 0.0), timeout=60.0)
    assert r.outcome is NavOutcome.POSE_UNCERTAIN and r.reason == "too far", r
    assert 2.0 < r.pose.x < 2.5 and max(x for x, _, _ in nav.mapped) <= 2.0
    assert r.frames == len(nav.mapped)
    nav.pose_guard = None
    assert nav.go_to((6.0, 0.0), timeout=60.0).arrived
    assert max(x for x, _, _ in nav.mapped) > 5.5


def test_a_long_drive_re_localizes_on_the_way_and_maps_no_frame_past_the_thresholds():
    """The search's navigate drives 8 m: the pose's deviation passes 10 cm on the way, the drive stops,
    the robot re-localizes (a landmark in view) and drives on to the target. The agent sees one drive
    that arrived, and no frame was mapped with a deviation past the drive's thresholds."""
    cfg = LocalizerConfig(drive_sigma_m=0.10, drive_sigma_rad=math.radians(10.0))
    base = _HeadedRobot(Pose2D(0.0, 0.0, 0.0))
    robot = _FixingRobot(base, cfg)
    base.enable()
    nav = _navigator(robot)
    adapter = NavigatorAdapter.__new__(NavigatorAdapter)  # the adapter round this navigator, no scan
    adapter.robot, adapter.timeout_s, adapter.navigator, adapter.scanned = robot, 120.0, nav, True
    navigate = ReportPolicy(robot, adapter, nav).relocalizing()
    r = navigate((8.0, 0.0), 0.0, 0.3)
    assert r.arrived and r.pose.x > 7.6, r
    assert len(robot.relocalizations) >= 2  # it stopped on the way (and not only before the drive)
    assert any(POSE_UNCERTAIN in m for m in robot.messages)
    assert all(s <= cfg.drive_sigma_m and th <= cfg.drive_sigma_rad for _, s, th in nav.mapped)
    assert nav.pose_guard is None  # not left behind for a detour's drive


def test_a_stop_no_landmark_can_help_drives_on_unguarded():
    """No landmark in view: the re-localization cannot bring the pose back, so after the first stop the
    drive goes on unguarded (standing still would not find a landmark either) and arrives."""
    cfg = LocalizerConfig(drive_sigma_m=0.10, drive_sigma_rad=math.radians(10.0))
    base = _HeadedRobot(Pose2D(0.0, 0.0, 0.0))
    robot = _FixingRobot(base, cfg, landmark_in_view=False)
    base.enable()
    nav = _navigator(robot)
    adapter = NavigatorAdapter.__new__(NavigatorAdapter)
    adapter.robot, adapter.timeout_s, adapter.navigator, adapter.scanned = robot, 120.0, nav, True
    r = ReportPolicy(robot, adapter, nav).relocalizing()((8.0, 0.0), 0.0, 0.3)
    assert r.arrived, r
    assert sum(POSE_UNCERTAIN in m for m in robot.messages) == 1


def test_the_stops_within_one_drive_are_bounded():
    """A guard that trips at every frame: after ``max_drive_stops`` re-localizations the drive goes on
    unguarded, and its result is what the agent gets."""
    calls = []

    class Robot:
        mode = LocalizationMode.LANDMARKS
        config = LocalizerConfig()

        def relocalize(self):
            calls.append("relocalize")

        def drive_guard(self):
            return None  # within the thresholds before every drive

        def log(self, msg):
            calls.append("log")

    class Nav:
        pose_guard = None

    nav = Nav()

    def drive(target_xy, lo, hi):
        guarded = nav.pose_guard is not None
        calls.append(("drive", guarded))
        if guarded:
            return NavigationResult(False, f"{POSE_UNCERTAIN}: drifted", None)
        return NavigationResult(True, "ARRIVED", None)

    r = ReportPolicy(Robot(), drive, nav).relocalizing()((1.0, 2.0), 0.0, 0.5)
    assert r.arrived and nav.pose_guard is None
    drives = [c for c in calls if isinstance(c, tuple)]
    assert drives == [("drive", True)] * 3 + [("drive", False)]
    assert calls.count("relocalize") == 4
