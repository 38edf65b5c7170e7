"""One search trial, end to end: build the world, place the object, search, and score against truth.

:func:`run_search` is what ``lab search`` runs; :meth:`SearchResult.to_json` is exactly what it writes
(the fields of the ``lab search`` contract in ``design.md``, and more). The agent never sees the truth:
the object's true pose, the collision count and the errors are filled in here, after the run.

The same agent runs on three robots (:func:`lab.runs.robots.make_robot`, ``robot_config``):

============================  ==========================================  =================================
robot                         the room and the object                     truth (scoring only)
============================  ==========================================  =================================
the simulator (no config)     the scene, the object placed by ``place``   the simulator's
                              or the seed
a rehearsal                   the same scene and placement, rendered      the rendered world (the object),
(``hardware/rehearsal.toml``) from the device emulators' true state       the emulators (the base, head)
the real robot                the real room; the map is the scene's       none, or the object's pose the
(``hardware/robot.toml``)     floor, the robot stood at its start         operator measured (``truth``)
============================  ==========================================  =================================

On a robot the wheel odometry starts at (0, 0, 0); the robot stands at the scene's ``[robot] start``
and :class:`~lab.runs.robots.PlacedRobot` puts its odometry in the room's frame. Its clock is the wall
clock: the time budget (``max_time``) is wall time there, ``sim_time_s`` the robot's time from the start
of the search, and the events' times are from that start too. Where there is no truth the scoring fields
(``true_pose``, the errors, ``success``) are null, and ``collisions`` counts the bumps the robot's bumpers
reported (:attr:`lab.robot.Robot.bumps`; in the simulator its contacts). Ctrl-C ends the search with the
reason ``"interrupted"``, the motors stopped, and the result so far.
"""

from __future__ import annotations

import contextlib
import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from lab.errors import ConfigError, SafetyStop
from lab.geometry import Pose2D, R_to_euler_zyx, Rz, se3, se3_inv
from lab.navigation.astar import astar_to_region
from lab.navigation.drive_loop import NavOutcome
from lab.navigation.grid import GridSpec
from lab.navigation.localization import LocalizationMode, LocalizedRobot, PoseEstimate
from lab.navigation.navigator import Navigator
from lab.robot import Robot
from lab.runs.placement import (
    check_placement,
    circle_polygon,
    footprint,
    polygon_inside,
    polygons_overlap,
    random_placement,
    searchable_objects,
    supports,
)
from lab.runs.robots import RobotKind, load_robot_config, make_robot, robot_kind
from lab.runs.room import localize, robot_start, room_landmarks
from lab.runs.tracks import RobotTrack, TrackedRobot
from lab.scene import BodySpec, Scene, load_scene
from lab.search.agent import (
    INTERRUPTED,
    AgentConfig,
    AgentResult,
    NavigationResult,
    SearchAgent,
    SearchEvent,
    Strategy,
)
from lab.search.budget import BudgetedRobot, SearchBudgetExceeded
from lab.search.probability_map import ProbabilityMap
from lab.training.search import search_database
from lab.vision.database import FeatureDatabase

__all__ = [
    "SearchResult",
    "SearchTrace",
    "map_spec",
    "navigator_factory",
    "outcome_in_words",
    "path_obstacles",
    "pose_errors",
    "run_search",
]

#: Success, as the acceptance counts it: found, within 5 cm and 10 degrees of the truth.
SUCCESS_POSITION_M = 0.05
SUCCESS_ORIENTATION_DEG = 10.0

NavigatorFactory = Callable[[Robot, GridSpec], Callable]


def map_spec(scene: Scene, resolution: float = 0.2) -> GridSpec:
    """The probability map's grid: the room's floor in ``resolution`` cells (the paper's 20 cm)."""
    if scene.room is None:
        raise ConfigError(f"scene {scene.name!r} has no room to search")
    sx, sy = scene.room.size
    return GridSpec.from_bounds(-sx / 2, -sy / 2, sx / 2, sy / 2, resolution)


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


