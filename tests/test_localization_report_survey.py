"""The report's re-localization against a surveyed map: the found point tied to every poster in view.

With the posters in the localizer's state, the robot's pose in the room is only as good as the surveys
of the posters it is tied to. A robot that has seen one poster well (a search that found its object
beside it) carries that poster's survey error whole; one view of every other poster in view from the
same place ties them together, and the reported point then carries the error of their survey's frame.

Peers: the true poses the seeded survey and sightings are drawn from, and the generalised least-squares
fit of a rigid planar transform between the true and the surveyed posters (SciPy's ``lstsq`` on the
whitened equations): the error of the frame that the posters' surveys define, which no estimate from
those posters can beat.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from nav_fakes import KinematicRobot
from scipy.linalg import lstsq

from lab.geometry import Pose2D, relative_pose2d, wrap_angle
from lab.localization import (
    LandmarkMap,
    LandmarkObservation,
    LocalizationMode,
    LocalizedRobot,
    LocalizerConfig,
    inward_normal,
    measurement_model,
)
from lab.robot import PanTiltState, StereoFrame
from lab.training.landmarks import landmark_map_from_scene

SURVEY_M, SURVEY_RAD = 0.015, math.radians(0.7)
TRUE = Pose2D(-1.7, 2.6, math.pi)  # by the shelf, looking into the room
P_W = np.array([TRUE.x - 0.8, TRUE.y])  # the found object's point, 0.8 m ahead


class _HeadRobot(KinematicRobot):
    """The kinematic robot with a blank stereo camera and a head that is where it was told at once."""

    head = (0.0, 0.0)

    def pan_tilt(self):
        return PanTiltState(*self.head, self.now(), *self.head)

    def command_pan_tilt(self, pan, tilt, speed=None):
        self.head = (float(pan), float(tilt))

    def capture_stereo(self, after=None):
        cam = self.camera
        img = np.zeros((cam.height, cam.width, 3), np.uint8)
        return StereoFrame(self.now(), img, img, cam, self.pan_tilt(), self.odometry())


class _SurveyObserver:
    """Sees the poster the head points at (within 5 deg) as from the robot's true pose against the true
    poster, with noise drawn from the covariance the filter is told, and reports it as the map's."""

    def __init__(self, robot, truth: LandmarkMap, mapped: LandmarkMap, config, rng):
        self.robot, self.truth, self.map, self.config, self.rng = robot, truth, mapped, config, rng
        self.Q = np.diag([0.005**2, 0.005**2, math.radians(0.3) ** 2])
        self.seen: dict[str, int] = {}

    def candidates(self, x, frame):
        true = self.robot.odometry().as_array()
        return [
            lm
            for lm in self.map
            if abs(wrap_angle(self.map.bearing_in_robot(lm, true)[1] - frame.pan_tilt.pan))
            < math.radians(5.0)
        ]

    def observe(self, frame, candidates):
        true = self.robot.odometry().as_array()
        out = []
        for lm in candidates:
            self.seen[lm.name] = self.seen.get(lm.name, 0) + 1
            z0 = measurement_model(true, self.truth.get(lm.name).planar)
            C = self.Q + self.config.observation_floor(z0)
            out.append(
                LandmarkObservation(
                    lm, np.eye(4), z0 + self.rng.multivariate_normal(np.zeros(3), C), self.Q, 30
                )
            )
        return out


def _surveyed(truth: LandmarkMap, rng) -> LandmarkMap:
    """The map a survey gives: each poster off by a draw of the stated 1.5 cm / 0.7 deg."""
    out = []
    for lm in truth:
        e = rng.normal(0.0, [SURVEY_M, SURVEY_M, SURVEY_RAD])
        c = (lm.centre_W[0] + e[0], lm.centre_W[1] + e[1], lm.centre_W[2])
        out.append(
            replace(lm, centre_W=c, yaw=lm.yaw + e[2], normal_W=inward_normal(c, lm.yaw + e[2], lm.size))
        )
    return LandmarkMap(tuple(out), truth.room_size).surveyed(SURVEY_M, SURVEY_RAD)


def _frame_error_at(truth: LandmarkMap, mapped: LandmarkMap, names, p) -> np.ndarray:
    """The error at ``p`` of the frame the named posters' surveys define: the weighted least-squares
    rigid transform (dx, dy, dtheta about W's origin) from the true posters to the surveyed ones."""
    A, b = [], []
    for n in names:
        (xt, yt, pt), (xm, ym, pm) = truth.get(n).planar, mapped.get(n).planar
        A += [[1 / SURVEY_M, 0, -yt / SURVEY_M], [0, 1 / SURVEY_M, xt / SURVEY_M], [0, 0, 1 / SURVEY_RAD]]
        b += [(xm - xt) / SURVEY_M, (ym - yt) / SURVEY_M, wrap_angle(pm - pt) / SURVEY_RAD]
    T = lstsq(np.array(A), np.array(b))[0]
    return np.array([T[0] - T[2] * p[1], T[1] + T[2] * p[0]])


