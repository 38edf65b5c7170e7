"""One search trial, end to end: build the world, place the object, search, and score against truth.

:func:`run_search` is what ``lab search`` runs; :meth:`SearchResult.to_json` is exactly what it writes
(the fields of the ``lab search`` contract in ``design.md``, and more; the result types and the
scoring are in :mod:`lab.runs.search_result`). The agent never sees the truth: the object's true pose,
the collision count and the errors are filled in here, after the run.

This module only sets up, runs and scores. The search's decisions are the algorithm layer's: when to
re-localize, before every drive and before a find is reported, with its detour
(:class:`~lab.search.report_policy.ReportPolicy`), and how the agent drives
(:class:`~lab.search.navigate.NavigatorAdapter`, which :func:`navigator_factory` builds).

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
from dataclasses import dataclass, replace

import numpy as np

from lab.errors import ConfigError
from lab.geometry import Rz, se3
from lab.localization import LocalizationMode
from lab.mounts import HeadMounts, load_mounts
from lab.navigation.grid import GridSpec
from lab.robot import Robot
from lab.runs.moving import (
    MovingOptions,
    agent_config,
    check_moving_surface,
    found_time,
    moving_record,
    passable_of,
)
from lab.runs.placement import check_placement, path_obstacles, random_placement, searchable_objects, supports
from lab.runs.robots import RobotKind, levelled, load_robot_config, robot_kind
from lab.runs.room import localize, room_landmarks, survey_the_room, survey_to_use, with_stored_survey
from lab.runs.search_result import (
    SUCCESS_ORIENTATION_DEG,
    SUCCESS_POSITION_M,
    SearchResult,
    SearchTrace,
    TrialTruth,
    outcome_in_words,
    pose_errors,
    scored,
)
from lab.runs.session import TruthOf, levels_by_default, start_of, trial_session
from lab.runs.tracks import TrackedRobot
from lab.scene import Scene, load_scene
from lab.search.agent import INTERRUPTED, SearchAgent, SearchEvent, Strategy
from lab.search.budget import BudgetedRobot
from lab.search.config import SearchAgentConfig
from lab.search.navigate import NavigatorAdapter
from lab.search.probability_map import ProbabilityMap
from lab.search.report_policy import ReportPolicy
from lab.training.search import search_database

__all__ = [
    "SUCCESS_ORIENTATION_DEG",
    "SUCCESS_POSITION_M",
    "SearchResult",
    "SearchTrace",
    "TrialOptions",
    "map_spec",
    "measured_pose",
    "navigator_factory",
    "outcome_in_words",
    "path_obstacles",
    "pose_errors",
    "progress_line",
    "run_search",
    "run_trial",
]

NavigatorFactory = Callable[[Robot, GridSpec], Callable]


def map_spec(scene: Scene, resolution: float = 0.2) -> GridSpec:
    """The probability map's grid: the room's floor in ``resolution`` cells (the paper's 20 cm)."""
    if scene.room is None:
        raise ConfigError(f"scene {scene.name!r} has no room to search")
    sx, sy = scene.room.size
    return GridSpec.from_bounds(-sx / 2, -sy / 2, sx / 2, sy / 2, resolution)


@dataclass(frozen=True)
class TrialOptions:
    """How one search trial runs: the arguments of :func:`run_search` after ``object`` and ``seed``
    (``seed`` seeds the placement when ``place`` is None, the obstacles, the sensor errors and RANSAC).

    Attributes
    ----------
    place : (x, y, z_underside, yaw_deg), optional
        Where to put the object (checked: in the room, on a surface, clear of the other bodies and the
        robot). Default: a seeded random valid placement. Not on the real robot (the object is where
        the operator put it).
    strategy : {"paper", "rate", "lawnmower", "frontier"}; max_time, max_wall_time : float [s]
        Time budget of the robot's clock (simulated time; on a robot, wall time): the run ends "not
        found" when it is used up; and, optionally, a wall-clock budget.
    navigate : callable ``(robot, spec) -> navigate``
        Required: the navigation callable (:mod:`lab.search.agent`) for the budgeted robot and the
        map's grid (:func:`navigator_factory`). The report's detour plans on a
        :class:`~lab.search.navigate.NavigatorAdapter`'s navigator; another callable gets no detour.
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
        Where the robot's pose comes from (:class:`lab.localization.LocalizedRobot`): the
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
    moving : MovingOptions, optional
        The simulator only: the object moves over the floor or a table's top, and the agent predicts it
        unless it is the static-map baseline (:mod:`lab.runs.moving`). None: the paper's stationary
        object.
    view3d : path, optional
        Write the recorded 3D view there (:mod:`lab.viz.view3d`: one HTML page, one step per event).
    mounts : path or HeadMounts, optional
        A mount calibration file (``lab hardware calibrate``, :mod:`lab.mounts`): the robot's camera frame
        includes it. Default: none in the simulator; a robot config's ``[camera] mounts`` if it exists.
    level : bool or None
        Without a mount calibration, level the camera against the floor before the search
        (:func:`lab.runs.robots.levelled`: the head turns round looking down for about 16 s before the
        search's clock and budget start; the mounts' roll and pitch it finds are in every later frame,
        and in the JSON's ``camera_level``). A bracket half a degree off square put found objects 1-2 cm
        too high and decided the room's failures (docs/tuning/room-errors.md). None (default): in the
        simulator when the sensing profile states a mount error (:func:`lab.runs.robots.mounts_stated`:
        ``realistic``'s half a degree; a robot told its mounts are exact, as under ``sensors`` or a
        sensing file with both mount sigmas 0, keeps its kinematics, since the floor levels the camera to
        0.2-0.3 deg and would only add that), not on a robot (calibrated once with ``lab hardware
        calibrate``; its rehearsal's levelling is not yet checked, docs/tuning/camera-level.md); True: on
        a robot too; False: the nominal kinematics.
    survey_tour : bool
        Before the search, drive a survey tour that ties the posters of a surveyed map together
        (:func:`lab.runs.room.survey_the_room`; outside the search's budgets; the JSON's ``survey_tour``).
    survey : str, Path, StoredSurvey or None
        A room surveyed once (``lab survey``'s file, :mod:`lab.localization.stored_survey`): the robot
        starts from its refined posters and their joint covariance instead of the map's survey. None: a
        robot config's ``[room] survey`` if it has one.
    """

    place: tuple | None = None
    strategy: str | Strategy = "paper"
    max_time: float = 600.0
    navigate: NavigatorFactory | None = None
    obstacles: bool = False
    world: str | Scene = "lab_room"
    config: SearchAgentConfig | None = None
    supersample: int = 2
    max_wall_time: float | None = None
    progress: bool = False
    record: object = None
    attach: Callable | None = None
    sensing: object = "realistic"
    localization: str = "landmarks"
    robot_config: object = None
    truth: object = None
    emulator_setup: Callable | None = None
    start: tuple | None = None
    moving: MovingOptions | None = None
    view3d: object = None
    mounts: object = None
    level: bool | None = None
    survey_tour: bool = False
    survey: object = None


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
    config: SearchAgentConfig | None = None,
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
    moving: MovingOptions | None = None,
    view3d=None,
    mounts=None,
    level: bool | None = None,
    survey_tour: bool = False,
    survey=None,
) -> SearchResult:
    """Run one search trial (in the simulator, a rehearsal or on the robot) and score it.

    ``object`` is a searchable object (:func:`lab.runs.placement.searchable_objects`); ``seed`` seeds
    the placement (when ``place`` is None), the obstacles, the sensor errors and RANSAC. The other
    arguments are the fields of :class:`TrialOptions`, which says what each does; ``navigate`` is
    required. :func:`run_trial` takes them as one :class:`TrialOptions`.
    """
    options = TrialOptions(
        place=place,
        strategy=strategy,
        max_time=max_time,
        navigate=navigate,
        obstacles=obstacles,
        world=world,
        config=config,
        supersample=supersample,
        max_wall_time=max_wall_time,
        progress=progress,
        record=record,
        attach=attach,
        sensing=sensing,
        localization=localization,
        robot_config=robot_config,
        truth=truth,
        emulator_setup=emulator_setup,
        start=start,
        moving=moving,
        view3d=view3d,
        mounts=mounts,
        level=level,
        survey_tour=survey_tour,
        survey=survey,
    )
    return run_trial(object, seed, options)