def path_obstacles(
    scene: Scene, name: str, place, rng: np.random.Generator, n: int = 2, size=(0.3, 0.3, 0.5)
) -> tuple[Scene, list[tuple[float, float, float, float]]]:
    """Put ``n`` boxes on the straight line from the robot's start to the object (the "obstacles placed
    in the planned path" of the paper's second set of trials).

    Each box goes at a random point along the middle of the line (jittered sideways by up to 15 cm),
    clear of other bodies by 0.35 m, at least 0.8 m from the start and 1.0 m from the object, so the
    robot can still get past and stand near the object. Boxes that find no such spot are left out.
    """
    rx, ry, _ = scene.robot_start
    ox, oy = float(place[0]), float(place[1])
    length = math.hypot(ox - rx, oy - ry)
    room = supports(scene)[0].polygon
    out_bodies, poses = list(scene.bodies), []
    ux, uy = ((ox - rx) / length, (oy - ry) / length) if length > 1e-9 else (1.0, 0.0)
    for k in range(n):
        for _ in range(200):
            s = rng.uniform(0.8, max(0.8, length - 1.0))
            lat = rng.uniform(-0.15, 0.15)
            x, y = rx + s * ux - lat * uy, ry + s * uy + lat * ux
            yaw = float(rng.uniform(0, 90))
            body = BodySpec(
                f"obstacle_{k + 1}", "box", tuple(size), (x, y, 0.0, yaw), "obstacle", (0.45, 0.4, 0.35)
            )
            fp = footprint(body)
            if not polygon_inside(footprint(body, 0.35), room):
                continue
            if any(polygons_overlap(fp, footprint(b, 0.35)) for b in out_bodies if b.role != "decor"):
                continue
            near_start = polygons_overlap(fp, circle_polygon(rx, ry, 0.6))
            if near_start or polygons_overlap(fp, circle_polygon(ox, oy, 1.0)):
                continue
            out_bodies.append(body)
            poses.append((x, y, 0.0, yaw))
            break
    return replace(scene, bodies=tuple(out_bodies)), poses


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
    odometry_error_m : float or None
        Distance between the odometry's and the true robot position at the end of the run (None on the
        real robot).
    localization_error_m : float or None
        Distance between the robot's pose estimate (odometry alone, or localized against the room's
        landmarks) and the true robot position at the end of the run (None on the real robot).
    localization : str
        ``odometry`` or ``landmarks`` (:mod:`lab.navigation.localization`).
    landmark_updates : int
        Landmark observations the localizer used (0 with landmarks: it fell back to odometry alone,
        and ``localization_note`` says so).
    localization_note : str or None
    odometry_calibration : dict or None
        The odometry's turn scale and curvature bias the localizer learned
        (:meth:`~lab.navigation.localization.LocalizedRobot.odometry_calibration`).
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
    t0 : float [s]
        The robot's time at the start of the search (0 in the simulator): the JSON's event and snapshot
        times are from it.
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
    odometry_error_m: float | None = 0.0
    localization_error_m: float | None = 0.0
    localization: str = "landmarks"
    landmark_updates: int = 0
    localization_note: str | None = None
    odometry_calibration: dict | None = None
    report_relocalization: dict | None = None
    events: tuple[SearchEvent, ...] = field(default=(), repr=False)
    trace: SearchTrace | None = field(default=None, repr=False, compare=False)
    recording: str | None = None
    sensing: str = "ideal"
    sensing_applies_to: tuple[str, ...] = ("camera", "odometry", "pan_tilt")
    robot: str = "sim"
    watchdog_stops: int | None = None
    t0: float = 0.0

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
            "odometry_error_m": _round(self.odometry_error_m, 4),
            "localization_error_m": _round(self.localization_error_m, 4),
            "localization": self.localization,
            "landmark_updates": int(self.landmark_updates),
            "localization_note": self.localization_note,
            "odometry_calibration": self.odometry_calibration,
            "report_relocalization": self.report_relocalization,
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
        }


def _round(v: float | None, digits: int) -> float | None:
    return None if v is None else round(float(v), digits)


