"""Rehearse without the robot: the adapter on the device emulators, the camera rendered by the simulator.

A rehearsal is the classroom robot with every device replaced and nothing else: the PTU-D46 and Create 2
emulators on ptys (so :class:`~lab.hardware.robot.HardwareRobot` runs its whole path: pyserial I/O, the
servo thread and watchdog, odometry from the encoders, rectification), and a camera,
:class:`SimRenderedStereoSource`, that renders the simulator's world from the emulators' *true* state:
the Create emulator's true pose ``(x, y, theta)`` and the PTU emulator's true axis positions. The agent
sees only what :class:`~lab.hardware.robot.HardwareRobot` gives it (odometry from the encoders, the head
angles the PTU reports, rectified images): the truth only places the camera in the rendered world.

Select it with ``[camera] source = "sim"`` and a ``[sim]`` section (``hardware/rehearsal.toml``); then::

    with rehearsal("hardware/rehearsal.toml", true_model=2) as r:    # starts the emulators
        agent = IdentificationAgent(r.robot)                          # r.robot is a HardwareRobot
        agent.run()

``lab identify --robot hardware/rehearsal.toml`` does the same. With another camera source (e.g.
``hardware/emulated.toml``, a synthetic pair) :func:`rehearsal` just starts the emulators and returns the
robot on them (``r.world`` is then None).

**Time.** The emulators run on the wall clock (``time.monotonic``, the robot's ``now()``); the simulator's
world has its own clock ``world.t``. The rendered scene is kept on the wall clock: the scene time is
``t_scene = t - t_start`` with ``t_start`` the monotonic time at which the source was made, and before each
render the world is stepped from ``world.t`` to ``t_scene`` in sub-steps of at most ``dt_world`` (0.02 s,
the simulator's physics step). So the carrier (its mover) moves at its simulator speed *per wall-clock
second*, however long the agent computes between frames, exactly as a person pushing the box would; frames
only sample it. Consequences worth knowing:

* a frame shows one instant ``t_snap`` (the monotonic time at which the emulators' state was read, just
  before rendering) and is stamped with it; the render itself takes tens of milliseconds, a latency as a
  real camera's. :meth:`HardwareRobot.capture_stereo` interpolates the head and odometry to the stamp;
* the agent's loop runs slower than in the simulator (``robot.step(dt)`` waits ``dt`` of wall time *after*
  the computation; in the simulator the computation takes no simulated time), so the world moves further
  per control step, and when a step's computation exceeds ``[robot] cmd_timeout_s`` the watchdog stops the
  base between two commands (counted in ``robot.watchdog_stops``);
* between two frames the evasive mover sees the observing robot where it was at the later frame (the
  world is only stepped when a frame is rendered).

**Sensing.** The rendered camera follows a sensing profile's camera section (``sensing``, as the
simulator's :class:`~lab.sim.SimRobot`; ``ideal`` by default, ``realistic`` under ``lab identify`` and
``lab search``): per episode, seeded by the run's seed, the raw cameras are rendered with perturbed focal
lengths and baseline and a tilted light while the adapter keeps rectifying with the nominal calibration,
and each raw pair gets the exposure, vertical residual, blur, left/right mismatch and pixel noise of
:func:`lab.sim.sensing.corrupt_stereo` (before rectification, as on a real sensor). The profile's
odometry and pan-tilt sections do not apply: the base's encoders and the head's axes are the emulators'
(their own step quantisation and timing; no wheel-radius, track or slip errors, no backlash or zero
offset).

Ground truth (:meth:`Rehearsal.truth`) is for tests and scoring only, as ``SimWorld.truth`` is.
"""

from __future__ import annotations

import contextlib
import math
import shutil
import tempfile
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lab.errors import ConfigError
from lab.geometry import Pose2D, se3, se3_inv
from lab.hardware.camera import RawStereo, StereoSource, load_camera_calibration, wait_until_after
from lab.hardware.config import HardwareConfig, load_config
from lab.hardware.emulators import Create2Emulator, EmulatorSet, PTUEmulator, start_emulators
from lab.mounts import mounted_G_RC
from lab.robot import StereoCamera
from lab.vision.rectify import StereoCalibration

