"""The camera's calibrated mounts: the head's and the camera's small rotations and the pan-tilt's zeros,
applied to the robot's kinematics, and the robot's calibration file that holds them.

The nominal kinematics (:func:`lab.geometry.pan_tilt_G_RC`) put the pan-tilt exactly square on the mast
and the camera exactly square on its bracket. A real bracket is 0.2-1 deg off, a pan-tilt's zero a step
or so. :class:`HeadMounts` holds what a calibration (``lab hardware calibrate``,
:mod:`lab.localization.mount_calibration`) estimated; :class:`MountedCamera` is a
:class:`~lab.robot.StereoCamera` whose ``G_RC`` includes them, and :class:`CalibratedRobot` hands every
algorithm frames taken through it, so the localizer and the search's world pose both use the calibrated
camera frame. The model (the same the simulator draws its mount errors with, :mod:`lab.sim.room_errors`)::

    G_RC = T(m) Rot(head_rpy) Rz(pan + pan_zero) Ry(-(tilt + tilt_zero)) T(o) Rot(camera_rpy) R_BO

with ``m`` the axes' intersection in R (``mount_R``), ``o`` the left camera's centre in the pan-tilt
frame P (``camera_offset_P``), ``Rot(r, p, y) = Rz(y) Ry(p) Rx(r)`` and ``R_BO`` the body-to-optical
axes. With every angle 0 it is the nominal ``pan_tilt_G_RC``.

**The file** (TOML, written atomically by :func:`save_mounts`, read strictly by :func:`load_mounts`)::

    format = "lab-mounts"
    version = 1
    robot = "rehearsal"                # who was calibrated (free text)
    created = "2026-12-05T20:00:00Z"
    head_rpy_deg = [0.1, -0.3, 0.0]    # roll, pitch, yaw [deg]
    camera_rpy_deg = [0.2, 0.0, -0.4]
    pan_zero_deg = 0.0
    tilt_zero_deg = 0.6
    std_deg = {head_rpy = [...], camera_rpy = [...], pan_zero = ..., tilt_zero = ...}
    estimated = ["head_roll", ...]     # which angles the routine solved for (the rest are held at 0)
    checksum = "sha256 of every line above it"

A file that is not TOML, lacks a key, has another version, holds a non-finite or implausible angle, or
whose checksum does not match its content (a truncated copy, a hand edit) raises
:class:`~lab.errors.ConfigError` naming the file and what is wrong.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lab.errors import ConfigError
from lab.geometry import R_BODY_TO_OPTICAL, Rx, Ry, Rz, se3
from lab.io import write_text_atomic
from lab.robot import Robot, RobotWrapper, StereoCamera, StereoFrame

__all__ = [
    "FILE_FORMAT",
    "FILE_VERSION",
    "MAX_MOUNT_DEG",
    "CalibratedRobot",
    "HeadMounts",
    "MountedCamera",
    "load_mounts",
    "mounted_G_RC",
    "rpy_matrix",
    "save_mounts",
    "with_head_yaw",
]

FILE_FORMAT = "lab-mounts"
FILE_VERSION = 1
#: Larger angles are not a bracket's error but a wrong file (or a mis-assembled head).
MAX_MOUNT_DEG = 10.0
_ANGLES = ("head_rpy", "camera_rpy", "pan_zero", "tilt_zero")


def rpy_matrix(rpy) -> np.ndarray:
    """``Rz(yaw) @ Ry(pitch) @ Rx(roll)`` of a mount's (roll, pitch, yaw) [rad]."""
    r, p, y = (float(v) for v in rpy)
    return Rz(y) @ Ry(p) @ Rx(r)


