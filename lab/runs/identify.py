"""One identification episode, set up, run and scored: what ``lab identify`` and ``lab demo`` call.

In the simulator (no robot config) the scene is the identification paper's: the observing robot in the
open ``arena``, the box to identify (``true_model``) on a carrier 1.2 m in front of it, turned so that the
robot first faces a *shared* face (the unique face points away), and moved by a mover (static, scripted,
random, evasive, teleop). With a robot config (``--robot``) the same agent runs on
:class:`~lab.hardware.robot.HardwareRobot`: in a rehearsal (``[camera] source = "sim"``) on the device
emulators with the box rendered from their state, or on the real robot, where there is no truth and
``true_model``, ``success`` and the pose error are None. :func:`~lab.runs.robots.make_robot` is the switch.

Ground truth is used only to score the run (pose error) and by the mover, never by the agent. The
databases and lookup tables come from :mod:`lab.training` (built on first use, and said so); the
agent is handed them (:func:`build_agent`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from lab.errors import ConfigError
from lab.geometry import Pose2D, se3_inv
from lab.identification.agent import AgentConfig, IdentificationAgent, PlannerChoice
from lab.identification.evaluators import make_evaluator
from lab.identification.scoring import ScoringConfig
from lab.io import write_json_atomic
from lab.localization import LocalizationMode, LocalizedRobot
from lab.robot import Robot
from lab.runs.robots import PlacedRobot, RobotKind, RobotSession, load_robot_config, make_robot, robot_kind
from lab.runs.room import (
    RoomLandmarks,
    localize,
    robot_start,
    room_landmarks,
    survey_to_use,
    with_stored_survey,
)
from lab.runs.tracks import TrackedRobot
from lab.search.world_pose import larger_axes_std
from lab.training import box_model_names, get_databases, get_tables

__all__ = ["build_agent", "final_pose_estimate", "floor_plan", "pose_error", "run_identify"]


def pose_error(G_est: np.ndarray, G_true: np.ndarray) -> dict:
    """Translation [m] and rotation [deg] between an estimated and the true pose (4 x 4 each)."""
    R = G_est[:3, :3].T @ G_true[:3, :3]
    return {
        "translation_m": float(np.linalg.norm(G_est[:3, 3] - G_true[:3, 3])),
        "rotation_deg": math.degrees(math.acos(float(np.clip((np.trace(R) - 1) / 2, -1, 1)))),
    }


def floor_plan(room_size_m: tuple[float, float], robot_radius_m: float, resolution_m: float = 0.1):
    """The known floor plan of a rectangular room centred on the origin, as A*'s cost grid: the walls
    grown by the robot's radius (a map the operator gives the robot, not the simulator's state).

    Parameters
    ----------
    room_size_m : (float, float) [m]
        The room's x and y extent.
    robot_radius_m : float [m]
        The robot's footprint radius.
    """
    from lab.navigation import Costmap, GridSpec

    sx, sy = (float(v) for v in room_size_m)
    if not (sx > 0 and sy > 0):
        raise ConfigError(f"room size must be positive, got {room_size_m}")
    spec = GridSpec.from_bounds(-sx / 2, -sy / 2, sx / 2, sy / 2, resolution_m)
    wall = np.zeros(spec.shape, dtype=bool)
    wall[0, :] = wall[-1, :] = wall[:, 0] = wall[:, -1] = True
    return Costmap.from_occupancy(spec, wall).inflated(robot_radius_m + resolution_m)


def build_agent(
    robot: Robot,
    planner: str = "lut",
    seed: int = 0,
    config: AgentConfig | None = None,
    names: Sequence[str] | None = None,
    floor_plan=None,
) -> IdentificationAgent:
    """The identification agent on ``robot`` with its parts: the models' feature databases, and the
    ``lut`` planner's lookup tables or the ``mc`` planner's databases, from the training cache (built
    first when missing, and said so on stderr)."""
    try:
        choice = PlannerChoice(planner)
    except ValueError:
        raise ConfigError(
            f"unknown planner {planner!r}; planners: {', '.join(p.value for p in PlannerChoice)}"
        ) from None
    names = tuple(names or box_model_names())
    dbs = get_databases(names)
    scoring = ScoringConfig().for_camera(robot.camera)  # the agent's and its evaluator's
    tables = get_tables(names, dbs=dbs) if choice is PlannerChoice.LUT else None
    evaluator = make_evaluator(choice, dbs, robot.camera, scoring, tables)
    return IdentificationAgent(
        robot, dbs, evaluator, config, planner=choice, seed=seed, scoring=scoring, floor_plan=floor_plan
    )


def run_identify(
    true_model: int,
    seed: int = 0,
    mover: str = "evasive",
    planner: str = "lut",
    max_actions: int = 8,
    out: Path | None = None,
    json_path: Path | None = None,
    max_time_s: float = 240.0,
    figures: bool = True,
    record: Path | None = None,
    attach=None,
    keep_direction: float | None = None,
    robot_config=None,
    progress=None,
    sensing="realistic",
    localization="odometry",
    start=None,
    view3d: Path | None = None,
) -> dict:
    """Run one episode and return the ``lab identify`` JSON (also written to ``json_path``).

    Parameters
    ----------
    true_model, seed : int
        The box on the carrier (0..3; ignored on the real robot); seeds the start poses' jitter, the
        sensor errors, RANSAC and the random movers/planners.
    mover, planner : str
        static, scripted, random, evasive or teleop (simulator and rehearsal); lut, mc, random or circle.
    record : Path, optional
        Write an animation of the live view (:mod:`lab.viz.live`) there, one frame per step.
    keep_direction : float, optional
        :attr:`AgentConfig.keep_direction <lab.identification.agent.AgentConfig>` (default 0.5; 1.0 is
        the plain argmax of Eq. (6)).
    attach : callable, optional
        ``attach(agent, carrier)`` once the agent is built, before it runs: a notebook's live view
        and teleoperation panel, e.g. ``display(LiveView.for_identification(agent).widget)`` and
        ``display(TeleopPanel(carrier.mover).widget)`` (with ``mover="teleop"``).
    robot_config : path or HardwareConfig, optional
        Run on its robot (:func:`~lab.runs.robots.make_robot`); None: the simulator.
    progress : callable(str), optional
        One line per decision (the robot's console).
    sensing : str or mapping
        The simulator's sensing profile (:func:`lab.sim.sensing.sensing_profile`), the JSON's ``sensing``;
        a rehearsal's rendered camera follows its camera section (the JSON's ``sensing_applies_to``).
    localization : {"landmarks", "odometry"}
        Where the robot's pose comes from (:class:`lab.localization.LocalizedRobot`); a robot's map is
        its config's ``[room] landmarks``, a rehearsal's the rendered scene's posters (:mod:`lab.runs.room`).
    start : (x_m, y_m, heading_deg), optional
        A robot only: where it stands in the room at the start (default: its config's ``[room] start``, a
        rehearsal's ``[sim] robot_start``; the real robot without one uses odometry alone, and says so).
    view3d : Path, optional
        Write the recorded 3D view there (:mod:`lab.viz.view3d`, one HTML page); the JSON's ``view3d``.
    """
    hw, room, start_at = _checked_setup(true_model, robot_config, localization, start, view3d, sensing, seed)
    config = _agent_config(max_actions, max_time_s, keep_direction)
    t_wall, t_cpu = time.perf_counter(), time.process_time()  # CPU: the episode's cost whatever the load
    with contextlib.ExitStack() as stack:
        session = _start(stack, hw, true_model, mover, seed, sensing)
        plan = _known_floor_plan(session)
        robot, note = _localized(session, room, start_at, seed)
        tracked = TrackedRobot(robot, _truth_pose(session))  # the robot's path, for Fig. 6
        agent = build_agent(tracked, planner, seed, config, floor_plan=plan)
        recorder, viewer = _watch(agent, record, progress), _viewer(agent, session, view3d)
        if attach is not None:
            attach(agent, session.carrier)
        truth = _record_truth(agent, session)
        t0 = 0.0 if session.kind is RobotKind.SIM else session.robot.now()
        identified, interrupted, loop = _run_loop(agent, robot, session, tracked)
        error = _final_pose_error(agent, session, truth, true_model)
        elapsed = session.robot.now() - t0
        extra = {**_robot_fields(session), **_localization_fields(robot, session, note, room.stored_survey)}
    wall, cpu = time.perf_counter() - t_wall, time.process_time() - t_cpu
    result = _episode_json(agent, session, true_model, identified, planner, seed, mover, t0)
    result.update(sim_time_s=elapsed, wall_time_s=wall, pose_error=error, **extra)
    _add_reason_and_speed(result, agent, session, identified, interrupted, (elapsed, wall, cpu, loop))
    _finish_recording(recorder, result, progress, viewer)
    poses = [G for _, G in truth]
    _write(result, json_path, out if figures else None, agent, session, poses, tracked.track())
    return result


def _checked_setup(true_model: int, robot_config, localization, start, view3d=None, sensing=None, seed=0):
    """The robot config, the room's landmarks and the robot's start in the room, each checked before
    anything starts (a bad model, config or map, or a 3D view without its optional viewer: one clear
    error)."""
    from lab.sim import box_model

    box_model(true_model)  # a clear error before anything starts
    if view3d is not None:
        from lab.viz.view3d import require_viser

        require_viser()
    hw = load_robot_config(robot_config)
    kind = robot_kind(hw)
    # a bad map is one line, first; in the simulator the surveyed map of the profile's room errors
    room = room_landmarks(kind, hw, _scene_of(kind, hw), localization, sensing=sensing, seed=seed)
    room = with_stored_survey(room, survey_to_use(None, hw, room))  # a robot's [room] survey
    return hw, room, _start_of(kind, hw, room, start)


def _agent_config(max_actions: int, max_time_s: float, keep_direction: float | None) -> AgentConfig:
    """The agent's config: the defaults with the episode's budgets (and ``keep_direction`` if given)."""
    config = AgentConfig(max_actions=max_actions, max_time_s=max_time_s)
    if keep_direction is not None:
        config = dataclasses.replace(config, keep_direction=keep_direction)
    return config


def _known_floor_plan(session: RobotSession):
    """The room's floor plan handed to the agent in a simulated room (:func:`floor_plan`); else None."""
    world = session.world
    plan = None
    if session.kind is RobotKind.SIM and world.scene.room is not None:
        plan = floor_plan(world.scene.room.size, session.robot.base_limits.radius)
    return plan


def _run_loop(
    agent: IdentificationAgent, robot: LocalizedRobot, session: RobotSession, tracked: TrackedRobot
):
    """Run the agent, then record where the episode ended on ``tracked``: ``(identified, interrupted,
    loop)``, ``loop`` the loop's own sim, wall and CPU time [s] (no start-up: databases, tables, scene;
    no figures)."""
    sim_t0, loop_wall0, loop_cpu0 = session.robot.now(), time.perf_counter(), time.process_time()
    interrupted = False
    try:
        if robot.mode is LocalizationMode.LANDMARKS and session.kind is not RobotKind.SIM:
            # a robot's start was measured by hand: look for a poster first (the first sighting may
            # correct it), then put the head back; the agent tracks the box, not the walls
            robot.enable()
            robot.relocalize()
        identified = agent.run()  # stops the robot on its way out
    except KeyboardInterrupt:  # Ctrl-C: the motors are stopped; the record so far is the result
        interrupted, identified = True, agent.identified
    loop = {  # the loop alone: no start-up (databases, tables, scene), no figures
        "sim": session.robot.now() - sim_t0,
        "wall": time.perf_counter() - loop_wall0,
        "cpu": time.process_time() - loop_cpu0,
    }
    tracked.record(force=True)  # where the episode ended
    return identified, interrupted, loop


def _add_reason_and_speed(result: dict, agent, session: RobotSession, identified, interrupted, times) -> None:
    """Add ``reason`` to ``result`` and, in the simulator, the speed fields; ``times`` is ``(elapsed,
    wall, cpu, loop)`` (:func:`_speed_fields`)."""
    elapsed, wall, cpu, loop = times
    result["reason"] = _reason(agent, identified, interrupted)
    if session.kind is RobotKind.SIM:
        result.update(_speed_fields(elapsed, wall, cpu, loop))


#: The ``reason`` of an episode ended by Ctrl-C (SIGINT, a notebook's "interrupt kernel").
INTERRUPTED = "interrupted"


def _reason(agent: IdentificationAgent, identified, interrupted: bool) -> str:
    """Why the episode ended, in words."""
    if interrupted:
        return INTERRUPTED
    if identified is not None:
        return "identified"
    if agent.n_actions >= agent.config.max_actions:
        return "action budget spent"
    return "time budget used up"


def _scene_of(kind: RobotKind, hw) -> str | None:
    """The scene behind an episode: the simulator's arena, a rehearsal's ``[sim] world``, none on the real
    robot (its room is its landmark map)."""
    if kind is RobotKind.SIM:
        return "arena"
    return hw.sim.world if kind is RobotKind.REHEARSAL else None


def _start_of(kind: RobotKind, hw, room: RoomLandmarks, start):
    """Where a robot's odometry starts in the room (``start``, ``[room] start``, a rehearsal's ``[sim]
    robot_start``), checked against the room's floor; None in the simulator and where it is unknown."""
    if kind is RobotKind.SIM:
        if start is not None:
            raise ConfigError(
                "--start is where a robot stands in the room (with --robot); in the simulator the episode "
                "places the robot itself"
            )
        return None
    size = None
    if room.landmarks is not None:
        size = room.landmarks.room_size
    elif kind is RobotKind.REHEARSAL:
        from lab.scene import load_scene

        sc = load_scene(hw.sim.world)
        size = None if sc.room is None else sc.room.size
    default = hw.sim.robot_start if kind is RobotKind.REHEARSAL else None
    return robot_start(hw, default, start, size)


def _localized(session: RobotSession, room: RoomLandmarks, start_pose, seed: int):
    """The episode's robot, on a robot placed at its start in the room, behind the localizer
    (:func:`lab.runs.room.localize`), and a note when it has to fall back to odometry alone (no landmark
    map, or a real robot with no start pose in the room)."""
    note = room.note
    if room.mode is LocalizationMode.LANDMARKS and session.kind is not RobotKind.SIM and start_pose is None:
        note = (
            "no start pose in the room for this robot (--start X,Y,YAW_DEG or [room] start in its config): "
            "the pose is odometry alone"
        )
        room = RoomLandmarks(LocalizationMode.ODOMETRY, note=note)
    return localize(session.robot, session.kind, room, start_pose, seed), note


def _truth_pose(session: RobotSession):
    """The true base pose for the robot's track (figures only): the simulator's; None elsewhere (the
    episode's figures are drawn in the simulator only; a real robot has no truth)."""
    return session.world.truth.robot_pose if session.kind is RobotKind.SIM else None


def _localization_fields(robot: LocalizedRobot, session: RobotSession, note, stored_survey=None) -> dict:
    """``localization``, ``odometry_error_m`` and ``localization_error_m`` (against the simulator's
    truth; null without one), the landmark updates, a note when no landmark was used, and the room
    surveyed once that the localizer started from (``stored_survey``, from a robot's ``[room] survey``)."""
    est = robot.pose_estimate()
    if note is None and robot.mode is LocalizationMode.LANDMARKS and est.n_updates == 0:
        note = "no landmark was seen: the pose is odometry alone"
    if note is not None:
        print(f"lab: localization: {note}", file=sys.stderr)
    odo_err = loc_err = None
    t = None
    if session.kind is RobotKind.SIM:
        t = session.world.truth.robot_pose()
    elif session.kind is RobotKind.REHEARSAL and isinstance(robot.base, PlacedRobot):
        t = session.rehearsal.source.base_pose_W()  # the emulator's true pose in the rendered world
    if t is not None:
        o = robot.base.odometry()  # the wheel odometry (placed at the start in the room on a robot)
        odo_err = round(math.hypot(o.x - t.x, o.y - t.y), 4)
        loc_err = round(math.hypot(est.pose.x - t.x, est.pose.y - t.y), 4)
    return {
        "localization": robot.mode.value,
        "odometry_error_m": odo_err,
        "localization_error_m": loc_err,
        "landmark_updates": est.n_updates,
        "localization_note": note,
        "odometry_calibration": robot.odometry_calibration(),
        "camera_estimate": robot.camera_estimate(),
        "stored_survey": stored_survey,
    }


def _write(result: dict, json_path, out, agent, session: RobotSession, true_poses: list, track=None) -> None:
    """The JSON to ``json_path``; in the simulator, Figs. 5-7 (Fig. 6 with the robot's ``track``) and
    ``identify.json`` into ``out``."""
    if json_path is not None:
        write_json_atomic(Path(json_path), result)
    if out is not None and agent.steps and session.kind is RobotKind.SIM:
        from lab.viz.identification import save_episode_figures

        save_episode_figures(Path(out), agent, true_poses, result["true_model"], track=track)
        write_json_atomic(Path(out) / "identify.json", result)


def _start(stack: contextlib.ExitStack, robot_config, true_model, mover, seed, sensing) -> RobotSession:
    """The robot of the episode, with the box in front of it (in the simulator: the arena, the box on
    a carrier 1.2 m ahead, its unique face (+X) pointing away so that the robot sees shared faces first)."""
    if robot_config is not None:
        rc = make_robot(robot_config, true_model=true_model, mover=mover, seed=seed, sensing=sensing)
        return stack.enter_context(rc)
    from lab.sim import SimWorld, load_box_models
    from lab.sim.movers import make_mover

    models = load_box_models()
    rng = np.random.default_rng(seed)
    world = stack.enter_context(SimWorld("arena"))
    yaw = float(rng.uniform(-0.3, 0.3))
    carrier = world.add_carrier(models[true_model], Pose2D(0.0, 0.0, 0.0), box_yaw=yaw)
    start = Pose2D(-1.2, float(rng.uniform(-0.1, 0.1)), 0.0)
    session = stack.enter_context(make_robot(None, world=world, start=start, seed=seed, sensing=sensing))
    carrier.mover = make_mover(mover, carrier, observer_pose=world.truth.robot_pose, seed=seed)
    session.carrier = carrier
    return session


def _watch(agent: IdentificationAgent, record: Path | None, progress):
    """Hook the console's decision lines and the recording's live view onto the agent; the recorder."""
    if progress is not None:
        seen = [0]
        t0 = [None]

        def on_step(a, frame):
            t0[0] = frame.t if t0[0] is None else t0[0]
            if len(a.decisions) > seen[0]:
                seen[0] = len(a.decisions)
                progress(f"decision {seen[0]} at t={frame.t - t0[0]:.1f} s: P = {np.round(a.P, 3).tolist()}")

        agent.on_step = on_step
    if record is None:
        return None
    from lab.viz.live import LiveView
    from lab.viz.recorder import Recorder

    recorder = Recorder(record)  # the live view drawn at every step: one frame per step
    LiveView.for_identification(agent, rate_hz=None, recorder=recorder, widget=False)
    return recorder


def _record_truth(agent: IdentificationAgent, session: RobotSession) -> list:
    """In the simulator, (G_WC, G_WO) true at each frame's capture (scoring and figures only): the camera
    when the frame's image was exposed (a camera latency before the frame's stamp; the robot takes its
    odometry and head back to that instant, so its estimates are relative to that camera), the box as
    the image shows it."""
    truth: list = []
    if session.kind is not RobotKind.SIM:
        return truth
    world, carrier, agent_step = session.world, session.carrier, agent.step

    def step_with_truth():
        truth.append((world.truth.G_WC_exposed(), carrier.G_WO.copy()))
        return agent_step()

    agent.step = step_with_truth
    return truth


def final_pose_estimate(agent: IdentificationAgent, identified) -> dict | None:
    """The final pose the robot states without a truth: the identified model's estimate (else the most
    probable model's) of the object in the last frame's camera C, ``position_m`` and ``euler_zyx_deg``,
    with its standard deviations, the larger axes of the estimate's covariance (``position_std_m``,
    ``orientation_std_deg``); None when that model has no estimate. The estimate is the model's filter
    fed only the consistent part of each frame (:mod:`lab.identification.final_pose`)."""
    k = int(identified) if identified is not None else int(np.argmax(agent.P))
    est = agent.final_pose.estimate(k)
    if est is None:
        return None
    pos, rot = larger_axes_std(est.Sigma_rv)
    return {
        "model": k,
        "frame": "camera",
        "position_m": [round(float(v), 5) for v in est.mu[:3]],
        "euler_zyx_deg": [round(math.degrees(float(v)), 3) for v in est.mu[3:]],
        "position_std_m": round(pos, 5),
        "orientation_std_deg": round(rot, 3),
    }


def _final_pose_error(agent: IdentificationAgent, session: RobotSession, truth: list, true_model: int):
    """The true model's stated estimate (:func:`final_pose_estimate`'s) against the truth behind the last
    frame (None without a truth)."""
    est = agent.final_pose.estimate(true_model)
    if session.kind is RobotKind.SIM:
        last = truth[-1] if truth else None
    else:
        t = session.rehearsal.truth() if session.rehearsal is not None else None
        last = (t.G_WC, t.G_WO) if t is not None and t.G_WO is not None else None
    if est is None or last is None:
        return {"translation_m": None, "rotation_deg": None}
    G_WC_true, G_WO_true = last
    return pose_error(est.G_CO, se3_inv(G_WC_true) @ G_WO_true)


def _robot_fields(session: RobotSession) -> dict:
    """What only one kind of robot reports: the simulator's collisions, the hardware's watchdog."""
    if session.kind is RobotKind.SIM:
        return {"collisions": session.world.truth.collisions}
    return {
        "robot": session.name,
        "rehearsal": session.kind is RobotKind.REHEARSAL,
        "watchdog_stops": session.robot.watchdog_stops,
    }


def _episode_json(agent, session, true_model, identified, planner, seed, mover, t0) -> dict:
    """The contract's fields of the ``lab identify`` JSON (history and decisions from ``t0``)."""
    has_truth = session.kind is not RobotKind.HARDWARE
    return {
        "true_model": true_model if has_truth else None,
        "identified_model": identified,
        "pose_estimate": final_pose_estimate(agent, identified),  # what the robot states, no truth
        "success": (identified == true_model) if has_truth else None,
        "actions": agent.n_actions,
        "final_posterior": [float(p) for p in (agent.P / agent.P.sum())],
        "history": [
            {
                "t": s.t - t0,
                "posterior": [float(p) for p in s.posterior],
                "ptu_state": s.head_mode,
                "base_state": s.base_mode,
                "action": s.action,
            }
            for s in agent.steps
        ],
        "planner": planner,
        "seed": seed,
        "sensing": session.sensing,
        "sensing_applies_to": session.sensing_applies_to,
        "mover": mover if has_truth else None,
        "keep_direction": agent.config.keep_direction,
        "decisions": [d.to_json(t0) for d in agent.decisions],
        "filter_reseats": agent.n_reseats,
        "ring_blocked": agent.n_blocked,
        "track_lost": agent.n_lost,
    }


def _speed_fields(sim_time: float, wall: float, cpu: float, loop: dict) -> dict:
    """Real-time factors: of the whole process, and of the loop alone per wall and per CPU second."""
    return {
        "real_time_factor": sim_time / wall if wall > 0 else None,
        "cpu_time_s": cpu,
        "real_time_factor_cpu": sim_time / cpu if cpu > 0 else None,  # on one free core
        "loop_sim_time_s": loop["sim"],
        "loop_wall_time_s": loop["wall"],
        "loop_cpu_time_s": loop["cpu"],
        "real_time_factor_wall": loop["sim"] / loop["wall"] if loop["wall"] > 0 else None,
        "real_time_factor_loop_cpu": loop["sim"] / loop["cpu"] if loop["cpu"] > 0 else None,
    }


def _viewer(agent, session, view3d):
    """The recorded 3D view of the episode (None without ``view3d``): the world's bodies are for
    display only; the agent never sees them."""
    if view3d is None:
        return None
    from lab.viz.view3d import View3D

    return View3D.for_identification(agent, view3d, session.world)


def _finish_recording(recorder, result: dict, progress, viewer=None) -> None:
    """Close the animation and the 3D view; their paths go into the JSON's ``recording`` and ``view3d``."""
    if viewer is not None:
        result["view3d"] = str(viewer.save())
    if recorder is None:
        return
    p = recorder.close()
    result["recording"] = None if p is None else str(p)
    if progress is not None:
        progress(f"recording: {p}")