def run_search(
    object: str,
    seed: int,
    place=None,
    strategy: str | Strategy = "paper",
    max_time: float = 600.0,
    navigate: NavigatorFactory | None = None,
    *,
    obstacles: bool = False,
    world: str | Scene = "lab_room",
    config: AgentConfig | None = None,
    supersample: int = 2,
    max_wall_time: float | None = None,
    progress: bool = False,
    record=None,
    attach: Callable | None = None,
    sensing="realistic",
    localization="landmarks",
    robot_config=None,
    truth=None,
    emulator_setup: Callable | None = None,
    start=None,
    view3d=None,
) -> SearchResult:
    """Run one search trial (in the simulator, a rehearsal or on the robot) and score it.

    Parameters
    ----------
    object : str
        A searchable object (:func:`lab.runs.placement.searchable_objects`).
    seed : int
        Seeds the placement (when ``place`` is None), the obstacles, the sensor errors and RANSAC.
    place : (x, y, z_underside, yaw_deg), optional
        Where to put the object (checked: in the room, on a surface, clear of the other bodies and the
        robot). Default: a seeded random valid placement. Not on the real robot (the object is where
        the operator put it).
    strategy : {"paper", "rate", "lawnmower", "frontier"}; max_time, max_wall_time : float [s]
        Time budget of the robot's clock (simulated time; on a robot, wall time): the run ends "not
        found" when it is used up; and, optionally, a wall-clock budget.
    navigate : callable ``(robot, spec) -> navigate``
        Required: the navigation callable (:mod:`lab.search.agent`) for the budgeted robot and the
        map's grid (:func:`navigator_factory`).
    obstacles : bool
        Add boxes on the straight line from the start to the object (:func:`path_obstacles`); the
        simulator and a rehearsal only.
    world, config, supersample :
        The scene; the agent's config (its ``strategy`` replaced); render supersampling (2: twice the
        SIFT matches on the small objects as 1; a rehearsal renders with its config's ``[sim]
        supersample``).
    progress, record, attach :
        Say when a database is built; write an animation of the live view (one frame per event);
        ``attach(agent)`` before the run (a notebook's ``LiveView.for_search(agent).widget``).
    sensing : str or mapping
        The simulator's sensing profile (:func:`lab.sim.sensing.sensing_profile`; default realistic).
    localization : {"landmarks", "odometry"}
        Where the robot's pose comes from (:class:`lab.navigation.localization.LocalizedRobot`): the
        odometry corrected by the room's posters (default), or wheel odometry alone, as in the papers.
        The map: the scene's posters; on a robot its config's ``[room] landmarks`` (a rehearsal without
        one: the rendered scene's posters; the real robot without one falls back to odometry and says
        so: :mod:`lab.runs.room`).
    start : (x_m, y_m, heading_deg), optional
        A robot only: where it stands in the room when it starts (default: its config's ``[room] start``,
        else the scene's ``[robot] start``); the localizer starts there with the covariance of ``[room]
        start_sigma``, and its first landmark sighting may correct it.
    robot_config : path or HardwareConfig, optional
        Run on this robot (:func:`lab.runs.robots.make_robot`): a rehearsal (``hardware/rehearsal.toml``)
        or the real robot (``hardware/robot.toml``); None: the simulator.
    truth : (x, y, z_underside, yaw_deg), optional
        The real robot only: the object's pose as the operator measured it, in the room's frame (as
        ``place``); the run is then scored against it.
    emulator_setup : callable, optional
        A rehearsal's fault injection (:func:`lab.runs.rehearsal.rehearsal`).
    view3d : path, optional
        Write the recorded 3D view there (:mod:`lab.viz.view3d`: one HTML page, one step per event).
    """
    wall0 = time.perf_counter()
    strategy = Strategy.parse(strategy)
    scene = world if isinstance(world, Scene) else load_scene(world)
    recorder = _check_trial(scene, object, navigate, max_time, record)
    viewer = None
    if view3d is not None:  # a missing viewer library: one line before anything starts
        from lab.viz.view3d import View3D

        viewer = View3D(view3d)
    hw = load_robot_config(robot_config)  # a bad robot config is one clear line before anything starts
    kind = robot_kind(hw)
    # the landmark map (a bad landmark file is one line too) and where the robot's odometry starts
    room = room_landmarks(kind, hw, scene, localization, progress=progress)
    mode, note = room.mode, room.note
    start_pose = _start_of(kind, hw, scene, room, start)
    rng = np.random.default_rng(seed)
    if kind is RobotKind.HARDWARE:
        G_WO_measured = _check_real_robot_trial(scene, object, place, obstacles, truth)
        place, surface, obstacle_poses = (None if truth is None else tuple(float(v) for v in truth)), None, []
    else:
        if truth is not None:
            raise ConfigError(
                "--truth is the object's measured pose on the real robot; in the simulator and a rehearsal "
                "the truth is known (put the object with --place)"
            )
        scene, place, surface, obstacle_poses = _place_object(scene, object, place, obstacles, rng)
        G_WO_measured = None
    db = search_database(object, progress=progress)
    cfg = replace(config or AgentConfig(), strategy=strategy)
    spec = map_spec(scene)
    with contextlib.ExitStack() as stack:
        run, truth_of = _session(
            stack,
            kind,
            hw,
            scene,
            object,
            seed,
            sensing,
            supersample,
            emulator_setup,
            G_WO_measured,
        )
        # on a robot its odometry starts at (0, 0, 0): placed at the start in the room (lab/runs/room.py)
        robot = localize(run.robot, kind, room, start_pose, seed)
        t0 = 0.0 if kind is RobotKind.SIM else robot.now()
        hook = _with_progress(attach, t0) if progress else attach
        if viewer is not None:  # the world's bodies for the 3D view: display only
            viewer.world, hook = run.world, viewer.attach_search(hook)
        parts = (db, navigate, spec, cfg, seed, recorder, hook, (max_time, max_wall_time))
        out, truth_end, budget, odom, track, report_reloc = _search(robot, truth_of, *parts)
        profile, applies = run.sensing, tuple(run.sensing_applies_to)
        estimate = robot.pose_estimate()
        watchdog = None if kind is RobotKind.SIM else int(run.robot.watchdog_stops)
    if viewer is not None:
        viewer.save()
    if note is None and mode is LocalizationMode.LANDMARKS and estimate.n_updates == 0:
        note = "no landmark was seen: the pose is odometry alone"
    if note is not None:
        print(f"lab: localization: {note}", file=sys.stderr)
    rp = truth_end.robot_pose
    return SearchResult(
        **_scored(object, out, truth_end, odom),
        localization_error_m=None
        if rp is None
        else math.hypot(estimate.pose.x - rp.x, estimate.pose.y - rp.y),
        localization=mode.value,
        landmark_updates=estimate.n_updates,
        localization_note=note,
        odometry_calibration=robot.odometry_calibration(),
        report_relocalization=report_reloc,
        path_length_m=budget.path_length_m,
        global_searches=out.global_searches,
        local_searches=out.local_searches,
        sim_time_s=truth_end.robot_time_s - t0,
        wall_time_s=time.perf_counter() - wall0,
        seed=int(seed),
        strategy=strategy.value,
        place=place,
        surface=surface,
        obstacles=tuple(obstacle_poses),
        events=out.events,
        trace=SearchTrace(out, spec, np.array(budget.trajectory), scene, db, track),
        recording=None if recorder is None or (p := recorder.close()) is None else str(p),
        sensing=profile,
        sensing_applies_to=applies,
        robot=run.name,
        watchdog_stops=watchdog,
        t0=t0,
    )


