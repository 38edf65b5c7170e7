"""The survey tour (lab.localization.survey_tour): its stands, and what driving it does to a surveyed map.

Peers: the lab room's own geometry (every poster seen well from a stand; the stands on the free floor),
and the least squares floor of :mod:`lab.localization.survey_limit` (itself checked against SciPy): after
the tour a robot's error is what all the posters' surveys leave together, not what its nearest posters'
do.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from localization_helpers import NO_FLOOR
from nav_fakes import KinematicRobot

from lab.geometry import Pose2D, wrap_angle
from lab.localization import (
    LandmarkObservation,
    LocalizationMode,
    LocalizedRobot,
    LocalizerConfig,
    measurement_model,
    motion_model,
    odometry_increment,
)
from lab.localization.survey_limit import survey_frame_error
from lab.localization.survey_tour import posters_seen_well, survey_stands, survey_tour
from lab.robot import PanTiltState, StereoFrame
from lab.search.records import NavigationResult
from lab.training.landmarks import landmark_map_from_scene

ROOM = landmark_map_from_scene("lab_room")
SURVEY_M, SURVEY_RAD = 0.015, math.radians(0.7)


def _in_room(x, y, margin=0.6):
    sx, sy = ROOM.room_size
    return abs(x) <= sx / 2 - margin and abs(y) <= sy / 2 - margin


def test_the_stands_see_every_poster_well_from_the_free_floor_in_the_order_driven():
    """With a table's worth of floor blocked: every stand is free, every poster that some free point sees
    well is seen well from a stand, each stand adds one the stands before it did not see well, and
    each next stand is the nearest of those left. Asked to, the stands see each poster well twice."""

    def free(x, y):
        return _in_room(x, y) and not (-1.0 <= x <= 1.0 and -0.5 <= y <= 0.5)

    start = (-1.5, -2.5)
    stands = survey_stands(ROOM, free, start_xy=start)
    assert stands and all(free(*p) for p in stands)
    grid = [(x, y) for x in np.arange(-3, 3, 0.5) for y in np.arange(-4, 4, 0.5) if free(x, y)]
    reachable = set().union(*(posters_seen_well(ROOM, p) for p in grid))
    covered = set().union(*(posters_seen_well(ROOM, p) for p in stands))
    assert covered == reachable and len(reachable) == len(ROOM)
    assert len(stands) <= len(ROOM) // 2
    at, left = start, list(stands)
    for p in stands:
        assert math.dist(p, at) == pytest.approx(min(math.dist(q, at) for q in left))
        left.remove(p)
        at = p
    assert survey_stands(ROOM, lambda x, y: False) == []
    # cover=2: every poster seen well from two stands, or from every free point that sees it well
    two = survey_stands(ROOM, free, start_xy=start, cover=2)
    assert len(set(two)) == len(two) and all(free(*p) for p in two) and len(two) > len(stands)
    for lm in ROOM:
        can = sum(lm.name in posters_seen_well(ROOM, p) for p in grid)
        assert sum(lm.name in posters_seen_well(ROOM, p) for p in two) >= min(2, can)
    with pytest.raises(ValueError, match="cover"):
        survey_stands(ROOM, free, cover=0)
    with pytest.raises(ValueError, match="spacing_m"):
        survey_stands(ROOM, free, spacing_m=0.0)
    with pytest.raises(ValueError, match="range_m"):
        survey_stands(ROOM, free, range_m=(3.0, 1.0))
    with pytest.raises(ValueError, match="passes"):
        survey_tour(None, None, [], passes=0)


class _TourBase(KinematicRobot):
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


class _Sightings:
    """Sees the true posters within 30 deg of where the camera looks, within range and facing, each
    with a fit's error drawn from ``Q``: 1.5 mm x (1 + (r / 2 m)^2) across the line of sight, 3 mm x
    (1 + (r / 1.5 m)^2) along it, 0.3 deg x (1 + (r / 2 m)^2) of yaw (the room's sightings: a few mm
    at 1-3 m, bearings only at 5-6 m); reported against the surveyed map ``mapped``."""

    def __init__(self, base: _TourBase, mapped, rng):
        self.base, self.map, self.rng = base, mapped, rng

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
            C = R @ np.diag([(0.003 * (1 + (r / 1.5) ** 2)) ** 2, (0.0015 * grow) ** 2]) @ R.T
            Q = np.zeros((3, 3))
            Q[:2, :2], Q[2, 2] = C, math.radians(0.3 * grow) ** 2
            out.append(
                LandmarkObservation(lm, np.eye(4), z + self.rng.multivariate_normal(np.zeros(3), Q), Q, 30)
            )
        return out


def _surveyed(rng):
    """The map a survey to 1.5 cm / 0.7 deg gives, and each poster's error ``[dx, dy, dyaw]`` by name."""
    errors, mapped = {}, []
    for lm in ROOM:
        e = rng.normal(0.0, [SURVEY_M, SURVEY_M, SURVEY_RAD])
        errors[lm.name] = e
        c = (lm.centre_W[0] + e[0], lm.centre_W[1] + e[1], lm.centre_W[2])
        mapped.append(replace(lm, centre_W=c, yaw=lm.yaw + e[2]))
    return errors, replace(ROOM, landmarks=tuple(mapped)).surveyed(SURVEY_M, SURVEY_RAD)