__all__ = ["Rehearsal", "RehearsalTruth", "SimRenderedStereoSource", "rehearsal"]

ARCSEC = math.pi / (180.0 * 3600.0)  # [rad] per arc-second


@dataclass(frozen=True)
class RehearsalTruth:
    """The true state behind the last rendered frame (tests and scoring only).

    Attributes
    ----------
    t : float [s, monotonic]
        The frame's stamp.
    base_W : Pose2D
        The base's true pose in the world W.
    pan, tilt : float [rad]
        The head's true angles.
    G_WC : ndarray, shape (4, 4)
        The rectified left camera frame C in W.
    G_WO : ndarray, shape (4, 4) or None
        The carried box's frame O in W (None in a world without a carrier).
    """

    t: float
    base_W: Pose2D
    pan: float
    tilt: float
    G_WC: np.ndarray
    G_WO: np.ndarray | None


def _pose_from(v) -> Pose2D:
    """``[x_m, y_m, heading_deg]`` (the config's form) -> Pose2D."""
    return Pose2D(float(v[0]), float(v[1]), math.radians(float(v[2])))


class SimRenderedStereoSource(StereoSource):
    """A stereo camera that renders a :class:`~lab.sim.SimWorld` from the emulators' true state.

    The raw pair is rendered as the calibration describes the two *unrectified* pinhole cameras
    (``K1``, ``K2``, and the right camera at ``X_right = R X_left + T``), so the adapter's rectification
    (``R1``, ``P1``, ...) turns it into the rectified pair of ``calib.camera_model(...)``, the camera the
    agent is given. The calibration must be distortion-free (a renderer draws pinhole images).

    Parameters
    ----------
    world : SimWorld
        The scene to render; stepped on the wall clock (see the module docstring).
    create : Create2Emulator
        Its true pose ``(x, y, theta)`` is the base's pose relative to ``robot_start``.
    ptu : PTUEmulator
        Its true axis positions [steps], turned into our angles with the unit's resolution and the
        configuration's ``pan_sign``/``tilt_sign`` and zero offsets (``angle = sign (steps res - zero)``).
    config : HardwareConfig
        Camera mounting (``mount_R``, ``camera_offset_P``), PTU signs and offsets, ``[sim]`` start pose.
    calibration : StereoCalibration
    clock : callable
        The robot's clock (monotonic).
    dt_world : float [s]
        Largest sub-step of the world (movers) when it is brought up to the wall clock.
    robot_start : Pose2D, optional
        Where the base stands in the world when the emulator's pose is (0, 0, 0) (default: the config's
        ``[sim] robot_start``; a search rehearsal gives its scene's start).
    sensing : SensingProfile, str or mapping
        The profile whose camera section the rendered pairs follow (:func:`lab.sim.sensing.sensing_profile`;
        its odometry and pan-tilt sections are the emulators' business and ignored; see the module
        docstring). Default ``ideal``: exact renders.
    seed : int
        Seeds the profile's per-episode draws and the capture noise (the same seed, the same images).
    """

    def __init__(
        self,
        world,
        create: Create2Emulator,
        ptu: PTUEmulator,
        config: HardwareConfig,
        calibration: StereoCalibration,
        *,
        clock: Callable[[], float] = time.monotonic,
        dt_world: float = 0.02,
        robot_start: Pose2D | None = None,
        sensing="ideal",
        seed: int = 0,
    ):
        if np.any(np.asarray(calibration.D1) != 0) or np.any(np.asarray(calibration.D2) != 0):
            raise ConfigError(
                '[camera] source = "sim" renders pinhole images: its calibration must have zero distortion '
                "(D1, D2), e.g. hardware/calibration/example_stereo_320x240.yml"
            )
        self.world, self.create, self.ptu = world, create, ptu
        self.config, self.calibration = config, calibration
        self.clock = clock
        self.dt_world = float(dt_world)
        c = config.camera
        self.image_size = tuple(calibration.image_size)
        #: the rectified camera, as the adapter builds it: its frame C is the robot's camera frame
        self.camera: StereoCamera = calibration.camera_model(c.mount_R, c.camera_offset_P)
        from lab.sim.episode import EpisodeSensing  # a rendered camera needs the simulator
        from lab.sim.sensing import sensing_profile

        self.sensing = sensing_profile(sensing)  # SensingProfile
        self._episode = None  # the camera errors' draws and capture noise (None: exact renders)
        focal, baseline = 1.0, 1.0
        if not self.sensing.camera.is_none:
            self._episode = EpisodeSensing(self.sensing, seed, self.camera, world.settings.light_direction)
            drawn = self._episode.camera.render_camera  # the rectified camera with this episode's errors
            focal = (drawn.fx / self.camera.fx, drawn.fy / self.camera.fy)
            baseline = drawn.baseline / self.camera.baseline
        # the raw cameras as they are (their focal lengths off by the draw's), not as calibrated
        self._raw = [self._pinhole(calibration.K1, focal), self._pinhole(calibration.K2, focal)]
        # rectified left C -> raw left L: x_C = R1 x_L, so G_CL = se3(R1); raw right: x_R = R x_L + T
        self._G_CL = se3(np.asarray(calibration.R1))
        T = baseline * np.asarray(calibration.T, float).reshape(3)  # the true baseline, off by the draw's
        self._G_LR = se3_inv(se3(np.asarray(calibration.R), T))
        self.robot_start = _pose_from(config.sim.robot_start) if robot_start is None else robot_start
        p = config.ptu
        self._sign = {"P": p.pan_sign, "T": p.tilt_sign}
        self._zero = {"P": math.radians(p.pan_zero_offset_deg), "T": math.radians(p.tilt_zero_offset_deg)}
        self.t_start = clock()
        self.last_truth: RehearsalTruth | None = None
        self.frames = 0

    def _pinhole(self, K, focal=1.0) -> StereoCamera:
        """The raw camera of ``K``, its focal lengths times ``focal`` (a factor, or one per axis)."""
        w, h = self.image_size
        K = np.asarray(K)
        sx, sy = np.broadcast_to(np.asarray(focal, float), (2,))
        fx, fy = float(K[0, 0]) * sx, float(K[1, 1]) * sy
        return StereoCamera(w, h, float(fx), float(fy), float(K[0, 2]), float(K[1, 2]), 1.0)

    # --- the emulators' truth ----------------------------------------------------------------------
    def base_pose_W(self) -> Pose2D:
        """The base's true pose in the world: ``robot_start`` composed with the emulator's true pose."""
        x, y, th = self.create.true_pose()
        s = self.robot_start
        c, sn = math.cos(s.theta), math.sin(s.theta)
        return Pose2D(
            s.x + c * x - sn * y,
            s.y + sn * x + c * y,
            math.atan2(math.sin(s.theta + th), math.cos(s.theta + th)),
        )

    def _G_RC_true(self, pan: float, tilt: float) -> np.ndarray:
        """The camera in R as rendered: the kinematics with ``[sim]``'s mount errors, when it has any."""
        head, cam = self.config.sim.head_mount_deg, self.config.sim.camera_mount_deg
        if not any(head) and not any(cam):
            return self.camera.G_RC(pan, tilt)
        c = self.camera
        return mounted_G_RC(pan, tilt, c.mount_R, c.camera_offset_P, np.radians(head), np.radians(cam))

    def pan_tilt_true(self) -> tuple[float, float]:
        """The head's true (pan, tilt) [rad] from the PTU emulator's axis positions."""
        pos, res = self.ptu.axis_positions()
        pan, tilt = (self._sign[a] * (pos[a] * res[a] * ARCSEC - self._zero[a]) for a in "PT")
        return pan, tilt

    # --- StereoSource ------------------------------------------------------------------------------
    def advance_world(self, t: float) -> None:
        """Step the world (its movers) up to the scene time of monotonic time ``t``."""
        t_scene = t - self.t_start
        gap = t_scene - self.world.t
        if gap <= 0:
            return
        n = max(1, math.ceil(gap / self.dt_world - 1e-9))
        for _ in range(n):
            self.world.step(gap / n)

    def read(self, after: float | None = None, timeout: float = 2.0) -> RawStereo:
        """Render the pair the cameras see now (or first after ``after``), stamped with that instant."""
        wait_until_after(after, timeout, self.clock)
        t = self.clock()
        base_W = self.base_pose_W()
        pan, tilt = self.pan_tilt_true()
        self.advance_world(t)
        G_WC = base_W.G() @ self._G_RC_true(pan, tilt)
        G_WL = G_WC @ self._G_CL
        light = None if self._episode is None else self._episode.camera.light_direction
        left, _, _ = self.world.render(G_WL, self._raw[0], light_direction=light)
        right, _, _ = self.world.render(G_WL @ self._G_LR, self._raw[1], light_direction=light)
        if self._episode is not None:  # the sensor's errors on the raw pair, before the rectification
            left, right = self._episode.corrupt(left, right)
        carrier = next(iter(self.world.carriers.values()), None)
        self.last_truth = RehearsalTruth(
            t, base_W, pan, tilt, G_WC, None if carrier is None else carrier.G_WO.copy()
        )
        self.frames += 1
        return RawStereo(t, left, right)

    def close(self) -> None:
        pass  # the world belongs to the rehearsal that made it