@dataclass(frozen=True)
class _TruthOf:
    """Where a trial's truth comes from (scoring only; None where there is none: the real robot)."""

    G_WO: Callable  # () -> the object in W (4 x 4) or None
    G_WC: Callable  # () -> the camera in W at the last frame or None
    robot_pose: Callable  # () -> Pose2D of the base in W or None
    collisions: Callable  # () -> int


def _session(stack, kind, robot_config, scene, object, seed, sensing, supersample, emulator_setup, G_WO):
    """The trial's robot session (entered on ``stack``) and where its truth comes from."""
    if kind is RobotKind.SIM:
        from lab.sim import RenderSettings, SimWorld

        w = stack.enter_context(SimWorld(scene, RenderSettings(supersample=supersample)))
        run = stack.enter_context(make_robot(world=w, seed=seed, sensing=sensing))
        t = w.truth
        return run, _TruthOf(lambda: t.G_W(object), t.G_WC, t.robot_pose, lambda: int(t.collisions))
    robot = make_robot(robot_config, seed=seed, scene=scene, emulator_setup=emulator_setup, sensing=sensing)
    run = stack.enter_context(robot)
    bumps = lambda: int(run.robot.bumps)  # noqa: E731 - the bumpers' count: a robot's own collisions
    if kind is RobotKind.REHEARSAL:
        r = run.rehearsal

        def G_WC():
            last = r.truth()
            return None if last is None else last.G_WC

        return run, _TruthOf(lambda: run.world.truth.G_W(object), G_WC, r.source.base_pose_W, bumps)
    none = lambda: None  # noqa: E731
    return run, _TruthOf(lambda: G_WO, none, none, bumps)


