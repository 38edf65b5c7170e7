r"""A survey tour: the robot ties the room's posters into one constellation before it works.

A map measured with a tape is off by its survey's error, poster by poster
(:attr:`~lab.localization.Landmark.survey_sigma_m`). A pose tied to the one or two posters near it
inherits their errors, however well it sees them: its floor is the turn-and-shift that those posters'
surveys leave (:mod:`lab.localization.survey_limit`; for the lab room under a 1.5 cm / 0.7 deg survey,
1.44 cm median with the best two posters, 0.62 cm with all in view). The posters are in the localizer's
state (:mod:`lab.localization.posters`), so every sighting from one place ties the posters seen there
to each other through the robot's pose; what is missing is places from which many posters are seen
well, and a robot that looks at all of them there. The tour gives both:

* **stands** (:func:`survey_stands`): points on the free floor, chosen greedily so that every poster is
  seen *well* (near and head-on: a precise fit) from one of them, each next stand the one that sees the
  most posters not yet seen well, ties broken by how many it sees at all (by the localizer's rules,
  :func:`~lab.localization.survey_limit.posters_in_view`);
* **the tour** (:func:`survey_tour`): the robot drives to each stand, nearest first, and there looks at
  every poster in view, ``passes`` times round (:meth:`~lab.localization.LocalizedRobot.relocalize`
  with thresholds it cannot meet, so it does not stop early).

After it the posters' estimates are correlated through the robot's poses, and what the robot's pose
inherits from the survey is close to what all the posters' surveys leave together. Odometry carries
the pose between stands, so the stands see overlapping sets of posters.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from lab.localization.filter import LocalizerConfig
from lab.localization.landmarks import LandmarkMap
from lab.localization.survey_limit import posters_in_view

__all__ = ["SurveyTour", "posters_seen_well", "survey_stands", "survey_tour"]


def posters_seen_well(
    landmarks: LandmarkMap, xy, range_m: tuple[float, float] = (1.0, 3.0), min_facing: float = 0.7
) -> set[str]:
    """The names of the posters seen well from ``xy``: ``range_m`` [m] away and at most
    ``acos(min_facing)`` off their face's normal."""
    out = set()
    for lm in landmarks:
        d = math.hypot(lm.centre_W[0] - xy[0], lm.centre_W[1] - xy[1])
        if range_m[0] <= d <= range_m[1] and lm.facing(xy) >= min_facing:
            out.add(lm.name)
    return out


def survey_stands(
    landmarks: LandmarkMap,
    free: Callable[[float, float], bool],
    start_xy=(0.0, 0.0),
    spacing_m: float = 0.5,
    range_m: tuple[float, float] = (1.0, 3.0),
    min_facing: float = 0.7,
    config: LocalizerConfig | None = None,
    cover: int = 1,
) -> list[tuple[float, float]]:
    """The tour's stands: points on a ``spacing_m`` grid over the room where ``free(x, y)``, chosen
    greedily until every poster that any of them sees well is seen well from one, in the order a robot
    at ``start_xy`` visits them (nearest next).

    A poster is seen well from a point ``range_m`` [m] away and at most ``acos(min_facing)`` off its face:
    the fit's range error grows as the square of the distance. The next stand is the one that sees the
    most posters not yet seen well often enough, then the most in view (:func:`posters_in_view` with
    ``config``, the localizer's range and facing), then the nearest the last. With ``cover`` above 1 every
    poster is seen well from that many stands (or from every point that sees it well, when fewer do): a
    poster sighted from two places is placed by two bearings, not by one bearing and a stereo range.
    """
    if isinstance(cover, bool) or not (isinstance(cover, int) and cover >= 1):
        raise ValueError(
            f"cover must be a whole number >= 1 (stands that see each poster well), got {cover!r}"
        )
    if not (math.isfinite(spacing_m) and spacing_m > 0):
        raise ValueError(f"spacing_m must be a finite number of metres > 0, got {spacing_m!r}")
    if not 0 <= range_m[0] < range_m[1]:
        raise ValueError(f"range_m must be (near, far) with 0 <= near < far [m], got {range_m!r}")
    sx, sy = (float(v) / 2.0 for v in landmarks.room_size)
    xs = np.arange(-sx + spacing_m, sx - spacing_m / 2, spacing_m)
    ys = np.arange(-sy + spacing_m, sy - spacing_m / 2, spacing_m)
    cands = []
    for x in xs:
        for y in ys:
            if free(float(x), float(y)):
                xy = (float(x), float(y))
                well = posters_seen_well(landmarks, xy, range_m, min_facing)
                cands.append((xy, well, len(posters_in_view(landmarks, xy, config))))
    wanted = {n: cover for c in cands for n in c[1]}  # poster -> stands still to see it well
    chosen, at = [], tuple(float(v) for v in start_xy)
    while cands and any(wanted.values()):
        best = max(cands, key=lambda c: (sum(wanted[n] > 0 for n in c[1]), c[2], -math.dist(c[0], at)))
        if not any(wanted[n] > 0 for n in best[1]):
            break  # the posters left are seen well from fewer points than ``cover``
        cands.remove(best)
        chosen.append(best[0])
        for n in best[1]:
            wanted[n] = max(wanted[n] - 1, 0)
        at = best[0]
    tour, at = [], tuple(float(v) for v in start_xy)
    while chosen:
        nxt = min(chosen, key=lambda p: math.dist(p, at))
        chosen.remove(nxt)
        tour.append(nxt)
        at = nxt
    return tour


@dataclass(frozen=True)
class SurveyTour:
    """What a tour did: the stands it reached and each stand's accepted sightings by poster.

    Attributes
    ----------
    stands : list of (x, y) [m]
        The stands, in the order driven to.
    arrived : list of bool
        Whether the robot got to each.
    sightings : list of dict
        Accepted sightings at each stand, by poster name.
    """

    stands: list
    arrived: list
    sightings: list

    @property
    def n_sightings(self) -> int:
        """All the tour's accepted sightings."""
        return sum(sum(s.values()) for s in self.sightings)


def survey_tour(robot, navigate, stands, passes: int = 2, tolerance_m: float = 0.25) -> SurveyTour:
    """Drive ``robot`` (a :class:`~lab.localization.LocalizedRobot`, or a wrapper of one that passes
    ``relocalize`` and ``localizer`` through) to each of ``stands`` with ``navigate(target_xy,
    min_distance, max_distance)`` (the search's), and at each look at every poster in view ``passes``
    times round. A stand the robot cannot reach is skipped."""
    if not (isinstance(passes, int) and passes >= 1):
        raise ValueError(
            f"passes must be a whole number >= 1 (times round the posters in view), got {passes!r}"
        )
    arrived, sightings = [], []
    loc = robot.localizer
    for xy in stands:
        ok = bool(navigate(tuple(xy), 0.0, tolerance_m).arrived)
        arrived.append(ok)
        n0 = len(loc.history)
        if ok:
            n_views = len(robot.landmark_views())
            robot.relocalize(max(n_views, 1) * passes, sigma_m=0.0, sigma_rad=0.0, passes=passes)
        seen: dict[str, int] = {}
        for rec in loc.history[n0:]:
            if rec.accepted:
                seen[rec.landmark] = seen.get(rec.landmark, 0) + 1
        sightings.append(seen)
    return SurveyTour(list(stands), arrived, sightings)