@dataclass(frozen=True)
class HeadMounts:
    """A calibration of the head: small rotations [rad] and their standard deviations.

    Attributes
    ----------
    head_rpy : 3 floats [rad]
        The pan-tilt unit on the mast: roll, pitch, yaw about the axes' intersection, in R.
    camera_rpy : 3 floats [rad]
        The camera on the bracket: roll, pitch, yaw about its optical centre, in the pan-tilt frame P.
    pan_zero, tilt_zero : float [rad]
        Added to the reported pan and tilt.
    std : dict name -> float or 3 floats [rad]
        One standard deviation of each angle (0 where it was not estimated).
    estimated : tuple of str
        Which angles the calibration solved for (``head_roll``, ``camera_yaw``, ``tilt_zero``, ...).
    robot, created : str
        Free text: who was calibrated, and when.
    """

    head_rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    camera_rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    pan_zero: float = 0.0
    tilt_zero: float = 0.0
    std: dict = field(default_factory=dict, compare=False)
    estimated: tuple[str, ...] = ()
    robot: str = ""
    created: str = ""

    def __post_init__(self):
        lim = math.radians(MAX_MOUNT_DEG)
        for name in _ANGLES:
            v = np.atleast_1d(np.asarray(getattr(self, name), dtype=float))
            if v.size != (3 if name.endswith("rpy") else 1) or not np.all(np.isfinite(v)):
                raise ConfigError(f"mounts {name} must be finite angles [rad], got {getattr(self, name)!r}")
            if np.any(np.abs(v) > lim):
                raise ConfigError(
                    f"mounts {name} = {np.degrees(v).round(3).tolist()} deg: beyond {MAX_MOUNT_DEG:g} deg, "
                    "not a bracket's error (re-assemble the head, or re-run the calibration)"
                )

    @property
    def is_zero(self) -> bool:
        return not any(np.any(np.asarray(getattr(self, n), float) != 0) for n in _ANGLES)


def mounted_G_RC(
    pan: float, tilt: float, mount_R, camera_offset_P, head_rpy, camera_rpy, pan_zero=0.0, tilt_zero=0.0
) -> np.ndarray:
    """The left camera frame C in R with the mounts' angles [rad] (the module's equation)."""
    m = np.asarray(mount_R, float)
    o = np.asarray(camera_offset_P, float)
    R_RP = rpy_matrix(head_rpy) @ Rz(pan + pan_zero) @ Ry(-(tilt + tilt_zero))
    R_PC = rpy_matrix(camera_rpy) @ R_BODY_TO_OPTICAL
    return se3(R_RP, m) @ se3(R_PC, o)


@dataclass(frozen=True)
class MountedCamera(StereoCamera):
    """A :class:`~lab.robot.StereoCamera` whose ``G_RC`` includes a calibration's :class:`HeadMounts`."""

    mounts: HeadMounts = field(default_factory=HeadMounts)

    @classmethod
    def of(cls, camera: StereoCamera, mounts: HeadMounts) -> MountedCamera:
        """``camera`` (its intrinsics, mounting and stated errors) with ``mounts``."""
        vals = {f.name: getattr(camera, f.name) for f in dataclasses.fields(StereoCamera)}
        return cls(**vals, mounts=mounts)

    def G_RC(self, pan: float, tilt: float) -> np.ndarray:
        m = self.mounts
        return mounted_G_RC(
            pan, tilt, self.mount_R, self.camera_offset_P, m.head_rpy, m.camera_rpy, m.pan_zero, m.tilt_zero
        )


def with_head_yaw(camera: StereoCamera, yaw: float) -> MountedCamera:
    """``camera`` turned by ``yaw`` [rad] more about the pan axis (the head's yaw on the mast: a rotation
    about R's vertical through the axes' intersection, which has x = y = 0). The localizer's estimate of
    the camera's yaw on the base (:mod:`lab.localization.posters`) is that rotation: frames taken through
    it place what they see where the landmarks put the camera."""
    m = camera.mounts if isinstance(camera, MountedCamera) else HeadMounts()
    r, p, y = m.head_rpy
    return MountedCamera.of(camera, dataclasses.replace(m, head_rpy=(r, p, y + float(yaw))))


class CalibratedRobot(RobotWrapper):
    """A robot whose camera (and every frame's) is the :class:`MountedCamera` of a calibration; the rest
    is passed on. Stack it below the localizer, so that both the localizer and what the search places in
    the world see the calibrated camera frame."""

    def __init__(self, base: Robot, mounts: HeadMounts):
        super().__init__(base)
        self.mounts = mounts
        self._camera = MountedCamera.of(base.camera, mounts)

    @property
    def camera(self) -> StereoCamera:
        return self._camera

    def capture_stereo(self, after: float | None = None) -> StereoFrame:
        return dataclasses.replace(self.base.capture_stereo(after), camera=self._camera)