def _start_of(kind: RobotKind, hw, scene: Scene, room, start):
    """Where a robot's odometry starts in the room (``start``, the config's ``[room] start``, else the
    scene's ``[robot] start``), checked against the room's floor; None in the simulator."""
    if kind is RobotKind.SIM:
        if start is not None:
            raise ConfigError(
                "--start is where a robot stands in the room (with --robot); in the simulator the robot "
                "starts at the scene's [robot] start"
            )
        return None
    size = room.landmarks.room_size if room.landmarks is not None else scene.room.size
    return robot_start(hw, scene.robot_start, start, size)


def _check_real_robot_trial(scene: Scene, object: str, place, obstacles: bool, truth):
    """One clear error for what the real robot cannot do (place the object, add obstacles) or a bad
    measured truth; returns the object's measured pose G_WO (None without ``truth``)."""
    if place is not None:
        raise ConfigError(
            "--place puts the object in a simulated room; on the real robot the object is where you put it "
            "(give its measured pose with --truth X,Y,Z,YAW_DEG to score the run)"
        )
    if obstacles:
        raise ConfigError("--obstacles adds simulated boxes; on the real robot put real ones in its way")
    if truth is None:
        return None
    return measured_pose(scene, object, truth)


def measured_pose(scene: Scene, object: str, truth) -> np.ndarray:
    """The object frame O in the room's frame W from a measured ``(x, y, z_underside, yaw_deg)``: the
    object stands upright at ``(x, y)`` on a surface at height ``z``, turned by ``yaw`` about z (the
    form of ``--place``; the frame's origin is the object's centre, as in the simulator).

    Raises
    ------
    ConfigError
        Not four finite numbers, a point outside the room's floor, or a negative height.
    """
    vals = tuple(truth) if isinstance(truth, (list, tuple, np.ndarray)) else ()
    ok = len(vals) == 4 and all(isinstance(v, (int, float, np.floating, np.integer)) for v in vals)
    if not ok or not all(math.isfinite(float(v)) for v in vals):
        raise ConfigError(f"--truth must be X,Y,Z,YAW_DEG (4 finite numbers [m, m, m, deg]), got {truth!r}")
    x, y, z, yaw = (float(v) for v in vals)
    sx, sy = scene.room.size
    if not (abs(x) < sx / 2 and abs(y) < sy / 2) or z < 0:
        raise ConfigError(
            f"--truth ({x:g}, {y:g}, {z:g}) is not on the room's floor or a surface above it: x within "
            f"+-{sx / 2:g} m, y within +-{sy / 2:g} m (the room's frame, origin at its centre), z >= 0"
        )
    body = scene.with_pose(object, (x, y, z, yaw)).body(object)
    return se3(Rz(body.yaw), np.array(body.centre))


