"""A trial's robot session, where it starts in the room, and where its truth comes from.

What a search trial (:mod:`lab.runs.search`) and a survey of the room (:mod:`lab.runs.survey`) set up
alike: the simulator's world or a robot (:func:`lab.runs.robots.make_robot`), the start of a robot's
odometry in the room, whether its camera is levelled first, and the truth behind it (scoring only).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from lab.errors import ConfigError
from lab.runs.moving import start_mover
from lab.runs.robots import RobotKind, make_robot, mounts_stated
from lab.runs.room import robot_start
from lab.scene import Scene

__all__ = ["TruthOf", "levels_by_default", "start_of", "trial_session"]


@dataclass(frozen=True)
class TruthOf:
    """Where a trial's truth comes from (scoring only; None where there is none: the real robot)."""

    G_WO: Callable  # () -> the object in W (4 x 4) or None
    G_WC: Callable  # () -> the camera in W at the last frame or None
    robot_pose: Callable  # () -> Pose2D of the base in W or None
    collisions: Callable  # () -> int
    mover: object = None  # a moving object's carrier: G_WO_at(t), the object in W at robot time t


def trial_session(stack, kind, robot_config, scene, object, seed, opts, G_WO):
    """The trial's robot session (entered on ``stack``) and where its truth comes from; ``opts`` is a
    :class:`~lab.runs.search.TrialOptions` (its sensing, supersample, emulator setup, mounts, moving)."""
    sensing, supersample, emulator_setup = opts.sensing, opts.supersample, opts.emulator_setup
    mounts = opts.mounts  # read by run_trial
    if kind is RobotKind.SIM:
        from lab.sim import RenderSettings, SimWorld

        w = stack.enter_context(SimWorld(scene, RenderSettings(supersample=supersample)))
        run = stack.enter_context(make_robot(world=w, seed=seed, sensing=sensing, mounts=mounts))
        t = w.truth
        mover = None if opts.moving is None else start_mover(w, object, opts.moving, seed)
        return run, TruthOf(lambda: t.G_W(object), t.G_WC, t.robot_pose, lambda: int(t.collisions), mover)
    robot = make_robot(
        robot_config, seed=seed, scene=scene, emulator_setup=emulator_setup, sensing=sensing, mounts=mounts
    )
    run = stack.enter_context(robot)
    bumps = lambda: int(run.robot.bumps)  # noqa: E731 - the bumpers' count: a robot's own collisions
    if kind is RobotKind.REHEARSAL:
        r = run.rehearsal

        def G_WC():
            last = r.truth()
            return None if last is None else last.G_WC

        return run, TruthOf(lambda: run.world.truth.G_W(object), G_WC, r.source.base_pose_W, bumps)
    none = lambda: None  # noqa: E731
    return run, TruthOf(lambda: G_WO, none, none, bumps)


def start_of(kind: RobotKind, hw, scene: Scene, room, start):
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


def levels_by_default(kind: RobotKind, sensing) -> bool:
    """Whether a search levels its camera without ``--level/--no-level``: a simulated robot whose sensing
    profile states its mounts uncertain (:func:`lab.runs.robots.mounts_stated`)."""
    return kind is RobotKind.SIM and mounts_stated(sensing)