@dataclass
class Rehearsal:
    """What :func:`rehearsal` yields: the robot and, for tests and scoring, what is behind it.

    Attributes
    ----------
    robot : HardwareRobot
        On the emulators; the only thing an agent should be given.
    emulators : EmulatorSet
        Fault switches and the devices' truth (``emulators.create.x``, ``emulators.ptu.pos``).
    config : HardwareConfig
        The configuration with the emulators' ports.
    world : SimWorld or None
        The rendered world (``source = "sim"`` only).
    carrier : Carrier or None
        The box's carrier in it.
    true_model : int or None
        Index of the box on the carrier.
    source : SimRenderedStereoSource or None
    """

    robot: object
    emulators: EmulatorSet
    config: HardwareConfig
    world: object = None
    carrier: object = None
    true_model: int | None = None
    source: SimRenderedStereoSource | None = None

    def truth(self) -> RehearsalTruth | None:
        """The true state behind the last frame (None before the first frame or without a sim camera)."""
        return None if self.source is None else self.source.last_truth


def _scene_world(scene, emu: EmulatorSet, cfg: HardwareConfig, calib: StereoCalibration, sensing, seed: int):
    """The world of ``scene`` and the camera that renders it, the robot standing as the scene's robot
    (its start; its mast height as the camera's ``mount_R`` z): the world, the source and the config."""
    import dataclasses

    from lab.scene import Scene, load_scene
    from lab.sim import SimWorld
    from lab.sim.world import RenderSettings

    sc = scene if isinstance(scene, Scene) else load_scene(scene)
    mx, my, _ = cfg.camera.mount_R
    camera = dataclasses.replace(cfg.camera, mount_R=(mx, my, float(sc.robot_mast_height)))
    cfg = dataclasses.replace(cfg, camera=camera)
    world = SimWorld(sc, RenderSettings(supersample=cfg.sim.supersample))
    try:
        source = SimRenderedStereoSource(
            world,
            emu.create,
            emu.ptu,
            cfg,
            calib,
            robot_start=_pose_from(sc.robot_start),
            sensing=sensing,
            seed=seed,
        )
    except BaseException:
        world.close()
        raise
    return world, source, cfg