def _search(robot, truth_of: _TruthOf, db, navigate, spec, cfg, seed, recorder, attach, budgets):
    """The agent's run on the enabled robot within the time budgets (sim, wall), with the truth behind
    it read once it has ended: returns the agent's result, the truth, the budgeted robot, its odometry
    at the end and the robot's track (odometry, estimate and truth: for the figures)."""
    robot.enable()
    tracked = TrackedRobot(robot, truth_of.robot_pose)
    budget = BudgetedRobot(tracked, *budgets)
    drive = navigate(budget, spec)
    nav = _relocalizing(drive, tracked, budget)
    agent = SearchAgent(budget, db, nav, ProbabilityMap(spec), cfg, rng=np.random.default_rng([seed, 1]))
    if recorder is not None:
        from lab.viz.live import LiveView

        LiveView.for_search(agent, rate_hz=None, recorder=recorder, widget=False)
    if attach is not None:
        attach(agent)
    out = agent.run()  # the robot stopped on its way out (also after Ctrl-C: then reason "interrupted")
    report_reloc = None
    G_WC = truth_of.G_WC()  # the camera of a found track's last frame (before a report moves the robot)
    if out.reason != INTERRUPTED:
        out, report_reloc = _relocalized_find(out, tracked, drive)
    tracked.record(force=True)  # where the run ended
    truth = _TrialTruth(
        G_WO=truth_of.G_WO(),
        G_WC=G_WC,
        robot_pose=truth_of.robot_pose(),
        collisions=truth_of.collisions(),
        robot_time_s=robot.now(),
    )
    return out, truth, budget, robot.base.odometry(), tracked.track(), report_reloc


def _relocalizing(navigate, robot: LocalizedRobot | TrackedRobot, budget: BudgetedRobot):
    """Active re-localization before every drive: when the pose is uncertain, look for a landmark first.
    Its views step the robot under the ``budget`` wrapper, so the budget is checked before and after:
    a run whose drives all failed at once (an unreachable cell each) looked round for 20 s before each
    and ran on to 768 s of a 300 s budget."""

    def go(*args, **kwargs):
        budget.check()
        robot.relocalize()
        budget.check()
        return navigate(*args, **kwargs)

    for k, v in vars(navigate).items():  # keep what the callable carries (its navigator, for figures)
        setattr(go, k, v)
    return go


def _relocalized_find(
    out: AgentResult, robot: LocalizedRobot | TrackedRobot, navigate=None
) -> tuple[AgentResult, dict | None]:
    """Active re-localization before reporting a found object, to the report's tighter thresholds
    at the object (:meth:`LocalizedRobot.relocalize_to_report`): the object's pose relative to the robot
    stays; its world pose follows the corrected robot pose ``G_WO' = G_WR' G_WR^-1 G_WO``.

    When no landmark from where the robot stands gets the object's point within ``report_sigma_m`` (and
    ``report_detour_above_m``) and ``navigate`` (the search's ``navigate(target_xy, min_distance,
    max_distance)``) is given, a detour (:func:`_report_detour`): the pose the object was found from is
    kept in the filter while the robot drives to a landmark, and ``G_WR'`` is that kept pose as the
    landmark corrected it.

    Also returns what it did, for the JSON's ``report_relocalization`` (None when nothing was reported):
    the landmark updates it made, the object point's position standard deviation before and after, how
    far the reported object moved, and the detour (None: none was needed or possible)."""
    if not out.found or out.G_WO is None or robot.mode is not LocalizationMode.LANDMARKS:
        return out, None
    p_W = out.G_WO[:2, 3].copy()
    est0 = robot.pose_estimate()
    robot.relocalize_to_report(at_W=p_W)
    est1 = robot.pose_estimate()
    G_WR, sigma, detour = est1.pose.G(), est1.point_sigma_m(p_W), None
    cfg = robot.config
    wanted = sigma > max(cfg.report_sigma_m, cfg.report_detour_above_m)
    if wanted and navigate is not None and cfg.report_detour_m > 0:
        kept, detour = _report_detour(robot, navigate)
        if kept is not None:
            G_WR, sigma = kept.pose.G(), kept.point_sigma_m(p_W)
    G_WO = G_WR @ se3_inv(est0.pose.G()) @ out.G_WO
    info = {
        "updates": int(robot.pose_estimate().n_updates - est0.n_updates),
        "point_sigma_before_m": round(est0.point_sigma_m(p_W), 4),
        "point_sigma_after_m": round(sigma, 4),
        "within_report_sigma": bool(sigma <= cfg.report_sigma_m),
        "shift_m": round(float(np.linalg.norm(G_WO[:3, 3] - out.G_WO[:3, 3])), 4),
        "detour": detour,
    }
    return replace(out, G_WO=G_WO), info


