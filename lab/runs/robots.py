"""One switch from simulator to robot: :func:`make_robot` gives the :class:`~lab.robot.Robot` an experiment
runs on, from a robot config or none.

============================  =========================================  ==================================
``config``                    robot                                      truth (scoring only)
============================  =========================================  ==================================
None                          :class:`~lab.sim.SimRobot` in ``world``    ``world.truth``
TOML, ``[camera] source =     :class:`~lab.hardware.HardwareRobot` on    the rendered world behind each
"sim"`` (a rehearsal)         the device emulators, camera rendered by   frame (:mod:`lab.runs.rehearsal`)
                              the simulator
TOML, any other source        :class:`~lab.hardware.HardwareRobot` on    none
                              the real devices
============================  =========================================  ==================================

The agents see only the :class:`~lab.robot.Robot`; the session's ``world`` and ``carrier`` are for the
run to set up and score the scene.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from enum import Enum
from pathlib import Path

from lab.errors import ConfigError
from lab.geometry import Pose2D, wrap_angle
from lab.hardware.config import HardwareConfig, load_config
from lab.mounts import CalibratedRobot, HeadMounts, load_mounts
from lab.navigation.level import NotLevelled, level_camera
from lab.robot import Robot, RobotWrapper, StereoFrame

__all__ = [
    "PlacedRobot",
    "RobotKind",
    "RobotSession",
    "levelled",
    "load_robot_config",
    "make_robot",
    "mounts_stated",
    "robot_kind",
]


class RobotKind(Enum):
    """Which implementation of the Robot interface a run drives."""

    SIM = "sim"  # the simulator
    REHEARSAL = "rehearsal"  # the hardware adapter on the device emulators, the camera rendered
    HARDWARE = "hardware"  # the real robot


@dataclass
class RobotSession:
    """What :func:`make_robot` yields.

    Attributes
    ----------
    kind : RobotKind
    robot : Robot
        The only thing an agent is given.
    world : lab.sim.SimWorld or None
        The simulated world (the simulator's, or the one a rehearsal renders); None on the real robot.
    carrier : lab.sim.Carrier or None
        A rehearsal's box carrier (in the simulator the run adds its own).
    config : HardwareConfig or None
        The robot config (with a rehearsal's emulator ports).
    rehearsal : lab.runs.rehearsal.Rehearsal or None
        A rehearsal's emulators and truth.
    """

    kind: RobotKind
    robot: Robot
    world: object = None
    carrier: object = None
    config: HardwareConfig | None = None
    rehearsal: object = None

    @property
    def _rendered(self):
        """A rehearsal's rendered camera (None: the simulator, the real robot, an emulated pair)."""
        return None if self.rehearsal is None else self.rehearsal.source

    @property
    def sensing(self) -> str:
        """The ``sensing`` field of a result: the profile of the simulator or of a rehearsal's rendered
        camera, else the robot kind's name (a real robot's errors are its devices')."""
        if self.kind is RobotKind.SIM:
            return self.robot.sensing.name
        return self._rendered.sensing.name if self._rendered is not None else self.kind.value

    @property
    def sensing_applies_to(self) -> list[str]:
        """The ``sensing_applies_to`` field: which of the profile's sections the run's sensors follow
        (all three in the simulator; a rehearsal's camera only, its odometry and head are the
        emulators'; none on the real robot)."""
        if self.kind is RobotKind.SIM:
            return ["camera", "odometry", "pan_tilt"]
        return ["camera"] if self._rendered is not None else []

    @property
    def name(self) -> str:
        """The robot config's path or name; ``"sim"`` in the simulator."""
        if self.config is None:
            return "sim"
        return str(self.config.path) if self.config.path is not None else self.config.robot.name


def _load(config: str | Path | HardwareConfig) -> HardwareConfig:
    return config if isinstance(config, HardwareConfig) else load_config(config)


def load_robot_config(config: str | Path | HardwareConfig | None) -> HardwareConfig | None:
    """The robot config read and checked (:func:`lab.hardware.load_config`; None: the simulator)."""
    return None if config is None else _load(config)


def robot_kind(config: str | Path | HardwareConfig | None) -> RobotKind:
    """The kind of robot ``config`` describes (None: the simulator)."""
    if config is None:
        return RobotKind.SIM
    return RobotKind.REHEARSAL if _load(config).camera.source == "sim" else RobotKind.HARDWARE


@contextlib.contextmanager
def make_robot(
    config: str | Path | HardwareConfig | None = None,
    *,
    world=None,
    start: Pose2D | None = None,
    seed: int = 0,
    true_model: int = 1,
    mover: str = "static",
    sensing="ideal",
    scene=None,
    emulator_setup: Callable | None = None,
    mounts=None,
    config_mounts: bool = True,
) -> Iterator[RobotSession]:
    """The robot a run drives, closed (devices stopped, emulators ended) on exit.

    Parameters
    ----------
    config : path or HardwareConfig, optional
        A robot config (``hardware/*.toml``); None: the simulator.
    world : lab.sim.SimWorld
        The simulator's world (required without ``config``; the run owns it).
    start : Pose2D, optional
        The simulated robot's start in the world (default: the scene's ``[robot] start``).
    seed : int
        Seeds the simulated odometry noise, or a rehearsal's box yaw and mover.
    true_model, mover :
        A rehearsal's box (index into the box models) and what moves its carrier.
    sensing : str or mapping
        The sensing profile (:func:`lab.sim.sensing.sensing_profile`) of the simulated robot, or of a
        rehearsal's rendered camera (its camera section only: the emulators have their own odometry and
        head); the real devices have their own errors.
    scene, emulator_setup :
        A rehearsal's scene instead of its config's ``[sim]`` world and carrier (the search's room), and
        a hook that injects faults into its emulators before the robot connects
        (:func:`lab.runs.rehearsal.rehearsal`).
    mounts : HeadMounts, optional
        A calibration of the camera's mounts (:mod:`lab.mounts`): the robot is a
        :class:`~lab.mounts.CalibratedRobot` whose camera frame includes it. Without it, a robot config's
        ``[camera] mounts`` file is used when it exists (``config_mounts``; False: the nominal
        kinematics, as ``lab hardware calibrate`` needs them).

    Raises
    ------
    ConfigError
        No world for the simulator, or a bad robot config (the config loader's message).
    """
    if config is None:
        if world is None:
            raise ConfigError("make_robot needs a world for the simulator (or a robot config)")
        from lab.sim import SimRobot

        robot = SimRobot(world, start=start, seed=seed, sensing=sensing)
        yield RobotSession(RobotKind.SIM, _calibrated(robot, mounts), world)
        return
    cfg = _load(config)
    if mounts is None and config_mounts and cfg.camera.mounts and Path(cfg.camera.mounts).exists():
        mounts = load_mounts(cfg.camera.mounts)  # a corrupt file stops here, naming it
    if cfg.camera.source == "sim":
        from lab.runs.rehearsal import rehearsal

        kw = {"scene": scene, "emulator_setup": emulator_setup, "sensing": sensing}
        with rehearsal(cfg, true_model=true_model, mover=mover, seed=seed, **kw) as r:
            robot = _calibrated(r.robot, mounts)
            yield RobotSession(RobotKind.REHEARSAL, robot, r.world, r.carrier, r.config, r)
        return
    from lab.hardware.robot import HardwareRobot

    with HardwareRobot(cfg) as robot:
        yield RobotSession(RobotKind.HARDWARE, _calibrated(robot, mounts), config=cfg)


def _calibrated(robot: Robot, mounts: HeadMounts | None) -> Robot:
    """``robot`` seeing through the calibrated camera frame (None: as it is)."""
    return robot if mounts is None else CalibratedRobot(robot, mounts)


def mounts_stated(sensing) -> bool:
    """Whether the simulator's sensing profile (a name, a file or a section:
    :func:`lab.sim.sensing.sensing_profile`) tells the robot its camera's mounts are off by some error
    (``[sensing.room] camera_mount_deg`` or ``head_mount_deg`` above 0), which the floor's levelling then
    estimates. A profile that states them exact (``ideal``, ``sensors``, issue 52's survey-and-start
    condition) has nothing for it to find: its own 0.2-0.3 deg would be the only error left
    (docs/tuning/camera-level.md)."""
    from lab.sim.sensing import sensing_profile  # lab.sim only where a simulated robot runs

    room = sensing_profile(sensing).room
    return room.camera_mount_deg > 0 or room.head_mount_deg > 0


def levelled(robot: Robot) -> tuple[Robot, dict | None]:
    """The session's robot with its camera levelled against the floor before a search
    (:func:`~lab.navigation.level.level_camera`: a
    :class:`~lab.mounts.CalibratedRobot` with the mounts found) and what was found, for the JSON's
    ``camera_level``; the robot as it is (and None) when it already has a calibration (a robot config's
    ``[camera] mounts``, or ``--mounts``: the operator's, kept), and (robot, the reason) when too few views
    showed the floor."""
    if isinstance(robot, CalibratedRobot):
        return robot, None
    robot.enable()
    t0 = robot.now()
    try:
        lv = level_camera(robot)
    except NotLevelled as e:
        print(f"lab: camera not levelled: {e}", file=sys.stderr)
        return robot, {"levelled": False, "reason": str(e), "sim_time_s": round(robot.now() - t0, 3)}
    m = lv.mounts
    info = {
        "levelled": True,
        "views": lv.views,
        "views_left_out": lv.dropped,
        "floor_tilt_before_deg": round(lv.rms_before_deg, 4),
        "floor_tilt_after_deg": round(lv.rms_deg, 4),
        "head_rpy_deg": [round(math.degrees(a), 4) for a in m.head_rpy],
        "camera_rpy_deg": [round(math.degrees(a), 4) for a in m.camera_rpy],
        "tilt_zero_deg": round(math.degrees(m.tilt_zero), 4),
        "sim_time_s": round(robot.now() - t0, 3),
    }
    head, cam = info["head_rpy_deg"], info["camera_rpy_deg"]
    print(
        f"lab: camera levelled on the floor ({lv.views} views; the floor's tilt {lv.rms_before_deg:.2f} -> "
        f"{lv.rms_deg:.2f} deg): head roll/pitch {head[0]:+.2f}/{head[1]:+.2f}, tilt zero "
        f"{info['tilt_zero_deg']:+.2f}, camera roll/yaw {cam[0]:+.2f}/{cam[2]:+.2f} deg",
        file=sys.stderr,
    )
    return CalibratedRobot(robot, m), info


class PlacedRobot(RobotWrapper):
    """A robot whose odometry (and each frame's) is in the room's frame W: the base started at ``start``.

    A real robot's wheel odometry starts at its own origin, (0, 0, 0) where it was switched on; the
    search's map, costmap and scoring are in the room's frame W. Standing the robot at a known pose
    ``start`` in W (the scene's ``[robot] start``) makes ``odometry() = start (+) odom``, the
    composition ``G_W,odom = G_W,start G_start,odom``; everything else is passed on.

    Parameters
    ----------
    base : Robot
    start : Pose2D
        Where the base stands in W while its own odometry reads (0, 0, 0).
    """

    def __init__(self, base: Robot, start: Pose2D):
        super().__init__(base)
        self.start = start

    def _in_room(self, p: Pose2D) -> Pose2D:
        s = self.start
        c, sn = math.cos(s.theta), math.sin(s.theta)
        return Pose2D(s.x + c * p.x - sn * p.y, s.y + sn * p.x + c * p.y, wrap_angle(s.theta + p.theta))

    def odometry(self) -> Pose2D:
        return self._in_room(self.base.odometry())

    def wheel_odometry(self) -> Pose2D:
        return self._in_room(self.base.wheel_odometry())

    def capture_stereo(self, after: float | None = None) -> StereoFrame:
        frame = self.base.capture_stereo(after)
        wheels = None if frame.wheel_odom is None else self._in_room(frame.wheel_odom)
        return dataclasses.replace(frame, odom=self._in_room(frame.odom), wheel_odom=wheels)