def _shape_error(errors: dict) -> float:
    """The RMS position error [m] of the posters ``errors`` (by name: ``[dx, dy, dyaw]``) left after the
    turn-and-shift that best explains them (:func:`survey_frame_error` about the room's centre): how far
    the constellation's shape is off, whatever its frame."""
    names = sorted(errors)
    xy = [ROOM.get(n).centre_W[:2] for n in names]
    E = np.array([errors[n] for n in names])
    t = survey_frame_error(xy, E, (0.0, 0.0), SURVEY_M, SURVEY_RAD)
    fitted = np.array([[t[0] - t[2] * y, t[1] + t[2] * x, t[2]] for x, y in xy])
    return float(np.sqrt(np.mean(np.sum((E - fitted)[:, :2] ** 2, axis=1))))


def test_the_tour_ties_every_poster_into_one_constellation():
    """Eight seeded surveys to 1.5 cm / 0.7 deg, a start known to 10 cm / 5 deg: the tour sights every
    poster, and the refined posters' shape (their errors after the best turn-and-shift of them all) is
    off by under 0.6 cm RMS, under a third of the survey's own. Sightings leave the frame of the
    constellation where the surveys put it together (the least squares floor,
    :mod:`lab.localization.survey_limit`): what the tour adds is that each poster is tied to all the
    others. Looking round the start alone leaves the shape about 1 cm off (the far posters are seen by
    their bearings only)."""
    cfg = LocalizerConfig(**NO_FLOOR)
    refined, surveyed = [], []
    for seed in range(8):
        rng = np.random.default_rng(6500 + seed)
        errors, mapped = _surveyed(rng)
        start = Pose2D(-1.5, -2.5, math.radians(30.0))
        base = _TourBase(start, rng)
        Sigma0 = np.diag([0.1**2, 0.1**2, math.radians(5.0) ** 2])
        robot = LocalizedRobot(base, "odometry", config=cfg, Sigma0=Sigma0, start_measured_by_hand=True)
        robot.mode, robot.observer = LocalizationMode.LANDMARKS, _Sightings(base, mapped, rng)
        robot.log = lambda m: None
        robot.relocalize()
        stands = survey_stands(mapped, _in_room, start_xy=robot.localizer.x[:2], config=cfg)
        tour = survey_tour(robot, base.navigate, stands)
        assert set().union(*tour.sightings) == {lm.name for lm in ROOM} and all(tour.arrived)
        est = robot.localizer.landmark_estimates()
        off = {}
        for name, (l, _) in est.items():
            d = l - ROOM.get(name).planar
            off[name] = (d[0], d[1], wrap_angle(d[2]))
        refined.append(_shape_error(off))
        surveyed.append(_shape_error(errors))
    refined, surveyed = 100 * np.array(refined), 100 * np.array(surveyed)
    print(
        f"the shape's RMS error: surveyed {np.round(surveyed, 2)} cm, "
        f"after the tour {np.round(refined, 2)} cm"
    )
    assert np.median(refined) < 0.6 and np.median(refined) < np.median(surveyed) / 3