def _report_detour(robot: LocalizedRobot | TrackedRobot, navigate) -> tuple[PoseEstimate | None, dict | None]:
    """Keep the robot's pose in the filter (:meth:`Localizer.start_clone`), drive to the nearest place
    from which a landmark is seen well (:meth:`LocalizedRobot.landmark_vantage_points`, on the
    navigator's costmap; the next one if a drive fails, two tries), re-localize there to the report's
    thresholds, and return the kept pose as corrected (None when it could not be kept) and what was
    done, for the JSON: the place, its landmark, whether the robot got there and the updates there.

    The time budget holds: a drive that runs it out ends the detour with what the filter has then."""
    loc = robot.localizer
    nav = getattr(navigate, "navigator", None)
    if nav is None or loc.first_sighting_pending:
        return None, None
    grid = nav.planning_grid()
    spec = grid.spec

    def free(x, y):
        if not spec.contains_xy(x, y):
            return False
        i, j = spec.world_to_cell(x, y)
        return not grid.blocked[i, j]

    spots = robot.landmark_vantage_points(free)
    info = {"to": None, "landmark": None, "arrived": False, "updates": 0, "stopped": None}
    if not spots:
        return None, {**info, "stopped": "no place within reach sees a landmark well"}
    est = robot.pose_estimate()
    n0 = est.n_updates
    loc.start_clone()
    try:
        for x, y, name in spots[:2]:
            info.update(to=[round(float(x), 3), round(float(y), 3)], landmark=name)
            robot.log(
                f"localization: no landmark seen well where the object was found; a detour of "
                f"{math.hypot(x - est.pose.x, y - est.pose.y):.1f} m to see {name}"
            )
            if navigate((x, y), 0.0, 0.2).arrived:
                info["arrived"] = True
                robot.relocalize_to_report()
                break
    except (SearchBudgetExceeded, SafetyStop) as e:
        robot.stop()
        info["stopped"] = str(e)
    finally:
        x_c, S_c = loc.end_clone()
    info["updates"] = int(robot.pose_estimate().n_updates - n0)
    kept = PoseEstimate(Pose2D(*(float(v) for v in x_c)), S_c, robot.now(), LocalizationMode.LANDMARKS)
    return kept, info


def _scored(object: str, out: AgentResult, truth: _TrialTruth, odom) -> dict:
    """The result's fields that compare the run with the truth: pose errors in W and in the camera
    frame C (the perception error alone, without the odometry's drift), success, odometry error; None
    where there is no truth."""
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
        "odometry_error_m": None if rp is None else math.hypot(odom.x - rp.x, odom.y - rp.y),
    }


def progress_line(event: SearchEvent, t0: float = 0.0) -> str:
    """One decision of the search, for the console: ``lab search: t =  27.8 s  local (4, 13): found...``
    (``t`` counted from ``t0``, the search's start on a robot's clock)."""
    where = "" if event.cell is None else f" {tuple(event.cell)}"
    return f"lab search: t = {event.t - t0:6.1f} s  {event.kind}{where}: {event.detail}"


