"""The Robot interface every algorithm uses; the simulator and the hardware adapter implement it.

A robot is a differential-drive base with a pan-tilt unit carrying a rectified stereo camera.
Frames, angles and units follow ``docs/conventions.md``: metres, radians, seconds; images are RGB
``uint8`` arrays of shape (H, W, 3); the camera frame C is the left camera's optical frame.

Order of a control step (the same on both implementations)::

    frame = robot.capture_stereo()          # images + the pan-tilt state and odometry at capture
    ... perceive, estimate, plan ...
    robot.command_pan_tilt(pan, tilt)       # position targets, limits checked before anything moves
    robot.drive(v, omega)                   # velocity command, held until the watchdog expires
    robot.step(dt)                          # simulator: advance simulated time; hardware: wait dt

Safety contract (both implementations):

* Motion commands need ``enable()`` first; before it, after ``close()`` or ``disable()`` they raise
  :class:`~lab.errors.NotEnabled`.
* ``drive`` and ``command_pan_tilt`` refuse NaN, infinite or non-numeric values with ``ValueError`` /
  ``TypeError`` before anything moves; pan/tilt outside the limits raise
  :class:`~lab.errors.LimitError`. Base speeds beyond the limits are clamped (``BaseLimits``), and
  changes are slew-limited by the acceleration limits.
* A watchdog stops the base when no ``drive`` command arrived for ``cmd_timeout_s`` (0.5 s).
* ``estop()`` stops everything and latches; ``drive`` then raises :class:`~lab.errors.EStopActive`
  until ``clear_estop()`` and ``enable()``.
* A safety trip (cliff, wheel drop) raises :class:`~lab.errors.SafetyStop` from the next command or
  step and leaves the robot disabled; it is never re-armed automatically.
* ``bumps`` counts the times the base ran into something (the Create 2's bumpers, packet 7; the
  simulated base's contacts), one per contact; a bump does not disarm. A wrapper passes it on, so
  the navigator sees a bump through any wrapper (it ends a drive with ``BUMPED``).

Ground truth (true poses, contacts) is not part of this interface: the simulator exposes it through a
separate evaluation handle (``lab.sim.SimWorld.truth``) for tests and scoring only.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, field

import numpy as np

from lab.errors import ConfigError, LimitError
from lab.geometry import Pose2D, pan_tilt_G_RC, relative_pose2d

__all__ = [
    "BaseLimits",
    "PanTiltLimits",
    "PanTiltState",
    "Robot",
    "RobotWrapper",
    "StereoCamera",
    "StereoFrame",
    "check_finite",
    "frame_motion",
]


def check_finite(**values) -> None:
    """Refuse non-numeric, NaN or infinite command values, naming the argument."""
    for name, v in values.items():
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
            raise TypeError(f"{name} must be a number, got {type(v).__name__} {v!r}")
        if not math.isfinite(float(v)):
            raise ValueError(f"{name} must be finite, got {v!r}")


@dataclass(frozen=True)
class CameraSpec:
    """A stereo camera as a renderer takes it: image size, vertical field of view and baseline.

    ``CameraSpec()`` is the simulated robot's camera (a BumbleBee2-like rig at the papers' 320 x 240):
    the one place the simulator, the training rings and the command line take it from. A real camera
    is described by its calibration file instead (:mod:`lab.vision.rectify`). Code that uses the camera
    takes it from the robot (:attr:`Robot.camera`), never from here.

    Attributes
    ----------
    width, height : int [px]
    fov_y_deg : float [deg]
    baseline : float [m]
    """

    width: int = 320
    height: int = 240
    fov_y_deg: float = 60.0
    baseline: float = 0.12

    def camera(self, mount_R=(0.0, 0.0, 0.8)) -> StereoCamera:
        """The rectified pinhole pair these render (:meth:`StereoCamera.from_fov`), mounted at ``mount_R``."""
        return StereoCamera.from_fov(self.width, self.height, self.fov_y_deg, self.baseline, mount_R=mount_R)


#: The simulated robot's camera.
SIM_CAMERA = CameraSpec()


@dataclass(frozen=True)
class StereoCamera:
    """A rectified stereo pair on a pan-tilt head: pinhole intrinsics, baseline and mounting.

    Attributes
    ----------
    width, height : int [px]
    fx, fy, cx, cy : float [px]
        Pinhole intrinsics of both rectified images (identical after rectification).
    baseline : float [m]
        Right camera's offset along the left camera's x axis.
    mount_R : tuple of 3 floats [m]
        Pan/tilt axes intersection in the robot frame R.
    camera_offset_P : tuple of 3 floats [m]
        Left camera's optical centre in the pan-tilt frame P (x forward, y left, z up).
    depth_scale_std : float
        How well the calibration is known, as the relative error of triangulated depths it leaves
        (focal length and baseline errors in quadrature): 0.007 is a checkerboard calibration to
        0.5 % each. 0: exact (a simulated camera under the ``ideal`` profile). The pose filters take
        it into account (``lab.estimation.CalibrationUncertainty.of_camera``).
    pointing_std_deg : float [deg]
        The same for the camera's orientation on the robot (pan-tilt zero, mount), per axis.
    focal_std : float
        The focal lengths' share of ``depth_scale_std``: the relative error of each of ``fx``, ``fy``
        (0.005 for a checkerboard calibration); the baseline's is the rest,
        ``sqrt(depth_scale_std**2 - focal_std**2)``. A focal length's error stretches depth and rows
        against the columns, which one scale cannot say; 0: all of the depth's error is a common scale.
    blur_sigma_px : float [px]
        The images' blur (lens, focus, demosaicing) as a Gaussian's standard deviation in these pixels,
        as measured on the camera (a slanted-edge target gives it to about 0.1 px). The stereo features
        sharpen by its excess over the 0.5 px SIFT assumes
        (:attr:`lab.vision.stereo.StereoParams.sift_blur_px`): a blur of 1 px takes the fine features
        SIFT matches a small object by. 0: sharp, or not measured.
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    baseline: float
    mount_R: tuple[float, float, float] = (0.0, 0.0, 0.8)
    camera_offset_P: tuple[float, float, float] = (0.05, 0.06, 0.0)
    depth_scale_std: float = 0.0
    pointing_std_deg: float = 0.0
    focal_std: float = 0.0
    blur_sigma_px: float = 0.0

    def __post_init__(self):
        for name in ("depth_scale_std", "pointing_std_deg", "focal_std", "blur_sigma_px"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ConfigError(f"camera {name} must be a finite number >= 0, got {v!r}")
        if self.focal_std > self.depth_scale_std:
            raise ConfigError(
                f"camera focal_std ({self.focal_std}) must be <= depth_scale_std ({self.depth_scale_std}): "
                "it is the focal lengths' share of the depth's error"
            )
        if self.width < 16 or self.height < 16:
            raise ConfigError(f"camera size {self.width}x{self.height} px is too small (at least 16x16)")
        if not (self.fx > 0 and self.fy > 0):
            raise ConfigError(f"camera focal lengths must be > 0 px, got fx={self.fx}, fy={self.fy}")
        if not self.baseline > 0:
            raise ConfigError(f"stereo baseline must be > 0 m, got {self.baseline}")

    @classmethod
    def from_fov(
        cls,
        width: int = SIM_CAMERA.width,
        height: int = SIM_CAMERA.height,
        fov_y_deg: float = SIM_CAMERA.fov_y_deg,
        baseline: float = SIM_CAMERA.baseline,
        mount_R=(0.0, 0.0, 0.8),
        camera_offset_P=(0.05, 0.06, 0.0),
    ) -> StereoCamera:
        """Intrinsics that match a rendered image: ``f = (H/2)/tan(fov_y/2)``, ``c = size/2 - 0.5``.

        The defaults are :data:`SIM_CAMERA`'s."""
        if not 5.0 <= fov_y_deg <= 150.0:
            raise ConfigError(f"fov_y_deg must be within [5, 150] degrees, got {fov_y_deg}")
        f = (height / 2.0) / math.tan(math.radians(fov_y_deg) / 2.0)
        return cls(
            int(width),
            int(height),
            f,
            f,
            width / 2.0 - 0.5,
            height / 2.0 - 0.5,
            float(baseline),
            tuple(float(v) for v in mount_R),
            tuple(float(v) for v in camera_offset_P),
        )

    @property
    def fov_y_deg(self) -> float:
        return math.degrees(2.0 * math.atan((self.height / 2.0) / self.fy))

    @property
    def K(self) -> np.ndarray:
        """3x3 intrinsic matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def project(self, points_cam: np.ndarray) -> np.ndarray:
        """Pixel positions (u, v) of points in the left camera frame C, shape (n, 3) -> (n, 2)."""
        p = np.atleast_2d(np.asarray(points_cam, dtype=float))
        return np.stack(
            [self.fx * p[:, 0] / p[:, 2] + self.cx, self.fy * p[:, 1] / p[:, 2] + self.cy], axis=1
        )

    def G_RC(self, pan: float, tilt: float) -> np.ndarray:
        """Left camera frame C in the robot frame R for a pan-tilt state (see ``lab.geometry``)."""
        return pan_tilt_G_RC(pan, tilt, self.mount_R, self.camera_offset_P)


@dataclass(frozen=True)
class PanTiltLimits:
    """Pan-tilt range [rad] and speed [rad/s]. Defaults are a PTU-D46-17's (0.0514 deg per step)."""

    pan_min: float = math.radians(-158.9)
    pan_max: float = math.radians(158.9)
    tilt_min: float = math.radians(-46.6)
    tilt_max: float = math.radians(31.0)
    max_speed: float = math.radians(120.0)
    min_speed: float = math.radians(1.6)

    def check(self, pan: float, tilt: float) -> None:
        """Raise :class:`LimitError` naming the axis and its range when a target is outside."""
        if not self.pan_min <= pan <= self.pan_max:
            raise LimitError(
                f"pan {math.degrees(pan):.1f} deg is outside "
                f"[{math.degrees(self.pan_min):.1f}, {math.degrees(self.pan_max):.1f}] deg"
            )
        if not self.tilt_min <= tilt <= self.tilt_max:
            raise LimitError(
                f"tilt {math.degrees(tilt):.1f} deg is outside "
                f"[{math.degrees(self.tilt_min):.1f}, {math.degrees(self.tilt_max):.1f}] deg"
            )

    def check_speed(self, speed: float) -> None:
        if not self.min_speed <= speed <= self.max_speed:
            raise LimitError(
                f"pan-tilt speed {math.degrees(speed):.1f} deg/s is outside "
                f"[{math.degrees(self.min_speed):.1f}, {math.degrees(self.max_speed):.1f}] deg/s"
            )


@dataclass(frozen=True)
class BaseLimits:
    """Differential-drive limits: speeds are clamped to these, changes slew-limited by the accelerations."""

    max_speed: float = 0.5  # [m/s], the Create 2's wheel limit
    max_turn_rate: float = 1.5  # [rad/s]
    max_accel: float = 0.5  # [m/s^2]
    max_turn_accel: float = 3.0  # [rad/s^2]
    wheel_base: float = 0.235  # [m] axle length (Create 2)
    radius: float = 0.2  # [m] footprint radius, for collision checks and obstacle growing


@dataclass(frozen=True)
class PanTiltState:
    """Pan-tilt angles [rad] at time ``t`` [s], its targets, and whether it is still moving."""

    pan: float
    tilt: float
    t: float = 0.0
    pan_target: float = 0.0
    tilt_target: float = 0.0
    moving: bool = False


@dataclass(frozen=True)
class StereoFrame:
    """A rectified stereo pair with everything needed to interpret it.

    Attributes
    ----------
    t : float [s]
        Capture time (simulated time in the simulator, monotonic time on hardware).
    left, right : ndarray, shape (H, W, 3), uint8
        Rectified RGB images.
    camera : StereoCamera
    pan_tilt : PanTiltState
        The head's state at capture: ``camera.G_RC(pan_tilt.pan, pan_tilt.tilt)`` is ``G_RC``.
    odom : Pose2D
        The robot's pose at capture, in the world frame: the base's wheel odometry, or the localizer's
        estimate behind :class:`lab.localization.LocalizedRobot`. Whatever is placed in the
        world from this frame uses it (``G_WC = odom.G() @ G_RC``).
    wheel_odom : Pose2D or None
        The base's own wheel odometry at capture when ``odom`` is a localized estimate (None: ``odom``
        is the wheel odometry). The motion between two frames comes from it (:func:`frame_motion`):
        a landmark update between two frames moves the estimate, not the robot.
    """

    t: float
    left: np.ndarray = field(repr=False)
    right: np.ndarray = field(repr=False)
    camera: StereoCamera
    pan_tilt: PanTiltState
    odom: Pose2D
    wheel_odom: Pose2D | None = None

    @property
    def G_RC(self) -> np.ndarray:
        return self.camera.G_RC(self.pan_tilt.pan, self.pan_tilt.tilt)

    @property
    def wheels(self) -> Pose2D:
        """The wheel odometry at capture (``wheel_odom``, else ``odom``)."""
        return self.odom if self.wheel_odom is None else self.wheel_odom


def frame_motion(prev: StereoFrame, cur: StereoFrame) -> np.ndarray:
    """``G_{R(k-1) R(k)}`` (4x4): how the base moved between two frames, by its wheel odometry.

    The object filters predict with it. It is the increment of the wheels, not of ``odom``: with
    localization on, ``odom`` also jumps when a landmark corrects the estimate.
    """
    return relative_pose2d(prev.wheels, cur.wheels)


class Robot(ABC):
    """A differential-drive robot with a pan-tilt stereo head (see the module docstring for the contract).

    Implementations: :class:`lab.sim.SimRobot` and the hardware adapter in ``lab.hardware``.
    """

    #: seconds without a ``drive`` command after which the base is stopped
    cmd_timeout_s: float = 0.5

    @property
    @abstractmethod
    def camera(self) -> StereoCamera:
        """The stereo camera model (intrinsics, baseline, mounting on the pan-tilt)."""

    @property
    @abstractmethod
    def pan_tilt_limits(self) -> PanTiltLimits: ...

    @property
    @abstractmethod
    def base_limits(self) -> BaseLimits: ...

    @abstractmethod
    def now(self) -> float:
        """Current time [s] on the robot's clock (simulated or monotonic)."""

    @abstractmethod
    def enable(self) -> None:
        """Arm the motors. Raises EStopActive while the emergency stop is latched."""

    @abstractmethod
    def disable(self) -> None:
        """Stop and disarm the motors (commands then raise NotEnabled)."""

    @property
    @abstractmethod
    def enabled(self) -> bool: ...

    @abstractmethod
    def capture_stereo(self, after: float | None = None) -> StereoFrame:
        """A rectified stereo pair, taken at ``now()`` (or the first frame newer than ``after``)."""

    @property
    @abstractmethod
    def bumps(self) -> int:
        """Number of bumps (contacts of the base with something) since the robot was created."""

    @abstractmethod
    def odometry(self) -> Pose2D:
        """The base's wheel-odometry pose in the world frame (drifts; it is not ground truth)."""

    def wheel_odometry(self) -> Pose2D:
        """The base's own wheel odometry: :meth:`odometry` here; a wrapper whose ``odometry()`` is an
        estimate (a localized robot) keeps the wheels' here, so that the distance the wheels drove is
        not lengthened by the estimate's corrections."""
        return self.odometry()

    @abstractmethod
    def pan_tilt(self) -> PanTiltState:
        """The pan-tilt unit's current angles and targets."""

    @abstractmethod
    def command_pan_tilt(self, pan: float, tilt: float, speed: float | None = None) -> None:
        """Move the head towards ``(pan, tilt)`` [rad] at ``speed`` [rad/s] (default: the unit's own).

        Raises LimitError (nothing moves) for targets or speeds outside the limits.
        """

    @abstractmethod
    def drive(self, v: float, omega: float) -> None:
        """Command forward speed ``v`` [m/s] and turn rate ``omega`` [rad/s] (counter-clockwise).

        Values beyond the limits are clamped; the command holds until the next one or the watchdog.
        """

    @abstractmethod
    def stop(self) -> None:
        """Zero the base velocity at once (no slew) and hold the head where it is."""

    @abstractmethod
    def step(self, dt: float) -> None:
        """Let ``dt`` [s] pass: the simulator advances simulated time, the hardware waits."""

    @abstractmethod
    def estop(self) -> None:
        """Emergency stop: stop everything and latch until ``clear_estop()`` + ``enable()``."""

    @abstractmethod
    def clear_estop(self) -> None: ...

    @abstractmethod
    def close(self) -> None:
        """Stop the motors and release the devices. Safe to call twice."""

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False

    def wait_pan_tilt(self, timeout: float = 10.0, dt: float = 0.05) -> PanTiltState:
        """Step until the head reaches its targets; raises DeviceTimeout after ``timeout`` [s].

        The default covers a swing across the whole pan range at the unit's default slew speed (318
        deg at 60 deg/s: 5.3 s, with the realistic profile's backlash on top): with 5 s, a search trial
        whose head stood at one end of the range when the global scan began at the other ended
        "stopped by a fault: DeviceTimeout"."""
        from lab.errors import DeviceTimeout

        t_end = self.now() + timeout
        while True:
            s = self.pan_tilt()
            if not s.moving:
                return s
            if self.now() >= t_end:
                raise DeviceTimeout(f"pan-tilt did not reach its target within {timeout:.1f} s")
            self.step(dt)


class RobotWrapper(Robot):
    """A :class:`Robot` that passes every call on to ``base``: subclasses override only what they
    change (a budget on ``step``, a localized ``odometry``, ...). Anything else the base offers (a
    hardware robot's ``watchdog_stops``, ``read_state``) is reached through it too.
    """

    def __init__(self, base: Robot):
        self.base = base

    @property
    def camera(self) -> StereoCamera:
        return self.base.camera

    @property
    def pan_tilt_limits(self) -> PanTiltLimits:
        return self.base.pan_tilt_limits

    @property
    def base_limits(self) -> BaseLimits:
        return self.base.base_limits

    @property
    def cmd_timeout_s(self) -> float:  # type: ignore[override]
        return self.base.cmd_timeout_s

    def now(self) -> float:
        return self.base.now()

    def enable(self) -> None:
        self.base.enable()

    def disable(self) -> None:
        self.base.disable()

    @property
    def enabled(self) -> bool:
        return self.base.enabled

    def capture_stereo(self, after: float | None = None) -> StereoFrame:
        return self.base.capture_stereo(after)

    @property
    def bumps(self) -> int:
        return self.base.bumps

    def odometry(self) -> Pose2D:
        return self.base.odometry()

    def wheel_odometry(self) -> Pose2D:
        return self.base.wheel_odometry()

    def pan_tilt(self) -> PanTiltState:
        return self.base.pan_tilt()

    def command_pan_tilt(self, pan: float, tilt: float, speed: float | None = None) -> None:
        self.base.command_pan_tilt(pan, tilt, speed)

    def drive(self, v: float, omega: float) -> None:
        self.base.drive(v, omega)

    def stop(self) -> None:
        self.base.stop()

    def step(self, dt: float) -> None:
        self.base.step(dt)

    def estop(self) -> None:
        self.base.estop()

    def clear_estop(self) -> None:
        self.base.clear_estop()

    def close(self) -> None:
        self.base.close()

    def __getattr__(self, name):  # only for what the class does not define
        if name == "base":  # not set yet (e.g. while unpickling): no recursion
            raise AttributeError(name)
        return getattr(self.base, name)
