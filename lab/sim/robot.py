"""The simulated robot: a differential-drive base, a PTU-D46-like pan-tilt unit and a stereo camera.

:class:`SimRobot` implements :class:`lab.robot.Robot` on a :class:`~lab.sim.world.SimWorld` with the same
limits, watchdog, emergency stop and exceptions as the hardware adapter, so that a notebook behaves the
same on both. Simulated time advances only in :meth:`SimRobot.step`, in sub-steps of ``dt_physics``:

1. the watchdog zeroes the velocity target when no ``drive`` arrived for ``cmd_timeout_s``;
2. the base's velocity slews towards its target within the acceleration limits;
3. the base moves (exact unicycle arc); if its footprint would touch a body, it stays where it was, its
   velocity is zeroed and a collision is counted (the bump sensor's view of it);
4. wheel odometry integrates the same motion with seeded noise (:class:`OdometryNoise` under the
   ``ideal`` sensing profile, :class:`~lab.sim.sensing.OdometryErrors` under ``realistic``);
5. the pan-tilt moves towards its targets at its speed (its axes through the profile's backlash);
6. the world's clock and carriers advance.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from lab.errors import ConfigError, EStopActive, NotEnabled, SafetyStop
from lab.geometry import Pose2D, R_to_quat_xyzw, Rz, pan_tilt_G_RP, se3, se3_inv, wrap_angle
from lab.robot import (
    SIM_CAMERA,
    BaseLimits,
    PanTiltLimits,
    PanTiltState,
    Robot,
    StereoCamera,
    StereoFrame,
    check_finite,
)
from lab.sim.episode import EpisodeSensing
from lab.sim.room_errors import rotation_rpy
from lab.sim.sensing import SensingProfile, backlash, sensing_profile
from lab.sim.world import SimWorld, pybullet

__all__ = ["OdometryNoise", "RobotTruth", "SimRobot"]


@dataclass(frozen=True)
class OdometryNoise:
    """Wheel-odometry error model (standard deviations per sub-step, proportional to the motion).

    Attributes
    ----------
    scale : float
        Relative error of the distance travelled (0.02 = 2 %).
    turn : float
        Relative error of the heading change.
    drift : float [rad/m]
        Heading drift per metre travelled.
    """

    scale: float = 0.02
    turn: float = 0.02
    drift: float = 0.01

    @classmethod
    def none(cls) -> OdometryNoise:
        return cls(0.0, 0.0, 0.0)


class RobotTruth:
    """Ground truth of a :class:`SimRobot`: for tests and scoring only, never for the robot's algorithms.

    A read-only view (``robot.truth``); :class:`lab.sim.truth.Truth` (``world.truth``) reads it.
    """

    __slots__ = ("_robot",)

    def __init__(self, robot: SimRobot):
        self._robot = robot

    def pose(self) -> Pose2D:
        """The base's true pose in the world."""
        return self._robot._true_pose

    def G_WC(self) -> np.ndarray:
        """The left camera's true pose in the world: the true base, the pan-tilt axes' true angles."""
        return self._robot._true_G_WC()

    def G_WC_exposed(self) -> np.ndarray:
        """The left camera's true pose when an image captured now was exposed: ``latency_s`` before now
        (what :meth:`SimRobot.capture_stereo` renders, the camera a frame's estimates are relative to);
        :meth:`G_WC` without a latency."""
        r = self._robot
        return r._G_WC_at(r.world.t - r._latency)

    @property
    def sensing(self) -> EpisodeSensing:
        """The sensing draws of this episode (the renders' cameras, light, odometry errors, zeros)."""
        return self._robot._episode

    @property
    def collisions(self) -> int:
        """Number of times the base ran into something."""
        return self._robot._collisions