# --- the file -------------------------------------------------------------------------------------


def _body(m: HeadMounts) -> str:
    def num(x) -> str:
        return repr(round(math.degrees(float(x)), 9))

    def vec(v) -> str:
        return "[" + ", ".join(num(x) for x in v) + "]"

    std = {n: m.std.get(n, [0.0, 0.0, 0.0] if n.endswith("rpy") else 0.0) for n in _ANGLES}
    std_items = ", ".join(f"{n} = {vec(v) if n.endswith('rpy') else num(v)}" for n, v in std.items())
    lines = [
        f'format = "{FILE_FORMAT}"',
        f"version = {FILE_VERSION}",
        f"robot = {_toml_str(m.robot)}",
        f"created = {_toml_str(m.created)}",
        f"head_rpy_deg = {vec(m.head_rpy)}",
        f"camera_rpy_deg = {vec(m.camera_rpy)}",
        f"pan_zero_deg = {num(m.pan_zero)}",
        f"tilt_zero_deg = {num(m.tilt_zero)}",
        f"std_deg = {{{std_items}}}",
        "estimated = [" + ", ".join(_toml_str(s) for s in m.estimated) + "]",
    ]
    return "\n".join(lines) + "\n"


def _toml_str(s: str) -> str:
    return '"' + str(s).replace("\\", "\\\\").replace('"', '\\"').replace("\n", " ") + '"'


def _checksum(body: str) -> str:
    return hashlib.sha256(body.encode()).hexdigest()


def save_mounts(path: str | Path, mounts: HeadMounts) -> Path:
    """Write ``mounts`` to ``path`` (the module's format, angles in degrees to 1e-9), atomically: a
    temporary file renamed over the old one, so a crash leaves the old calibration or the new one."""
    body = "# The camera's mounts, estimated by `lab hardware calibrate` (lab/mounts.py). Do not edit:\n"
    body += "# the checksum covers every line above it.\n" + _body(mounts)
    return write_text_atomic(path, body + f'checksum = "{_checksum(body)}"\n')


def load_mounts(path: str | Path) -> HeadMounts:
    """Read a calibration file strictly (see the module docstring for what is rejected)."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"mount calibration {path} not found (make it with: lab hardware calibrate)")
    text = path.read_text(errors="replace")
    body, sep, last = text.rstrip("\n").rpartition("\n")
    try:
        d = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{path}: not valid TOML ({e}); re-run lab hardware calibrate") from None
    if d.get("format") != FILE_FORMAT:
        raise ConfigError(f'{path}: not a mount calibration (format must be "{FILE_FORMAT}")')
    if d.get("version") != FILE_VERSION:
        raise ConfigError(
            f"{path}: version {d.get('version')!r} is not supported (this lab reads version {FILE_VERSION}); "
            "re-run lab hardware calibrate"
        )
    if not sep or not last.startswith("checksum") or d.get("checksum") != _checksum(body + "\n"):
        raise ConfigError(
            f"{path}: checksum does not match the content (a truncated or edited file); re-run lab hardware "
            "calibrate"
        )
    try:
        std = d["std_deg"]
        return HeadMounts(
            head_rpy=tuple(np.radians(d["head_rpy_deg"]).tolist()),
            camera_rpy=tuple(np.radians(d["camera_rpy_deg"]).tolist()),
            pan_zero=math.radians(d["pan_zero_deg"]),
            tilt_zero=math.radians(d["tilt_zero_deg"]),
            std={n: np.radians(std[n]).tolist() for n in _ANGLES},
            estimated=tuple(str(s) for s in d["estimated"]),
            robot=str(d["robot"]),
            created=str(d["created"]),
        )
    except ConfigError as e:
        raise ConfigError(f"{path}: {e}") from None
    except (KeyError, TypeError, ValueError) as e:
        raise ConfigError(
            f"{path}: missing or malformed field ({e}); re-run lab hardware calibrate"
        ) from None