def run_trial(object: str, seed: int, opts: TrialOptions) -> SearchResult:
    """Run one search trial with its :class:`TrialOptions` and score it (:func:`run_search`): set up
    the world and the robot, run the agent under its report policy, score."""
    wall0 = time.perf_counter()
    strategy = Strategy.parse(opts.strategy)
    scene = opts.world if isinstance(opts.world, Scene) else load_scene(opts.world)
    recorder = _check_trial(scene, object, opts.navigate, opts.max_time, opts.record)
    viewer = _viewer(opts.view3d)  # a missing viewer library: one line before anything starts
    hw = load_robot_config(opts.robot_config)  # a bad robot config is one clear line before anything starts
    if opts.mounts is not None and not isinstance(opts.mounts, HeadMounts):  # so is a bad calibration file
        opts = replace(opts, mounts=load_mounts(opts.mounts))
    kind = robot_kind(hw)
    # the landmark map (a bad landmark file is one line too) and where the robot's odometry starts
    room = room_landmarks(kind, hw, scene, opts.localization, opts.progress, sensing=opts.sensing, seed=seed)
    room = with_stored_survey(room, survey_to_use(opts.survey, hw, room))  # a room surveyed once
    mode, note = room.mode, room.note
    start_pose = start_of(kind, hw, scene, room, opts.start)
    rng = np.random.default_rng(seed)
    scene, place, surface, obstacle_poses, G_WO_measured = _trial_world(kind, scene, object, opts, rng)
    db = search_database(object, progress=opts.progress)
    cfg = replace(opts.config or SearchAgentConfig(), strategy=strategy)
    cfg = cfg if opts.moving is None else agent_config(cfg, opts.moving)
    spec = map_spec(scene)
    with contextlib.ExitStack() as stack:
        run, truth_of = trial_session(stack, kind, hw, scene, object, seed, opts, G_WO_measured)
        to_level = opts.level if opts.level is not None else levels_by_default(kind, opts.sensing)
        base, level = levelled(run.robot) if to_level else (run.robot, None)
        # on a robot its odometry starts at (0, 0, 0): placed at the start in the room (lab/runs/room.py)
        robot = localize(base, kind, room, start_pose, seed)
        tour = survey_the_room(robot, spec) if opts.survey_tour and room.landmarks is not None else None
        t0 = robot.now()  # the search's start: after the levelling (the simulator's clock is 0 without it)
        hook = _with_progress(opts.attach, t0) if opts.progress else opts.attach
        if viewer is not None:  # the world's bodies and the tables' and shelves' tops: display only
            viewer.world, hook = run.world, viewer.attach_search(hook)
            viewer.set_surfaces([(s.name, s.z, s.polygon) for s in supports(scene) if s.kind != "floor"])
        parts = (db, opts.navigate, spec, cfg, seed, recorder, hook, (opts.max_time, opts.max_wall_time))
        out, truth_end, budget, odom, track, report_reloc = _search(robot, truth_of, *parts)
        profile, applies = run.sensing, tuple(run.sensing_applies_to)
        estimate = robot.pose_estimate()
        watchdog = None if kind is RobotKind.SIM else int(run.robot.watchdog_stops)
    if viewer is not None:
        viewer.save()
    return SearchResult(
        **scored(object, out, truth_end, odom),
        **_localization_fields(robot, mode, note, estimate, truth_end.robot_pose),
        odometry_calibration=robot.odometry_calibration(),
        camera_estimate=robot.camera_estimate(),
        report_relocalization=report_reloc,
        camera_level=level,
        survey_tour=tour,
        stored_survey=room.stored_survey,
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
        moving=None if opts.moving is None else moving_record(opts.moving, truth_of.mover, truth_end.time_s),
    )


