"""A synthetic lab room for the survey tour (:mod:`lab.localization.survey_tour`): a robot that the tour's
``navigate`` moves at once with drawn odometry errors, sightings of the true posters with drawn fit
errors reported against a surveyed map, and the shape error of a refined constellation. Shared by
``tests/test_survey_tour.py`` and ``benchmarks/survey_tour_design.py``.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from nav_fakes import KinematicRobot

from lab.geometry import Pose2D, wrap_angle
from lab.localization import LandmarkObservation, measurement_model, motion_model, odometry_increment
from lab.localization.survey_limit import survey_frame_error
from lab.robot import PanTiltState, StereoFrame
from lab.search.records import NavigationResult
from lab.training.landmarks import landmark_map_from_scene

ROOM = landmark_map_from_scene("lab_room")


def in_room(x, y, margin=0.6):
    """Whether (x, y) [m] is on the room's floor, ``margin`` [m] from its walls."""
    sx, sy = ROOM.room_size
    return abs(x) <= sx / 2 - margin and abs(y) <= sy / 2 - margin


class TourBase(KinematicRobot):
    """A robot that the tour's ``navigate`` moves at once: its true pose goes to the target, its wheel
    odometry by the same motion with a drawn error (2 % of the distance, 1 deg per radian turned, 0.3 deg
    per metre); the head turns at once; each frame is stamped with the wheels' reading."""

    def __init__(self, pose: Pose2D, rng: np.random.Generator):
        super().__init__(pose)
        self.rng = rng
        self.wheels = np.array([pose.x, pose.y, pose.theta])
        self.head = (0.0, 0.0)

    def odometry(self) -> Pose2D:
        return Pose2D(*(float(v) for v in self.wheels))

    def pan_tilt(self) -> PanTiltState:
        return PanTiltState(self.head[0], self.head[1], self._t)

    def command_pan_tilt(self, pan, tilt, speed=None) -> None:
        self.head = (float(pan), float(tilt))
        self._t += 1.0

    def wait_pan_tilt(self, timeout: float = 10.0) -> PanTiltState:
        return self.pan_tilt()

    def capture_stereo(self, after=None):
        self._t += 0.1
        cam = self.camera
        img = np.zeros((cam.height, cam.width, 3), np.uint8)
        return StereoFrame(self._t, img, img, cam, self.pan_tilt(), self.odometry())

    def navigate(self, target_xy, min_distance, max_distance) -> NavigationResult:
        x0 = self._pose.copy()
        heading = math.atan2(target_xy[1] - x0[1], target_xy[0] - x0[0])
        for goal in ([x0[0], x0[1], heading], [target_xy[0], target_xy[1], heading]):
            u = odometry_increment(Pose2D(*self._pose), Pose2D(*goal))
            d, turn = math.hypot(u[0], u[1]), abs(u[2])
            e = self.rng.normal(0.0, [0.02 * d, 0.02 * d, math.radians(1.0) * turn + math.radians(0.3) * d])
            self.wheels = motion_model(self.wheels, u + e)
            self.wheels[2] = wrap_angle(self.wheels[2])
            self._pose = np.array(goal, float)
        self._t += 10.0
        return NavigationResult(True, "ARRIVED", self.odometry(), None)


class Sightings:
    """Sees the true posters within 30 deg of where the camera looks, within range and facing, each
    with a fit's error drawn from ``Q``: 1.5 mm x (1 + (r / 2 m)^2) across the line of sight, 3 mm x
    (1 + (r / 1.5 m)^2) along it, 0.3 deg x (1 + (r / 2 m)^2) of yaw (the room's sightings: a few mm
    at 1-3 m, bearings only at 5-6 m), the along and yaw parts times ``along`` and ``yaw``; reported
    against the surveyed map ``mapped``."""

    def __init__(self, base: TourBase, mapped, rng, along: float = 1.0, yaw: float = 1.0):
        self.base, self.map, self.rng = base, mapped, rng
        self.along, self.yaw = along, yaw

    def candidates(self, x, frame):
        p = self.base._pose
        look = p[2] + frame.pan_tilt.pan
        out = []
        for lm in self.map:
            t = ROOM.get(lm.name)
            b = math.atan2(t.centre_W[1] - p[1], t.centre_W[0] - p[0])
            r = math.hypot(t.centre_W[0] - p[0], t.centre_W[1] - p[1])
            if abs(wrap_angle(b - look)) < math.radians(30) and r < 6.5 and t.facing(p[:2]) > 0.35:
                out.append(lm)
        return out

    def observe(self, frame, candidates):
        p = self.base._pose
        out = []
        for lm in candidates:
            z = measurement_model(p, ROOM.get(lm.name).planar)
            r = math.hypot(z[0], z[1])
            u = np.array([z[0], z[1]]) / r
            R = np.column_stack([u, [-u[1], u[0]]])
            grow = 1 + (r / 2.0) ** 2  # fewer and smaller features the farther the poster
            C = R @ np.diag([(self.along * 0.003 * (1 + (r / 1.5) ** 2)) ** 2, (0.0015 * grow) ** 2]) @ R.T
            Q = np.zeros((3, 3))
            Q[:2, :2], Q[2, 2] = C, math.radians(self.yaw * 0.3 * grow) ** 2
            out.append(
                LandmarkObservation(lm, np.eye(4), z + self.rng.multivariate_normal(np.zeros(3), Q), Q, 30)
            )
        return out


def survey_of(rng, sigma_m: float, sigma_rad: float, stated: tuple[float, float] | None = None):
    """The map a survey to ``sigma_m`` [m] / ``sigma_rad`` [rad] per poster gives, stated as ``stated``
    (default: as drawn), and each poster's error ``[dx, dy, dyaw]`` by name."""
    errors, mapped = {}, []
    for lm in ROOM:
        e = rng.normal(0.0, [sigma_m, sigma_m, sigma_rad])
        errors[lm.name] = e
        c = (lm.centre_W[0] + e[0], lm.centre_W[1] + e[1], lm.centre_W[2])
        mapped.append(replace(lm, centre_W=c, yaw=lm.yaw + e[2]))
    return errors, replace(ROOM, landmarks=tuple(mapped)).surveyed(*(stated or (sigma_m, sigma_rad)))


def shape_error(errors: dict) -> float:
    """The RMS position error [m] of the posters ``errors`` (by name: ``[dx, dy, dyaw]``) left after the
    turn-and-shift that best explains them (:func:`survey_frame_error` about the room's centre): how far
    the constellation's shape is off, whatever its frame."""
    names = sorted(errors)
    xy = [ROOM.get(n).centre_W[:2] for n in names]
    E = np.array([errors[n] for n in names])
    t = survey_frame_error(xy, E, (0.0, 0.0), 0.015, math.radians(0.7))  # the fit's weights: a ratio
    fitted = np.array([[t[0] - t[2] * y, t[1] + t[2] * x, t[2]] for x, y in xy])
    return float(np.sqrt(np.mean(np.sum((E - fitted)[:, :2] ** 2, axis=1))))