@contextlib.contextmanager
def rehearsal(
    config: str | Path | HardwareConfig,
    *,
    true_model: int = 1,
    mover: str = "static",
    seed: int = 0,
    box_yaw: float | None = None,
    link_dir: str | Path | None = None,
    on_event=None,
    scene=None,
    emulator_setup: Callable[[EmulatorSet], None] | None = None,
    sensing="ideal",
) -> Iterator[Rehearsal]:
    """Start the emulators (and, for ``[camera] source = "sim"``, the rendered world) and a
    :class:`~lab.hardware.robot.HardwareRobot` on them; stop everything on exit.

    Parameters
    ----------
    config : path or HardwareConfig
        Its ports are replaced by the emulators'.
    true_model : int
        The box on the carrier (index into ``lab.sim.load_box_models()``), sim camera only.
    mover : str
        What moves the carrier: static, scripted, random, evasive (the paper's operator) or teleop.
    seed : int
        Seeds the box's yaw on the carrier (uniform in +-0.3 rad, as ``lab identify``), the mover and
        the rendered camera's errors.
    box_yaw : float [rad], optional
        The box's yaw on the carrier instead of the seeded one.
    link_dir : path, optional
        Where the emulators' port symlinks go (default: a fresh temporary folder, removed on exit, so a
        running ``lab hardware emulate`` is never disturbed).
    scene : str or Scene, optional
        Render this scene instead of the config's ``[sim] world`` with its carrier (the search's room with
        its object placed: :func:`lab.runs.search.run_search`). The robot then stands as the scene's
        robot: at the scene's ``[robot] start`` when the Create emulator's pose is (0, 0, 0), its camera's
        pan-tilt axes at the scene's mast height (``mount_R`` z replaced). No carrier, no mover.
    emulator_setup : callable, optional
        ``emulator_setup(emulators)`` once the emulators run, before the robot connects: inject faults
        (``emulators.ptu.garbage_every = 3``, ``emulators.create.known_packets = {...}``).
    sensing : SensingProfile, str or mapping
        The profile whose camera section the rendered camera follows (``[camera] source = "sim"`` only;
        :class:`SimRenderedStereoSource`). Default ``ideal``: exact renders.
    """
    from lab.hardware.robot import HardwareRobot

    cfg = config if isinstance(config, HardwareConfig) else load_config(config)
    c = cfg.camera
    calib = load_camera_calibration(cfg)  # checked against the [camera] section
    tmp = None
    if link_dir is None:
        tmp = link_dir = tempfile.mkdtemp(prefix="lab-rehearsal-")
    world = carrier = source = robot = None
    emu = start_emulators(link_dir)
    try:
        if emulator_setup is not None:
            emulator_setup(emu)
        cfg = cfg.with_ports(base=emu.base_port, ptu=emu.ptu_port)
        if c.source == "sim" and scene is not None:
            world, source, cfg = _scene_world(scene, emu, cfg, calib, sensing, seed)
        elif c.source == "sim":
            from lab.sim import SimWorld, box_model
            from lab.sim.movers import make_mover
            from lab.sim.world import RenderSettings

            model = box_model(true_model)
            rng = np.random.default_rng(seed)
            yaw = float(rng.uniform(-0.3, 0.3)) if box_yaw is None else float(box_yaw)
            world = SimWorld(cfg.sim.world, RenderSettings(supersample=cfg.sim.supersample))
            carrier = world.add_carrier(model, _pose_from(cfg.sim.carrier_start), box_yaw=yaw)
            source = SimRenderedStereoSource(
                world, emu.create, emu.ptu, cfg, calib, sensing=sensing, seed=seed
            )
            carrier.mover = make_mover(mover, carrier, observer_pose=source.base_pose_W, seed=seed)
        robot = HardwareRobot(cfg, camera_source=source, on_event=on_event)
        yield Rehearsal(robot, emu, cfg, world, carrier, true_model if carrier is not None else None, source)
    finally:
        _stop_all(robot, emu, world, tmp)


def _stop_all(robot, emu: EmulatorSet, world, tmp: str | None) -> None:
    """Close the robot, then the emulators, then the world; then remove the temporary link folder."""
    if robot is not None:
        robot.close()
    emu.close()
    if world is not None:
        world.close()
    if tmp is not None:
        shutil.rmtree(tmp, ignore_errors=True)