def _with_progress(attach, t0: float = 0.0):
    """An ``attach`` hook that also prints every event of the agent to stderr as it happens (after any
    observer the recorder or ``attach`` set, which it keeps); times from ``t0``."""

    def hook(agent) -> None:
        if attach is not None:
            attach(agent)
        before = agent.observer

        def observer(a, event) -> None:
            if before is not None:
                before(a, event)
            print(progress_line(event, t0), file=sys.stderr, flush=True)

        agent.observer = observer

    return hook


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
class _TrialTruth:
    """The truth at the end of a trial, for scoring only (None where there is none)."""

    G_WO: np.ndarray | None  # the object in W
    G_WC: np.ndarray | None  # the camera in W at the last frame
    robot_pose: object  # Pose2D of the base, or None
    collisions: int
    robot_time_s: float  # the robot's clock at the end


def _check_trial(scene: Scene, object: str, navigate, max_time, record):
    """One clear error for an unknown object, a missing navigator, a bad time budget or a bad recording
    path, before anything is built; returns the recorder (None without ``record``)."""
    names = searchable_objects(scene)
    if object not in names:
        raise ConfigError(f"unknown object {object!r}; searchable objects: {', '.join(names)}")
    if navigate is None:
        raise ConfigError(
            "run_search needs a navigator: navigate=lambda robot, spec: <callable(target_xy, min_d, max_d)>"
        )
    if not (isinstance(max_time, (int, float)) and math.isfinite(max_time) and max_time > 0):
        raise ConfigError(f"max_time must be a finite number of seconds > 0, got {max_time!r}")
    if record is None:
        return None
    from lab.viz.recorder import Recorder

    return Recorder(record)


def _place_object(scene: Scene, object: str, place, obstacles: bool, rng: np.random.Generator):
    """Put the object at ``place`` (checked) or at a seeded random valid spot, and the path's obstacles:
    returns the scene, the placement, its surface and the obstacles' poses."""
    if place is None:
        place = random_placement(scene, object, rng)
    surface = check_placement(scene, object, place).kind
    place = tuple(float(v) for v in place)
    scene = scene.with_pose(object, place)
    obstacle_poses: list = []
    if obstacles:
        scene, obstacle_poses = path_obstacles(scene, object, place, rng)
    return scene, place, surface, obstacle_poses


# --- the navigation the search drives with -----------------------------------------------------------


def navigator_factory(robot, spec, timeout_s: float = 120.0, config=None):
    """``navigate`` for :func:`run_search`: scan once, then ``go_near`` each target.

    The navigator's workspace is the floor the map ``spec`` covers (the scene's room); ``config`` is its
    :class:`~lab.navigation.navigator.NavigatorConfig` (default: the navigator's). The returned
    callable keeps its :class:`~lab.navigation.Navigator` as ``navigate.navigator`` (its costmap is what
    ``lab search --out`` draws under the trajectory). Each outcome carries the path A* plans first on the
    current costmap (``path_xy``, for the figures; the navigator replans on the way). A drive that ends
    in a safety stop (``SAFETY_STOP``: a cliff or a wheel drop; the robot is disarmed) raises
    :class:`~lab.errors.SafetyStop`, which ends the search with that fault.
    """
    x0, x1, y0, y1 = (round(v, 9) for v in spec.extent)  # 30 x 0.2 m is 6.000000000000001 m
    nav = Navigator(robot, config=config, bounds=(x0, y0, x1, y1))
    state = {"scanned": False}

    def navigate(target_xy, min_distance: float, max_distance: float) -> NavigationResult:
        if not state["scanned"]:
            nav.scan()
            state["scanned"] = True
        first = astar_to_region(nav.planning_grid(), robot.odometry(), target_xy, max_distance, min_distance)
        r = nav.go_near(target_xy, min_distance, max_distance, timeout=timeout_s)
        if r.outcome is NavOutcome.SAFETY_STOP:
            # the robot stopped itself (cliff, wheel drop) and stays disarmed: the search cannot go on; the
            # agent ends the run with this fault (without this, each next target failed at once)
            raise SafetyStop(r.reason or r.outcome.value)
        arrived = r.outcome is NavOutcome.ARRIVED
        path = first.points_xy if first.found else None
        return NavigationResult(arrived, r.reason or r.outcome.name, r.pose, path)

    navigate.navigator = nav
    return navigate