def _localization_fields(robot, mode: LocalizationMode, note: str | None, estimate, robot_pose) -> dict:
    """A search result's localization fields: the localizer's error against the true pose at the end
    (None on a real robot), the landmark updates and re-finds, and the note (printed: why the pose is
    odometry alone)."""
    if note is None and mode is LocalizationMode.LANDMARKS and estimate.n_updates == 0:
        note = "no landmark was seen: the pose is odometry alone"
    if note is not None:
        print(f"lab: localization: {note}", file=sys.stderr)
    rp = robot_pose
    error = None if rp is None else math.hypot(estimate.pose.x - rp.x, estimate.pose.y - rp.y)
    return {
        "localization_error_m": error,
        "localization": mode.value,
        "landmark_updates": estimate.n_updates,
        "landmark_refinds": robot.localizer.n_refinds,
        "localization_note": note,
    }


def _viewer(view3d):
    """The 3D view a trial records (``TrialOptions.view3d``), or None."""
    if view3d is None:
        return None
    from lab.viz.view3d import View3D

    return View3D(view3d)


def _trial_world(kind: RobotKind, scene: Scene, object: str, opts: TrialOptions, rng: np.random.Generator):
    """The object's placement and the path's obstacles (:func:`_place_object`), or on the real robot
    the measured truth: returns the scene, the placement, its surface, the obstacles' poses and the
    object's measured pose G_WO (None but on the real robot with ``truth``)."""
    place, truth = opts.place, opts.truth
    if opts.moving is not None and kind is not RobotKind.SIM:
        raise ConfigError("--moving moves a simulated object; with --robot the object is what you move")
    if kind is RobotKind.HARDWARE:
        G_WO_measured = _check_real_robot_trial(scene, object, place, opts.obstacles, truth)
        place, surface, obstacle_poses = (None if truth is None else tuple(float(v) for v in truth)), None, []
        return scene, place, surface, obstacle_poses, G_WO_measured
    if truth is not None:
        raise ConfigError(
            "--truth is the object's measured pose on the real robot; in the simulator and a rehearsal "
            "the truth is known (put the object with --place)"
        )
    moving = None if opts.moving is None else opts.moving.surface  # a carrier's: the floor or a table
    scene, place, surface, obstacle_poses = _place_object(scene, object, place, opts.obstacles, rng, moving)
    return scene, place, surface, obstacle_poses, None


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


