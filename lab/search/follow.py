"""Following a colour track while the robot approaches it (the predicting search, issue 50).

:func:`start_tracks` turns the used colour peaks of a global search into
:class:`~lab.search.colour_track.ColourTrack` s. When the map's next cell is where one of them started
(within ``match_m``), the agent approaches the *track* instead of the cell (:func:`approach_track`), in
legs of ``leg_m``:

    loop (at most max_legs):
        aim the head at the track's predicted point, take one frame, find the colour blob near the
        predicted pixel (within the track's deviation as seen), update the track      (reobserve)
        the track lost (no re-detection for lost_after_s since the approach began or it was last
        seen): give up -> the agent approaches the cell
        the robot stands within the local-search band of the predicted position: arrived
        goal = the track's predicted position when the robot will get there (distance / travel speed)
        drive leg_m towards the goal, or (the last leg) into the goal's local-search band

Aiming at the predicted point is the identification paper's tracking (Sec. IV, Eqs. (16)-(17),
:mod:`lab.identification.head`: keep the object's image position at the image centre) in position
mode: its proportional law run to convergence in one command, on the filter's prediction rather than
the last image. The navigator owns the head while it drives (it watches the floor ahead), so the head
follows the object between legs: one rendered frame per leg keeps the frame budget small. The local
search then looks at the track's predicted position, not at the cell where the object was seen.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from lab.geometry import se3_inv, transform_points
from lab.search.colour_track import (
    ColourTrack,
    ColourTrackConfig,
    find_blob,
    measurement_xy,
    predicted_pixel,
)
from lab.search.global_search import GlobalSearchResult
from lab.search.tracking import aim_at

__all__ = ["FollowResult", "approach_track", "reobserve", "start_tracks", "track_for"]

#: How far [m] either side of a leg's end the navigator may stop (the ring it drives into).
LEG_SLACK_M = 0.15


@dataclass(frozen=True)
class FollowResult:
    """How an approach of a track ended.

    Attributes
    ----------
    arrived : bool
        The robot stands within the local-search band of the track's predicted position.
    nav : object
        The last navigation result (None when no leg was driven).
    xy : tuple of 2 floats [m]
        The track's predicted position now (where to look).
    detail : str
        For the event log.
    """

    arrived: bool
    nav: object
    xy: tuple[float, float]
    detail: str


def start_tracks(
    result: GlobalSearchResult, speed_mps: float, config: ColourTrackConfig
) -> list[ColourTrack]:
    """A track for each used colour peak of a global search, at the peak's stereo point and the time
    its view was captured."""
    tracks = []
    for view in result.views:
        for p in view.peaks:
            if p.used and p.p_W is not None and p.disparity is not None:
                p_W, R = measurement_xy(view.frame, p.uv, p.disparity, config)
                tracks.append(ColourTrack(p_W, R, view.frame.t, speed_mps, config))
    return tracks


def track_for(tracks: list[ColourTrack], xy, t: float) -> ColourTrack | None:
    """The live track that started nearest the point ``xy`` [m], within its ``match_m``; or None."""
    best, best_d = None, math.inf
    for tr in tracks:
        d = math.dist(tr.start_xy, (float(xy[0]), float(xy[1])))
        if d <= tr.config.match_m and d < best_d and not tr.lost(t):
            best, best_d = tr, d
    return best


def reobserve(robot, track: ColourTrack, colour_model: np.ndarray, db) -> bool:
    """Aim the head at the track's predicted point (:func:`~lab.search.tracking.aim_at`), take one frame,
    and update the track with the colour blob nearest the predicted pixel; True when it was
    re-detected (the gate let the blob through). ``colour_model``: the global search's ratio histogram
    of the object's database ``db`` (whose colour space it is in)."""
    t = robot.now()
    track.predict(t)
    p_R = transform_points(se3_inv(robot.odometry().G()), track.point_at(t))
    pan, tilt = aim_at(p_R, robot.camera, robot.pan_tilt_limits)
    robot.command_pan_tilt(pan, tilt)
    robot.wait_pan_tilt()
    frame = robot.capture_stereo()
    track.frames += 1
    track.predict(max(frame.t, track.t))
    pix = predicted_pixel(frame, track.point_at(track.t))
    if pix is None:
        return False
    space = db.meta.get("colour_space", "rg")
    gate = track.gate_px(pix[2], frame.camera.fx)
    blob = find_blob(frame, colour_model, space, pix[:2], track.config, gate)
    return blob is not None and track.update(blob.p_W[:2], blob.R_xy, track.t)


def approach_track(
    robot,
    navigate: Callable,
    track: ColourTrack,
    colour_model: np.ndarray,
    db,
    band: tuple[float, float],
    travel_speed_m_s: float,
) -> FollowResult:
    """The loop of the module docstring. ``navigate(xy, min_distance, max_distance)`` drives (the
    agent's); ``band`` the local search's ``(min_distance_m, max_distance_m)`` [m]."""
    cfg = track.config
    lo, hi = band
    nav, seen, t0 = None, 0, robot.now()
    for leg in range(cfg.max_legs + 1):
        seen += reobserve(robot, track, colour_model, db)
        now = robot.now()
        here = track.position_at(now)
        xy = (float(here[0]), float(here[1]))
        if track.lost(now, since=t0):
            return FollowResult(False, nav, xy, f"colour track lost after {leg} legs ({seen} re-detections)")
        pose = robot.odometry()
        d = math.hypot(here[0] - pose.x, here[1] - pose.y)
        if lo - 0.05 <= d <= hi + 0.05 and leg > 0:
            moved = math.dist(track.start_xy, xy)
            detail = (
                f"followed a colour track: {leg} legs, {seen} re-detections, {moved:.2f} m from where seen"
            )
            return FollowResult(True, nav, xy, detail)
        if leg == cfg.max_legs:
            break
        eta = max(0.0, d - 0.5 * (lo + hi)) / travel_speed_m_s
        goal = track.position_at(now + eta)
        g = (float(goal[0]), float(goal[1]))
        dg = math.hypot(goal[0] - pose.x, goal[1] - pose.y)
        if dg - cfg.leg_m <= hi:
            nav = navigate(g, lo, hi)
        else:
            r = dg - cfg.leg_m
            nav = navigate(g, r - LEG_SLACK_M, r + LEG_SLACK_M)
        if not nav.arrived:
            return FollowResult(False, nav, xy, f"colour track: leg {leg + 1} not driven ({nav.reason})")
    return FollowResult(False, nav, xy, f"colour track not reached in {cfg.max_legs} legs")
