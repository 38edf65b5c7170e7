"""The survey tour (lab.localization.survey_tour): its stands, and what driving it does to a surveyed map.

Peers: the lab room's own geometry (every poster seen well from a stand; the stands on the free floor),
and the least squares floor of :mod:`lab.localization.survey_limit` (itself checked against SciPy): after
the tour a robot's error is what all the posters' surveys leave together, not what its nearest posters'
do.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from localization_helpers import NO_FLOOR
from tour_fakes import ROOM, Sightings, TourBase, in_room, shape_error, survey_of

from lab.geometry import Pose2D, wrap_angle
from lab.localization import LocalizationMode, LocalizedRobot, LocalizerConfig
from lab.localization.survey_tour import posters_seen_well, survey_stands, survey_tour

SURVEY_M, SURVEY_RAD = 0.015, math.radians(0.7)


def test_the_stands_see_every_poster_well_from_the_free_floor_in_the_order_driven():
    """With a table's worth of floor blocked: every stand is free, every poster that some free point sees
    well is seen well from a stand, each stand adds one the stands before it did not see well, and
    each next stand is the nearest of those left. Asked to, the stands see each poster well twice."""

    def free(x, y):
        return in_room(x, y) and not (-1.0 <= x <= 1.0 and -0.5 <= y <= 0.5)

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
    for bad in (0, 1.5, True):
        with pytest.raises(ValueError, match="cover must be a whole number"):
            survey_stands(ROOM, free, cover=bad)
    with pytest.raises(ValueError, match="spacing_m"):
        survey_stands(ROOM, free, spacing_m=0.0)
    with pytest.raises(ValueError, match="range_m"):
        survey_stands(ROOM, free, range_m=(3.0, 1.0))
    with pytest.raises(ValueError, match="passes"):
        survey_tour(None, None, [], passes=0)


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
        errors, mapped = survey_of(rng, SURVEY_M, SURVEY_RAD)
        start = Pose2D(-1.5, -2.5, math.radians(30.0))
        base = TourBase(start, rng)
        Sigma0 = np.diag([0.1**2, 0.1**2, math.radians(5.0) ** 2])
        robot = LocalizedRobot(base, "odometry", config=cfg, Sigma0=Sigma0, start_measured_by_hand=True)
        robot.mode, robot.observer = LocalizationMode.LANDMARKS, Sightings(base, mapped, rng)
        robot.log = lambda m: None
        robot.relocalize()
        stands = survey_stands(mapped, in_room, start_xy=robot.localizer.x[:2], config=cfg)
        tour = survey_tour(robot, base.navigate, stands)
        assert set().union(*tour.sightings) == {lm.name for lm in ROOM} and all(tour.arrived)
        est = robot.localizer.landmark_estimates()
        off = {}
        for name, (l, _) in est.items():
            d = l - ROOM.get(name).planar
            off[name] = (d[0], d[1], wrap_angle(d[2]))
        refined.append(shape_error(off))
        surveyed.append(shape_error(errors))
    refined, surveyed = 100 * np.array(refined), 100 * np.array(surveyed)
    print(
        f"the shape's RMS error: surveyed {np.round(surveyed, 2)} cm, "
        f"after the tour {np.round(refined, 2)} cm"
    )
    assert np.median(refined) < 0.6 and np.median(refined) < np.median(surveyed) / 3