def _placed_point(est) -> np.ndarray:
    """The object's point as the robot places it from its estimate (fixed in the robot's frame)."""
    p_R = relative_pose2d(TRUE, Pose2D(*P_W, 0.0))[:2, 3]
    return est.pose.G()[:2, :2] @ p_R + [est.pose.x, est.pose.y]


def _robot_tied_to_the_shelf(truth, mapped, cfg, rng) -> LocalizedRobot:
    """A robot that has seen only poster_shelf, five times, from a start known to 5 cm / 2 deg."""
    base = _HeadRobot(TRUE)
    base.enable()
    robot = LocalizedRobot(base, "odometry", config=cfg, log=lambda m: None)
    robot.mode = LocalizationMode.LANDMARKS  # the observer below stands in for a trained map
    robot.observer = _SurveyObserver(base, truth, mapped, cfg, rng)
    robot.localizer.x = TRUE.as_array() + rng.normal(0.0, [0.05, 0.05, math.radians(2.0)])
    robot.localizer.Sigma = np.diag([0.05**2, 0.05**2, math.radians(2.0) ** 2])
    pan = next(p for p, _, n in robot.landmark_views() if n == "poster_shelf")
    base.command_pan_tilt(pan, 0.0)
    for _ in range(5):
        robot.capture_stereo()
    return robot


def test_a_report_with_a_surveyed_map_ties_the_point_to_every_poster_in_view():
    """40 seeded surveys (every poster off by draws of the stated 1.5 cm / 0.7 deg). The robot has seen
    only poster_shelf; the re-localization the thresholds alone ask for (the report's sigmas, passes
    and views) stops after a poster or two; the report's looks at every poster in view once first.
    Its reported point's median error is below the thresholds-only one's (1.2 cm against 1.6 cm when
    written), within 50 % of the median error of the frame the surveys of the posters in view define
    (the least-squares peer, 0.9 cm: the limit for those posters were each seen without error; one
    view each adds the observation's own error), and its stated covariance is honest (the point's NEES,
    chi-square 2, has a mean within [1, 3])."""
    truth = landmark_map_from_scene("lab_room")
    cfg = LocalizerConfig()
    err_report, err_thresholds, err_limit, nees = [], [], [], []
    for seed in range(40):
        mapped = _surveyed(truth, np.random.default_rng([seed, 1]))
        robot = _robot_tied_to_the_shelf(truth, mapped, cfg, np.random.default_rng([seed, 2]))
        robot.relocalize_to_report(at_W=P_W)
        est = robot.pose_estimate()
        e = _placed_point(est) - P_W
        err_report.append(np.linalg.norm(e))
        J = np.array([[1.0, 0.0, -(P_W[1] - est.pose.y)], [0.0, 1.0, P_W[0] - est.pose.x]])
        nees.append(float(e @ np.linalg.solve(J @ est.Sigma @ J.T, e)))
        in_view = [n for n, k in robot.observer.seen.items() if k > 0]
        err_limit.append(np.linalg.norm(_frame_error_at(truth, mapped, in_view, P_W)))
        # the same robot and sightings, re-localized to the thresholds alone
        robot = _robot_tied_to_the_shelf(truth, mapped, cfg, np.random.default_rng([seed, 2]))
        robot.relocalize()
        robot.relocalize(
            cfg.report_max_views,
            sigma_m=cfg.report_sigma_m,
            sigma_rad=cfg.report_sigma_rad,
            passes=cfg.report_passes,
            at_W=P_W,
        )
        err_thresholds.append(np.linalg.norm(_placed_point(robot.pose_estimate()) - P_W))
    med = {
        k: 100 * np.median(v)
        for k, v in (("report", err_report), ("thresholds", err_thresholds), ("limit", err_limit))
    }
    print(
        f"point error median: report {med['report']:.2f} cm, thresholds only {med['thresholds']:.2f} cm, "
        f"the surveys' frame {med['limit']:.2f} cm; NEES mean {np.mean(nees):.2f}; in view {len(in_view)}"
    )
    assert med["report"] < 0.85 * med["thresholds"]
    assert med["report"] < 1.5 * med["limit"]
    assert 1.0 < np.mean(nees) < 3.0
