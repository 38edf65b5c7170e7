"""A search trial's result: the ``lab search`` JSON, the trace behind the figures, and the scoring.

:class:`SearchResult` is what :func:`lab.runs.search.run_search` returns and :meth:`SearchResult.to_json`
is exactly what ``lab search --json`` writes. :func:`scored` compares a run with its truth
(:class:`TrialTruth`, read after the run: the agent never sees it); :func:`outcome_in_words` says what a
result means in one line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from lab.geometry import R_to_euler_zyx, se3_inv
from lab.navigation.grid import GridSpec
from lab.runs.tracks import RobotTrack
from lab.scene import Scene
from lab.search.agent import INTERRUPTED, AgentResult, SearchEvent
from lab.vision.database import FeatureDatabase

__all__ = [
    "SUCCESS_ORIENTATION_DEG",
    "SUCCESS_POSITION_M",
    "SearchResult",
    "SearchTrace",
    "TrialTruth",
    "outcome_in_words",
    "pose_errors",
    "scored",
]

#: Success, as the acceptance counts it: found, within 5 cm and 10 degrees of the truth.
SUCCESS_POSITION_M = 0.05
SUCCESS_ORIENTATION_DEG = 10.0


def pose_errors(G_est: np.ndarray, G_true: np.ndarray) -> tuple[float, float]:
    """Position error [m] and orientation error [deg] (the angle of ``R_est^T R_true``)."""
    pe = float(np.linalg.norm(G_est[:3, 3] - G_true[:3, 3]))
    R = G_est[:3, :3].T @ G_true[:3, :3]
    oe = math.degrees(math.acos(float(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))))
    return pe, oe


def _pose_dict(G: np.ndarray) -> dict:
    return {
        "position_m": [round(float(v), 5) for v in G[:3, 3]],
        "euler_zyx_deg": [round(math.degrees(float(v)), 4) for v in R_to_euler_zyx(G[:3, :3])],
    }


@dataclass(frozen=True)
class SearchTrace:
    """Everything a trial recorded beyond the JSON (for the figures): the agent's record, the map's grid,
    the trajectory of the pose the agent used ``(t, x, y, theta)`` (the localized pose, or the odometry),
    the world's scene, the database the agent searched with, and the robot's path as the wheel odometry,
    the estimate and (where known) the truth saw it (``track``)."""

    agent: AgentResult = field(repr=False)
    spec: GridSpec = field(repr=False)
    trajectory: np.ndarray = field(repr=False)
    scene: Scene = field(repr=False)
    db: FeatureDatabase | None = field(default=None, repr=False)
    track: RobotTrack | None = field(default=None, repr=False)


@dataclass(frozen=True)
class SearchResult:
    """The outcome of one trial: the ``lab search`` JSON fields, and the trace for the figures.

    Attributes
    ----------
    object : str
    found : bool
        The agent's claim.
    true_pose, estimated_pose : dict or None
        ``{"position_m": [x, y, z], "euler_zyx_deg": [alpha, beta, gamma]}`` of the object frame O in
        the world (the estimate in the odometry frame, which the run started aligned with). No true pose
        on the real robot unless the operator measured it (``truth``).
    position_error_m, orientation_error_deg : float or None
        Against the truth (None when not found, or without a truth).
    path_length_m : float
        Distance driven, from odometry.
    global_searches, local_searches : int
    collisions : int
        Bumps: the simulator's contacts; on a robot the bumps its bumpers reported.
    sim_time_s, wall_time_s : float [s]
        The robot's time (the simulator's; on a robot, wall time from the start of the search).
    seed : int
    strategy : str
    success : bool or None
        Found within :data:`SUCCESS_POSITION_M` and :data:`SUCCESS_ORIENTATION_DEG` (None without a truth).
    reason : str
        Why the run ended (:data:`~lab.search.agent.INTERRUPTED` after Ctrl-C).
    place : tuple of 4 floats or None
        The object's placement ``(x, y, z_underside, yaw_deg)`` (on the real robot: the measured truth,
        or None).
    surface : str or None
        floor, table or shelf (None on the real robot).
    obstacles : tuple
        Placements of the extra obstacles (``--obstacles``).
    camera_frame_error : dict or None
        ``{"position_m", "orientation_deg"}``: the estimate's error in the camera frame at detection
        (the local search's own error; ``position_error_m`` adds the odometry's drift to it).
    pose_std : dict or None
        The found pose's stated standard deviations in W (what the robot says without a truth:
        :meth:`lab.search.world_pose.WorldPoseStd.as_dict`); None when not found.
    odometry_error_m : float or None
        Distance between the odometry's and the true robot position at the end of the run (None on the
        real robot).
    localization_error_m : float or None
        Distance between the robot's pose estimate (odometry alone, or localized against the room's
        landmarks) and the true robot position at the end of the run (None on the real robot).
    localization : str
        ``odometry`` or ``landmarks`` (:mod:`lab.localization`).
    landmark_updates : int
        Landmark observations the localizer used (0 with landmarks: it fell back to odometry alone,
        and ``localization_note`` says so).
    landmark_refinds : int
        Times the localizer was lost and re-found (:mod:`lab.localization.refind`): its estimate reset
        from two rejected sightings that agreed with each other.
    localization_note : str or None
    odometry_calibration : dict or None
        The odometry's turn scale and curvature bias the localizer learned
        (:meth:`~lab.localization.LocalizedRobot.odometry_calibration`).
    camera_estimate : dict or None
        The camera's yaw on the base and the stereo's range scale the localizer learned, when it
        estimates them (:meth:`~lab.localization.LocalizedRobot.camera_estimate`).
    camera_level : dict or None
        The camera levelled against the floor before the search (``lab.runs.search._levelled``,
        :mod:`lab.navigation.level`): the views, the floor's tilt before and after, the mounts' angles
        found and the time it took; ``levelled`` False with the reason when too few views showed the
        floor; None when not levelled (``level=False``, or a calibration file was used).
    survey_tour : dict or None
        The survey tour before the search (:func:`lab.runs.room.survey_the_room`: its stands, the
        sightings at each, its time); None without one.
    stored_survey : dict or None
        The room surveyed once that the run started from (``lab survey``'s file,
        :mod:`lab.localization.stored_survey`): the file, its posters, and the tour that made it; None
        without one.
    events : tuple of SearchEvent
    trace : SearchTrace
    recording : str or None
        The animation written (``record``): one frame per event.
    sensing : str
        The sensing profile the trial ran under (the simulator's, or a rehearsal's rendered camera's);
        ``hardware`` on the real robot.
    sensing_applies_to : tuple of str
        The profile's sections the sensors followed: camera, odometry and pan_tilt in the simulator,
        camera in a rehearsal (the emulators have their own odometry and head), none on the robot.
    robot : str
        ``sim``, or the robot config's path.
    watchdog_stops : int or None
        How often the robot's watchdog stopped the base (None in the simulator).
    moving : dict or None
        A moving object's trial (``lab search --moving``): its kind, speed, pause, whether the agent
        predicted it, and ``truth_time_s``, the robot time of the truth the find is scored against (the
        moment it was confirmed); None (and absent from the JSON) for a stationary object.
    t0 : float [s]
        The robot's time at the start of the search (after the camera's levelling; 0 in the simulator
        without it): the JSON's event and snapshot times, and ``sim_time_s``, are from it.
    """

    object: str
    found: bool
    true_pose: dict | None
    estimated_pose: dict | None
    position_error_m: float | None
    orientation_error_deg: float | None
    path_length_m: float
    global_searches: int
    local_searches: int
    collisions: int
    sim_time_s: float
    wall_time_s: float
    seed: int
    strategy: str
    success: bool | None
    reason: str
    place: tuple[float, float, float, float] | None
    surface: str | None
    obstacles: tuple = ()
    camera_frame_error: dict | None = None
    pose_std: dict | None = None
    odometry_error_m: float | None = 0.0
    localization_error_m: float | None = 0.0
    localization: str = "landmarks"
    landmark_updates: int = 0
    landmark_refinds: int = 0
    localization_note: str | None = None
    odometry_calibration: dict | None = None
    camera_estimate: dict | None = None
    report_relocalization: dict | None = None
    camera_level: dict | None = None
    survey_tour: dict | None = None
    stored_survey: dict | None = None
    events: tuple[SearchEvent, ...] = field(default=(), repr=False)
    trace: SearchTrace | None = field(default=None, repr=False, compare=False)
    recording: str | None = None
    sensing: str = "ideal"
    sensing_applies_to: tuple[str, ...] = ("camera", "odometry", "pan_tilt")
    robot: str = "sim"
    watchdog_stops: int | None = None
    t0: float = 0.0
    moving: dict | None = None

    @property
    def interrupted(self) -> bool:
        """Ended by Ctrl-C (the result is what was found so far)."""
        return self.reason == INTERRUPTED

    def to_json(self) -> dict:
        """The JSON ``lab search --json`` writes (plain types only)."""
        snaps = [] if self.trace is None else self.trace.agent.snapshots
        t0 = self.t0
        return {
            "object": self.object,
            "found": bool(self.found),
            "true_pose": self.true_pose,
            "estimated_pose": self.estimated_pose,
            "position_error_m": self.position_error_m,
            "orientation_error_deg": self.orientation_error_deg,
            "path_length_m": round(float(self.path_length_m), 4),
            "global_searches": int(self.global_searches),
            "local_searches": int(self.local_searches),
            "collisions": int(self.collisions),
            "sim_time_s": round(float(self.sim_time_s), 3),
            "wall_time_s": round(float(self.wall_time_s), 3),
            "seed": int(self.seed),
            "strategy": self.strategy,
            "success": None if self.success is None else bool(self.success),
            "reason": self.reason,
            "place": None if self.place is None else [round(float(v), 4) for v in self.place],
            "surface": self.surface,
            "obstacles": [[round(float(v), 4) for v in o] for o in self.obstacles],
            "camera_frame_error": self.camera_frame_error,
            "pose_std": self.pose_std,
            "odometry_error_m": _round(self.odometry_error_m, 4),
            "localization_error_m": _round(self.localization_error_m, 4),
            "localization": self.localization,
            "landmark_updates": int(self.landmark_updates),
            "landmark_refinds": int(self.landmark_refinds),
            "localization_note": self.localization_note,
            "odometry_calibration": self.odometry_calibration,
            "camera_estimate": self.camera_estimate,
            "report_relocalization": self.report_relocalization,
            "camera_level": self.camera_level,
            "survey_tour": self.survey_tour,
            "stored_survey": self.stored_survey,
            "events": [{**e.as_dict(), "t": round(e.t - t0, 3)} for e in self.events],
            "recording": self.recording,
            "sensing": self.sensing,
            "sensing_applies_to": list(self.sensing_applies_to),
            "robot": self.robot,
            "watchdog_stops": self.watchdog_stops,
            "map_snapshots": [
                {
                    "t": round(s.t - t0, 3),
                    "label": s.label,
                    "cell": None if s.cell is None else list(s.cell),
                    "max_p": float(s.P.max()),
                }
                for s in snaps
            ],
        } | ({} if self.moving is None else {"moving": self.moving})


def _round(v: float | None, digits: int) -> float | None:
    return None if v is None else round(float(v), digits)


def scored(object: str, out: AgentResult, truth: TrialTruth, odom) -> dict:
    """The result's fields that compare the run with the truth: pose errors in W and in the camera
    frame C (the perception error alone, without the odometry's drift), success, odometry error; None
    where there is no truth. Also what the robot says without a truth: the found pose's stated
    deviation in W (``pose_std``, :class:`lab.search.world_pose.WorldPoseStd`)."""
    pe = oe = cam = None
    if out.found and truth.G_WO is not None:
        pe, oe = pose_errors(out.G_WO, truth.G_WO)
        if truth.G_WC is not None:
            cpe, coe = pose_errors(out.local.estimate.G_CO, se3_inv(truth.G_WC) @ truth.G_WO)
            cam = {"position_m": round(cpe, 5), "orientation_deg": round(coe, 3)}
    rp = truth.robot_pose
    return {
        "object": object,
        "found": out.found,
        "true_pose": None if truth.G_WO is None else _pose_dict(truth.G_WO),
        "estimated_pose": None if out.G_WO is None else _pose_dict(out.G_WO),
        "position_error_m": None if pe is None else round(pe, 5),
        "orientation_error_deg": None if oe is None else round(oe, 3),
        "collisions": truth.collisions,
        "success": None
        if truth.G_WO is None
        else bool(out.found and pe <= SUCCESS_POSITION_M and oe <= SUCCESS_ORIENTATION_DEG),
        "reason": out.reason,
        "camera_frame_error": cam,
        "pose_std": None if out.pose_std is None else out.pose_std.as_dict(),
        "odometry_error_m": None if rp is None else math.hypot(odom.x - rp.x, odom.y - rp.y),
    }


def outcome_in_words(data: dict) -> str:
    """What a ``lab search`` result (its JSON fields) means, in one line for the console: found or
    not, and whether it counts as a success against the truth, with the limit that it missed.

    >>> outcome_in_words({"found": True, "success": False, "position_error_m": 0.083,
    ...                   "orientation_error_deg": 2.0, "reason": "found"})
    'found, but 8.3 cm from the true position: the limit is 5 cm'
    """
    if not data.get("found"):
        return f"not found: {data.get('reason') or 'no reason recorded'}"
    pe, oe = data.get("position_error_m"), data.get("orientation_error_deg")
    if pe is None or oe is None:
        return "found (no true pose to score it against)"
    misses = []
    if pe > SUCCESS_POSITION_M:
        misses.append(
            f"{100 * pe:.1f} cm from the true position: the limit is {100 * SUCCESS_POSITION_M:.0f} cm"
        )
    if oe > SUCCESS_ORIENTATION_DEG:
        misses.append(
            f"{oe:.1f} deg off the true orientation: the limit is {SUCCESS_ORIENTATION_DEG:.0f} deg"
        )
    if misses:
        return "found, but " + "; and ".join(misses)
    return (
        f"found and a success: {100 * pe:.1f} cm and {oe:.1f} deg from the true pose "
        f"(limits {100 * SUCCESS_POSITION_M:.0f} cm, {SUCCESS_ORIENTATION_DEG:.0f} deg)"
    )


@dataclass(frozen=True)
class TrialTruth:
    """The truth at the end of a trial, for scoring only (None where there is none)."""

    G_WO: np.ndarray | None  # the object in W
    G_WC: np.ndarray | None  # the camera in W at the last frame
    robot_pose: object  # Pose2D of the base, or None
    collisions: int
    robot_time_s: float  # the robot's clock at the end
    time_s: float | None = None  # the robot's clock when G_WO was read (a moving object: at the find)