class SimRobot(Robot):
    """A simulated robot in a :class:`SimWorld` (see the module docstring for one sub-step).

    Parameters
    ----------
    world : SimWorld
    camera : StereoCamera, optional
        Default: :data:`lab.robot.SIM_CAMERA` (320 x 240, 60 degree vertical field of view, 0.12 m
        baseline), the pan-tilt axes at the
        scene's ``[robot] mast_height`` (0.7 m unless the scene says otherwise; the lab room's robot
        has a 1.1 m mast to see over a table and onto the 1.2 m shelf).
    start : Pose2D, optional
        Default: the scene's ``[robot] start``.
    seed : int
        Seeds the odometry noise and every draw of the sensing profile.
    odometry_noise : OdometryNoise, optional
        The odometry's noise under a profile without odometry errors (``ideal``); a profile with
        odometry errors (``realistic``) has its own, and passing both is a ConfigError.
    base_limits, pan_tilt_limits : optional
    pan_tilt_speed : float [rad/s]
        The unit's default slew speed.
    dt_physics : float [s]
        Sub-step of :meth:`step`.
    sensing : SensingProfile, str or mapping
        The sensing errors (:func:`lab.sim.sensing.sensing_profile`): ``"ideal"`` (the default, exact
        images and pan-tilt) or ``"realistic"``. Under either the robot reports the nominal ``camera``,
        the commanded pan-tilt angles and its odometry; only the renders and ``world.truth`` see the
        perturbed calibration, the axes' true angles and the true pose.
    """

    HEIGHT = 0.3  # base height [m] (the mast above it is thin and has no collision shape)

    def __init__(
        self,
        world: SimWorld,
        camera: StereoCamera | None = None,
        start: Pose2D | None = None,
        seed: int = 0,
        odometry_noise: OdometryNoise | None = None,
        base_limits: BaseLimits | None = None,
        pan_tilt_limits: PanTiltLimits | None = None,
        pan_tilt_speed: float = math.radians(60.0),
        dt_physics: float = 0.02,
        sensing: SensingProfile | str | Mapping = "ideal",
    ):
        if world.robot is not None:
            raise ConfigError("this world already has a robot")
        self.world = world
        self._camera = camera or SIM_CAMERA.camera(mount_R=(0.0, 0.0, world.scene.robot_mast_height))
        self._base_limits = base_limits or BaseLimits()
        self._pt_limits = pan_tilt_limits or PanTiltLimits()
        self._pt_limits.check_speed(pan_tilt_speed)
        self._pt_speed_default = pan_tilt_speed
        if not 0 < dt_physics <= 0.1:
            raise ConfigError(f"dt_physics must be within (0, 0.1] s, got {dt_physics}")
        self.dt_physics = dt_physics
        self._sensing = sensing_profile(sensing)
        self._camera = self._sensing.reported_camera(self._camera)
        if odometry_noise is not None and not self._sensing.odometry.is_none:
            raise ConfigError(
                f"odometry_noise applies only without odometry errors (sensing 'ideal'); sensing "
                f"{self._sensing.name!r} has its own (its odometry section)"
            )
        self._noise = odometry_noise or OdometryNoise()
        self._rng = np.random.default_rng(seed)
        self._episode = EpisodeSensing(self._sensing, seed, self._camera, world.settings.light_direction)
        if start is None:
            x, y, h = world.scene.robot_start
            start = Pose2D(x, y, math.radians(h))
        self._true_pose = start
        room = self._episode.room
        # the operator stood the robot on its mark; its odometry starts where the operator believes it is
        self._odom = _compose(start, room.start_offset) if not self._sensing.room.is_none else start
        self._head_mount = self._camera_mount = None
        if not self._sensing.room.is_none:
            m = np.asarray(self._camera.mount_R, float)
            self._head_mount = se3(None, m) @ se3(rotation_rpy(room.head_mount_rpy)) @ se3(None, -m)
            self._camera_mount = rotation_rpy(room.camera_mount_rpy)
        self._latency = room.latency_s
        n_past = int(math.ceil(self._latency / dt_physics)) + 4
        self._past: deque = deque(maxlen=n_past)  # (t, true pose, true axes) per sub-step, for a late image
        self._v = self._omega = 0.0
        self._v_cmd = self._omega_cmd = 0.0
        self._last_cmd_t = -math.inf
        self._pan = self._tilt = 0.0
        self._pan_target = self._tilt_target = 0.0
        self._pan_axis = self._tilt_axis = 0.0  # the geared axes (backlash), before the zero offsets
        self._pt_speed = pan_tilt_speed
        self._enabled = False
        self._estop = False
        self._closed = False
        self._safety_trip: str | None = None
        self._collisions = 0
        self._in_contact = False
        self._build_body()
        world.robot = self
        self._remember()

    # --- body -----------------------------------------------------------------------------------
    def _build_body(self):
        pb = self.world.p
        r = self._base_limits.radius
        col = pb.createCollisionShape(pybullet.GEOM_CYLINDER, radius=r, height=self.HEIGHT)
        vis = pb.createVisualShape(
            pybullet.GEOM_CYLINDER, radius=r, length=self.HEIGHT, rgbaColor=(0.1, 0.45, 0.2, 1)
        )
        self._body = pb.createMultiBody(0, col, vis, (0, 0, self.HEIGHT / 2))
        mast_h = self._camera.mount_R[2] - self.HEIGHT - 0.06
        mvis = pb.createVisualShape(
            pybullet.GEOM_BOX, halfExtents=(0.02, 0.02, mast_h / 2), rgbaColor=(0.3, 0.3, 0.3, 1)
        )
        self._mast = pb.createMultiBody(0, -1, mvis, (0, 0, 0))
        self._mast_h = mast_h
        self.world.register("robot", self._body)
        self._place(self._true_pose)

    def _place(self, pose: Pose2D):
        pb = self.world.p
        q = R_to_quat_xyzw(Rz(pose.theta))
        pb.resetBasePositionAndOrientation(self._body, (pose.x, pose.y, self.HEIGHT / 2), q)
        m = self._camera.mount_R
        c, s = math.cos(pose.theta), math.sin(pose.theta)
        mx, my = pose.x + c * m[0] - s * m[1] - 0.03 * c, pose.y + s * m[0] + c * m[1] - 0.03 * s
        pb.resetBasePositionAndOrientation(self._mast, (mx, my, self.HEIGHT + self._mast_h / 2), q)

    def _collides(self, margin: float = 0.0) -> bool:
        """Whether the base's footprint touches (or comes within ``margin`` [m] of) any other body."""
        pb = self.world.p
        skip = (self._body, self.world.body_ids.get("floor"))
        # every registered body (carriers' bases included), also those added after the robot
        others = [b for b in self.world.body_ids.values() if b not in skip]
        return any(pb.getClosestPoints(self._body, b, margin) for b in others)

    @property
    def truth(self) -> RobotTruth:
        """Ground truth (true pose, camera pose, sensing draws): for tests and scoring only, never for
        the robot's algorithms, which see only the :class:`lab.robot.Robot` interface."""
        return RobotTruth(self)

    # --- Robot interface ------------------------------------------------------------------------
    @property
    def camera(self) -> StereoCamera:
        return self._camera

    @property
    def sensing(self) -> SensingProfile:
        """The sensing profile this robot's sensors follow."""
        return self._sensing

    @property
    def pan_tilt_limits(self) -> PanTiltLimits:
        return self._pt_limits

    @property
    def base_limits(self) -> BaseLimits:
        return self._base_limits

    def now(self) -> float:
        return self.world.t

    @property
    def enabled(self) -> bool:
        return self._enabled

    def enable(self) -> None:
        self._check_open()
        if self._estop:
            raise EStopActive("emergency stop is latched: call clear_estop() before enable()")
        self._safety_trip = None
        self._enabled = True

    def disable(self) -> None:
        self.stop()
        self._enabled = False

    def _check_open(self):
        if self._closed:
            raise NotEnabled("the robot is closed; create a new one")

    def _check_motion_allowed(self):
        self._check_open()
        if self._safety_trip is not None:
            raise SafetyStop(f"safety stop ({self._safety_trip}): call enable() to re-arm")
        if self._estop:
            raise EStopActive("emergency stop is latched: call clear_estop() and then enable()")
        if not self._enabled:
            raise NotEnabled("motors are disabled: call enable() first")

    def capture_stereo(self, after: float | None = None) -> StereoFrame:
        self._check_open()
        if after is not None and after >= self.world.t:
            self.step(after - self.world.t + self.dt_physics)
        G_WC = self._G_WC_at(self.world.t - self._latency)
        if self._sensing.camera.is_none:
            left, right = self.world.render_stereo(G_WC, self._camera)
        else:
            left, right = self._episode.render_stereo(self.world, G_WC)
        return StereoFrame(self.world.t, left, right, self._camera, self.pan_tilt(), self._odom)

    def odometry(self) -> Pose2D:
        return self._odom

    def _true_G_WC(self) -> np.ndarray:
        """The left camera's true pose: the true base, the axes' true angles (``world.truth.G_WC``)."""
        return self._G_WC(self._true_pose, *self._true_axes())

    def _true_axes(self) -> tuple[float, float]:
        """The pan-tilt axes' true angles: geared (backlash), plus the zero offsets."""
        if self._sensing.pan_tilt.is_none:
            return self._pan, self._tilt
        d = self._episode.pan_tilt
        return self._pan_axis + d.pan_offset, self._tilt_axis + d.tilt_offset

    def _G_WC(self, pose: Pose2D, pan: float, tilt: float) -> np.ndarray:
        """The left camera in W for a base pose and true axis angles, with the mounts' errors: the
        pan-tilt rotated on the mast about the axes' intersection, the camera on its bracket about its
        optical centre (what the robot's kinematics, ``camera.G_RC``, do not know)."""
        G_RC = self._camera.G_RC(pan, tilt)
        if self._head_mount is not None:
            G_RP = pan_tilt_G_RP(pan, tilt, self._camera.mount_R)
            G_PC = se3_inv(G_RP) @ G_RC
            o = G_PC[:3, 3]
            G_RC = self._head_mount @ G_RP @ se3(self._camera_mount, o) @ se3(None, -o) @ G_PC
        return pose.G() @ G_RC

    def _remember(self) -> None:
        self._past.append((self.world.t, self._true_pose, *self._true_axes()))

    def _G_WC_at(self, t: float) -> np.ndarray:
        """The true camera pose at time ``t`` (now at most; the sub-steps' record, linearly interpolated,
        and the oldest one before it): what an image exposed ``latency_s`` before its stamp shows."""
        if self._latency == 0 or t >= self._past[-1][0]:
            return self._true_G_WC()
        past = list(self._past)
        for (t0, p0, *a0), (t1, p1, *a1) in zip(past[:-1], past[1:], strict=True):
            if t0 <= t <= t1:
                w = (t - t0) / (t1 - t0) if t1 > t0 else 1.0
                pose = Pose2D(
                    p0.x + w * (p1.x - p0.x),
                    p0.y + w * (p1.y - p0.y),
                    wrap_angle(p0.theta + w * wrap_angle(p1.theta - p0.theta)),
                )
                return self._G_WC(pose, *(u + w * (v - u) for u, v in zip(a0, a1, strict=True)))
        _, p, *axes = past[0]
        return self._G_WC(p, *axes)

    def pan_tilt(self) -> PanTiltState:
        moving = abs(self._pan - self._pan_target) > 1e-9 or abs(self._tilt - self._tilt_target) > 1e-9
        return PanTiltState(self._pan, self._tilt, self.world.t, self._pan_target, self._tilt_target, moving)

    def command_pan_tilt(self, pan: float, tilt: float, speed: float | None = None) -> None:
        check_finite(pan=pan, tilt=tilt, **({} if speed is None else {"speed": speed}))
        self._pt_limits.check(float(pan), float(tilt))
        if speed is not None:
            self._pt_limits.check_speed(float(speed))
        self._check_motion_allowed()
        self._pan_target, self._tilt_target = float(pan), float(tilt)
        self._pt_speed = self._pt_speed_default if speed is None else float(speed)

    def drive(self, v: float, omega: float) -> None:
        check_finite(v=v, omega=omega)
        self._check_motion_allowed()
        L = self._base_limits
        self._v_cmd = float(np.clip(v, -L.max_speed, L.max_speed))
        self._omega_cmd = float(np.clip(omega, -L.max_turn_rate, L.max_turn_rate))
        self._last_cmd_t = self.world.t

    def stop(self) -> None:
        self._v = self._omega = self._v_cmd = self._omega_cmd = 0.0
        self._pan_target, self._tilt_target = self._pan, self._tilt

    def estop(self) -> None:
        self.stop()
        self._estop = True
        self._enabled = False

    def clear_estop(self) -> None:
        self._estop = False

    def close(self) -> None:
        if not self._closed:
            self.stop()
            self._enabled = False
            self._closed = True

    def trip_safety(self, reason: str) -> None:
        """Simulate a cliff or wheel-drop trip: stop, disable, and raise from the next command or step."""
        self.stop()
        self._enabled = False
        self._safety_trip = reason

    @property
    def bumps(self) -> int:
        """Contacts of the base with something (the bump sensor's count); see :attr:`collisions`."""
        return self._collisions

    @property
    def collisions(self) -> int:
        """Number of times the base ran into something (the bump sensor's count)."""
        return self._collisions

    # --- simulation -----------------------------------------------------------------------------
    def step(self, dt: float) -> None:
        check_finite(dt=dt)
        if dt < 0:
            raise ValueError(f"dt must be >= 0 s, got {dt}")
        self._check_open()
        if self._safety_trip is not None:
            raise SafetyStop(f"safety stop ({self._safety_trip}): call enable() to re-arm")
        n = max(1, int(math.ceil(dt / self.dt_physics - 1e-9))) if dt > 0 else 0
        for _ in range(n):
            self._substep(dt / n)

    def _substep(self, h: float) -> None:
        L = self._base_limits
        if self.world.t - self._last_cmd_t > self.cmd_timeout_s or not self._enabled:
            self._v_cmd = self._omega_cmd = 0.0  # watchdog: no fresh command, no motion
        v0, w0 = self._v, self._omega
        self._v += float(np.clip(self._v_cmd - self._v, -L.max_accel * h, L.max_accel * h))
        self._omega += float(
            np.clip(self._omega_cmd - self._omega, -L.max_turn_accel * h, L.max_turn_accel * h)
        )
        v_mid, w_mid = 0.5 * (v0 + self._v), 0.5 * (w0 + self._omega)  # exact for constant acceleration
        if v_mid != 0.0 or w_mid != 0.0:
            new = _unicycle(self._true_pose, v_mid, w_mid, h)
            self._place(new)
            if self._collides():
                self._place(self._true_pose)
                if not self._in_contact:  # one collision per contact, not one per push against it
                    self._collisions += 1
                    self._slip()
                self._in_contact = True
                self._v = self._omega = 0.0
            else:
                self._in_contact = self._in_contact and self._collides(margin=0.02)
                ds = v_mid * h
                dth = w_mid * h
                ds_m, dth_m = self._measure_motion(ds, dth)
                self._odom = _unicycle_increment(self._odom, ds_m, dth_m)
                self._true_pose = new
        step = self._pt_speed * h
        self._pan += float(np.clip(self._pan_target - self._pan, -step, step))
        self._tilt += float(np.clip(self._tilt_target - self._tilt, -step, step))
        width = math.radians(self._sensing.pan_tilt.backlash_deg)
        self._pan_axis = backlash(self._pan_axis, self._pan, width)
        self._tilt_axis = backlash(self._tilt_axis, self._tilt, width)
        self.world.step(h)
        self._remember()

    def _slip(self) -> None:
        """Wheel slip on a bump: the true pose jumps by the profile's draw, which the odometry does not
        see (mirrored when the jump would run into something; none when both would)."""
        room = self._sensing.room
        if room.bump_slip_m == 0 and room.bump_slip_deg == 0:
            return
        d = self._episode.bump_slip()
        for sign in (1.0, -1.0):
            new = _compose(self._true_pose, tuple(sign * v for v in d))
            self._place(new)
            if not self._collides():
                self._true_pose = new
                return
        self._place(self._true_pose)

    def _measure_motion(self, ds: float, dth: float) -> tuple[float, float]:
        """The odometry's distance [m] and heading change [rad] for a true arc ``ds``, ``dth``."""
        if not self._sensing.odometry.is_none:
            return self._episode.odometry_increment(ds, dth, self._base_limits.wheel_base)
        n = self._noise
        ds_m = ds * (1.0 + n.scale * self._rng.standard_normal())
        dth_m = (
            dth * (1.0 + n.turn * self._rng.standard_normal())
            + n.drift * abs(ds) * self._rng.standard_normal()
        )
        return ds_m, dth_m


def _unicycle_increment(p: Pose2D, ds: float, dth: float) -> Pose2D:
    """Pose after moving ``ds`` [m] along a circular arc that turns by ``dth`` [rad] (exact).

    The chord of the arc has length ``ds * sin(dth/2) / (dth/2)`` and points along the midpoint heading.
    """
    th_mid = p.theta + 0.5 * dth
    chord = ds * float(np.sinc(0.5 * dth / math.pi))  # np.sinc(x) = sin(pi x) / (pi x)
    return Pose2D(p.x + chord * math.cos(th_mid), p.y + chord * math.sin(th_mid), wrap_angle(p.theta + dth))


def _compose(p: Pose2D, d) -> Pose2D:
    """``p`` moved by ``d = (dx, dy, dtheta)`` given in ``p``'s own frame."""
    c, s = math.cos(p.theta), math.sin(p.theta)
    return Pose2D(p.x + c * d[0] - s * d[1], p.y + s * d[0] + c * d[1], wrap_angle(p.theta + d[2]))


def _unicycle(p: Pose2D, v: float, omega: float, h: float) -> Pose2D:
    return _unicycle_increment(p, v * h, omega * h)