def _search(robot, truth_of: TruthOf, db, navigate, spec, cfg, seed, recorder, attach, budgets):
    """The agent's run on the enabled robot within the time budgets (sim, wall), with the truth behind
    it read once it has ended: returns the agent's result, the truth, the budgeted robot, its odometry
    at the end and the robot's track (odometry, estimate and truth: for the figures)."""
    robot.enable()
    tracked = TrackedRobot(robot, truth_of.robot_pose)
    budget = BudgetedRobot(tracked, *budgets)
    drive = navigate(budget, spec)
    navigator = drive.navigator if isinstance(drive, NavigatorAdapter) else None
    upright = cfg.local_search.max_rest_tilt_deg is not None  # the boxes rest on a face (pose_check)
    policy = ReportPolicy(tracked, drive, navigator, check=budget.check, rests_on_face=upright)
    nav = policy.relocalizing()
    passable = passable_of(drive, spec) if cfg.motion is not None else None
    agent = SearchAgent(
        budget, db, nav, ProbabilityMap(spec), cfg, rng=np.random.default_rng([seed, 1]), passable=passable
    )
    if recorder is not None:
        from lab.viz.live import LiveView

        LiveView.for_search(agent, rate_hz=None, recorder=recorder, widget=False)
    if attach is not None:
        attach(agent)
    out = agent.run()  # the robot stopped on its way out (also after Ctrl-C: then reason "interrupted")
    report_reloc = None
    G_WC = truth_of.G_WC()  # the camera of a found track's last frame (before a report moves the robot)
    if out.reason != INTERRUPTED:
        out, report_reloc = policy.report(out)
    tracked.record(force=True)  # where the run ended
    t_found = found_time(out) if truth_of.mover is not None else None  # a moving object: at the find
    truth = TrialTruth(
        G_WO=truth_of.G_WO() if t_found is None else truth_of.mover.G_WO_at(t_found),
        G_WC=G_WC,
        robot_pose=truth_of.robot_pose(),
        collisions=truth_of.collisions(),
        robot_time_s=robot.now(),
        time_s=robot.now() if t_found is None else t_found,
    )
    return out, truth, budget, robot.base.odometry(), tracked.track(), report_reloc


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


def _place_object(scene: Scene, object: str, place, obstacles: bool, rng: np.random.Generator, moving=None):
    """Put the object at ``place`` (checked) or at a seeded random valid spot (on the surface ``moving``
    names for a moving object), and the path's obstacles: returns the scene, the placement, its surface
    and the obstacles' poses."""
    if place is None:
        place = (
            random_placement(scene, object, rng)
            if moving is None
            else random_placement(scene, object, rng, moving)
        )
    surface = check_placement(scene, object, place).kind
    if moving is not None:
        check_moving_surface(surface)
    place = tuple(float(v) for v in place)
    scene = scene.with_pose(object, place)
    obstacle_poses: list = []
    if obstacles:
        scene, obstacle_poses = path_obstacles(scene, object, place, rng)
    return scene, place, surface, obstacle_poses


# --- the navigation the search drives with -----------------------------------------------------------


def navigator_factory(robot, spec, timeout_s: float = 120.0, config=None) -> NavigatorAdapter:
    """``navigate`` for :func:`run_search`: a :class:`~lab.search.navigate.NavigatorAdapter` (scan once,
    then ``go_near`` each target) driving ``robot`` over the floor the map ``spec`` covers, each drive
    within ``timeout_s``, with the navigator's ``config`` (default: the navigator's). Its navigator
    (``navigate.navigator``) has the costmap ``lab search --out`` draws under the trajectory."""
    return NavigatorAdapter(robot, spec, timeout_s, config)
