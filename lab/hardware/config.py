"""The robot's hardware configuration: a TOML file read into frozen dataclasses, strictly.

``hardware/robot.toml`` describes the real robot, ``hardware/emulated.toml`` the emulators. The loader
rejects a missing file, an unknown section or key, a wrong type and an impossible value with one
:class:`~lab.errors.ConfigError` line that names the file, the key and what is allowed. Relative paths
(calibration file, replay folder) are resolved against the config file's folder.

Degrees appear only here, at the edge, with ``_deg`` in their names; the drivers get radians.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from lab.errors import ConfigError
from lab.hardware.open_interface import PACKETS, REQUIRED_STREAM

__all__ = [
    "BaseConfig",
    "CameraConfig",
    "HardwareConfig",
    "PTUConfig",
    "RobotConfig",
    "RoomConfig",
    "SimSceneConfig",
    "load_config",
]

CREATE_BAUDS = (115200, 19200)
PTU_BAUDS = (9600, 19200, 38400, 57600, 115200)
CAMERA_SOURCES = ("side_by_side", "two_devices", "replay", "synthetic", "sim")


@dataclass(frozen=True)
class RobotConfig:
    """``[robot]``: name, watchdog and servo loop."""

    name: str = "robot"
    cmd_timeout_s: float = 0.5
    servo_rate_hz: float = 50.0
    install_sigint_handler: bool = True


@dataclass(frozen=True)
class BaseConfig:
    """``[base]``: the iRobot Create 2 and the limits the adapter enforces on it."""

    port: str = ""
    baudrate: int = 115200
    mode: str = "safe"
    max_speed: float = 0.5  # [m/s] per wheel and forward
    max_turn_rate: float = 1.5  # [rad/s]
    max_accel: float = 0.5  # [m/s^2]
    max_turn_accel: float = 3.0  # [rad/s^2]
    wheel_base: float = 0.235  # [m]
    wheel_diameter: float = 0.072  # [m]
    ticks_per_rev: float = 508.8
    radius: float = 0.17  # [m] footprint
    stale_timeout_s: float = 0.1
    first_frame_timeout_s: float = 0.5
    connect_attempts: int = 10
    # the sensor packets streamed; without the optional ones (25, 26 battery, 34 charger) the driver falls
    # back to the required set when the device streams only what it knows
    stream_packets: tuple = (7, 9, 10, 11, 12, 25, 26, 34, 35, 43, 44)


@dataclass(frozen=True)
class PTUConfig:
    """``[ptu]``: the PTU-D46; signs and zero offsets map the unit's axes onto ours."""

    port: str = ""
    baudrate: int = 9600
    timeout_s: float = 1.0
    banner_wait_s: float = 0.6
    pan_sign: int = 1
    tilt_sign: int = 1
    pan_zero_offset_deg: float = 0.0
    tilt_zero_offset_deg: float = 0.0
    speed_deg_s: float = 60.0
    move_margin_s: float = 1.0


@dataclass(frozen=True)
class CameraConfig:
    """``[camera]``: the stereo source, its calibration file and its mounting on the pan-tilt."""

    source: str = "side_by_side"
    device: int | str = 0
    devices: tuple = (0, 1)
    width: int = 1280
    height: int = 720
    swap_lr: bool = False
    fourcc: str = "MJPG"
    flush_grabs: int = 4
    calibration: str = ""
    folder: str = ""
    mount_R: tuple = (0.0, 0.0, 0.8)
    camera_offset_P: tuple = (0.05, 0.06, 0.0)
    mounts: str = ""  # the head's mount calibration (lab/mounts.py), written by lab hardware calibrate
    blur_sigma_px: float = 0.0  # the rectified images' blur [px] as measured (lab.robot.StereoCamera); 0: not
    # how far the head's and the camera's brackets may turn the camera, one sd [deg]: 0.2-1 deg for a bracket
    # mounted by hand; 0.7 is the simulator's realistic statement (0.5 deg each, lab.sim.room_errors)
    mount_sigma_deg: float = 0.7


@dataclass(frozen=True)
class SimSceneConfig:
    """``[sim]``: the world a ``source = "sim"`` camera renders (a rehearsal, :mod:`lab.runs.rehearsal`).

    Poses are ``[x, y, heading_deg]`` in the world frame W: ``robot_start`` is where the base stands when
    the Create emulator's true pose is (0, 0, 0); ``carrier_start`` is where the box's carrier stands.
    ``head_mount_deg`` and ``camera_mount_deg`` (roll, pitch, yaw [deg]) rotate the rendered camera as a
    real head's mounts would (:func:`lab.mounts.mounted_G_RC`): what ``lab hardware calibrate`` recovers
    in a rehearsal; the robot's kinematics do not know them.
    """

    world: str = "arena"
    robot_start: tuple = (-1.2, 0.0, 0.0)
    carrier_start: tuple = (0.0, 0.0, 0.0)
    supersample: int = 1
    head_mount_deg: tuple = (0.0, 0.0, 0.0)
    camera_mount_deg: tuple = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class RoomConfig:
    """``[room]``: the room the robot localizes in (``lab --localization landmarks``).

    Attributes
    ----------
    landmarks : str
        The room's landmark map (``hardware/landmarks.toml``: the posters on its walls and their measured
        poses, :func:`lab.training.landmarks.load_landmark_map`), relative to the config file; empty: none
        (a rehearsal then uses the posters of the scene it renders, a real robot odometry alone).
    start : tuple of 3 floats, or ()
        ``[x_m, y_m, heading_deg]``: where the base stands in the room's frame when it starts (its wheel
        odometry reads (0, 0, 0) there); empty: the scene's start (``[robot] start`` of the search's room,
        a rehearsal's ``[sim] robot_start``).
    start_sigma : tuple of 2 floats
        ``[sigma_m, sigma_deg]``: how well the start was measured (one standard deviation of each position
        coordinate and of the heading), the localizer's initial covariance.
    survey : str
        The room surveyed once (``lab survey``'s file, :mod:`lab.localization.stored_survey`), relative to
        the config file: ``lab survey --robot CONFIG`` writes it there, and every run that localizes on
        the landmarks starts from its refined posters, as with ``--survey``. Empty: the map's survey.
    """

    landmarks: str = ""
    start: tuple = ()
    start_sigma: tuple = (0.10, 5.0)
    survey: str = ""


@dataclass(frozen=True)
class HardwareConfig:
    """The whole file. ``path`` is where it was read from (None when built in code)."""

    robot: RobotConfig = field(default_factory=RobotConfig)
    base: BaseConfig = field(default_factory=BaseConfig)
    ptu: PTUConfig = field(default_factory=PTUConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    sim: SimSceneConfig = field(default_factory=SimSceneConfig)
    room: RoomConfig = field(default_factory=RoomConfig)
    path: Path | None = None

    def with_ports(self, *, base: str | None = None, ptu: str | None = None) -> HardwareConfig:
        """A copy with other serial ports (e.g. the emulators' pty paths)."""
        b = self.base if base is None else dataclasses.replace(self.base, port=base)
        p = self.ptu if ptu is None else dataclasses.replace(self.ptu, port=ptu)
        return dataclasses.replace(self, base=b, ptu=p)


_SECTIONS = {
    "robot": RobotConfig,
    "base": BaseConfig,
    "ptu": PTUConfig,
    "camera": CameraConfig,
    "sim": SimSceneConfig,
    "room": RoomConfig,
}
_REQUIRED = {
    ("base", "port"): '"/dev/ttyUSB0"',
    ("ptu", "port"): '"/dev/ttyUSB1"',
    ("camera", "calibration"): '"calibration/stereo.yml"',
}


def _type_ok(value: Any, default: Any, key: str) -> bool:
    if key == "device":
        return isinstance(value, (int, str)) and not isinstance(value, bool)
    if isinstance(default, bool):
        return isinstance(value, bool)
    if isinstance(default, int):
        return isinstance(value, int) and not isinstance(value, bool)
    if isinstance(default, float):
        return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    if isinstance(default, str):
        return isinstance(value, str)
    if isinstance(default, tuple):
        return isinstance(value, list)
    return True


def _type_name(default: Any, key: str) -> str:
    if key == "device":
        return "an integer index or a device path string"
    return {bool: "true or false", int: "an integer", float: "a number", str: "a string", tuple: "a list"}[
        type(default)
    ]


def load_config(path: str | Path) -> HardwareConfig:
    """Read and check a hardware TOML file.

    Raises
    ------
    ConfigError
        One line naming the file, the section and key, and what is allowed.
    """
    path = Path(path)
    if not path.is_file():
        raise ConfigError(
            f"hardware config {path} not found (examples: hardware/robot.toml, hardware/emulated.toml)"
        )
    try:
        data = tomllib.loads(path.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise ConfigError(f"{path}: not valid TOML ({e})") from e
    where = str(path)
    sections = {}
    for name, value in data.items():
        if name not in _SECTIONS:
            raise ConfigError(
                f"{where}: unknown section [{name}]; allowed: {', '.join(f'[{s}]' for s in _SECTIONS)}"
            )
        if not isinstance(value, dict):
            raise ConfigError(f"{where}: {name} must be a [{name}] table")
        cls = _SECTIONS[name]
        defaults = {
            f.name: (f.default if f.default is not dataclasses.MISSING else None)
            for f in dataclasses.fields(cls)
        }
        kwargs = {}
        for key, v in value.items():
            if key not in defaults:
                raise ConfigError(f"{where}: unknown key [{name}] {key!r}; allowed: {', '.join(defaults)}")
            if not _type_ok(v, defaults[key], key):
                raise ConfigError(
                    f"{where}: [{name}] {key} must be {_type_name(defaults[key], key)}, got {v!r}"
                )
            if isinstance(defaults[key], float):
                v = float(v)
            if isinstance(defaults[key], tuple):
                v = tuple(v)
            kwargs[key] = v
        sections[name] = kwargs
    for (sec, key), example in _REQUIRED.items():
        if not sections.get(sec, {}).get(key):
            raise ConfigError(f"{where}: [{sec}] {key} is required (e.g. {key} = {example})")
    cfg = HardwareConfig(**{n: _SECTIONS[n](**sections.get(n, {})) for n in _SECTIONS}, path=path)
    _check_values(cfg, where)
    return _resolve_paths(cfg, path.parent)


def _check_values(c: HardwareConfig, where: str) -> None:
    """Check every section's values, in file order; the first bad one is a ConfigError naming ``where``."""

    def need(ok: bool, msg: str):
        if not ok:
            raise ConfigError(f"{where}: {msg}")

    _check_robot(c.robot, need)
    _check_base(c.base, need)
    _check_ptu(c.ptu, need)
    _check_camera(c.camera, need)
    _check_sim(c.sim, c.camera, need)
    _check_room(c.room, need)


def _check_robot(r: RobotConfig, need) -> None:
    need(
        0.05 <= r.cmd_timeout_s <= 2.0,
        f"[robot] cmd_timeout_s must be within [0.05, 2] s, got {r.cmd_timeout_s}",
    )
    need(5 <= r.servo_rate_hz <= 500, f"[robot] servo_rate_hz must be within [5, 500], got {r.servo_rate_hz}")


def _check_base(b: BaseConfig, need) -> None:
    need(
        b.baudrate in CREATE_BAUDS,
        f"[base] baudrate {b.baudrate} is not a Create 2 rate; allowed: 115200 (default) or 19200",
    )
    need(b.mode in ("safe", "full"), f'[base] mode must be "safe" or "full", got {b.mode!r}')
    need(
        0 < b.max_speed <= 0.5,
        f"[base] max_speed must be within (0, 0.5] m/s (the Create 2's limit), got {b.max_speed}",
    )
    for k in (
        "max_turn_rate",
        "max_accel",
        "max_turn_accel",
        "wheel_base",
        "wheel_diameter",
        "ticks_per_rev",
        "radius",
        "stale_timeout_s",
        "first_frame_timeout_s",
    ):
        need(getattr(b, k) > 0, f"[base] {k} must be > 0, got {getattr(b, k)}")
    need(
        1 <= b.connect_attempts <= 50,
        f"[base] connect_attempts must be within [1, 50], got {b.connect_attempts}",
    )
    sp = b.stream_packets
    need(
        all(isinstance(i, int) and not isinstance(i, bool) and i in PACKETS for i in sp)
        and len(set(sp)) == len(sp),
        f"[base] stream_packets must be distinct sensor packet ids among {sorted(PACKETS)}, got {list(sp)}",
    )
    missing = [i for i in REQUIRED_STREAM if i not in sp]
    need(
        not missing,
        f"[base] stream_packets must include {list(REQUIRED_STREAM)} (safety, odometry); missing {missing}",
    )


def _check_ptu(p: PTUConfig, need) -> None:
    need(
        p.baudrate in PTU_BAUDS,
        f"[ptu] baudrate {p.baudrate} is not a PTU-D46 rate; allowed: {', '.join(map(str, PTU_BAUDS))} "
        "(9600 is the factory setting)",
    )
    need(p.pan_sign in (1, -1) and p.tilt_sign in (1, -1), "[ptu] pan_sign and tilt_sign must be 1 or -1")
    need(0 < p.timeout_s <= 10, f"[ptu] timeout_s must be within (0, 10] s, got {p.timeout_s}")
    need(0 <= p.banner_wait_s <= 5, f"[ptu] banner_wait_s must be within [0, 5] s, got {p.banner_wait_s}")
    need(p.speed_deg_s > 0, f"[ptu] speed_deg_s must be > 0, got {p.speed_deg_s}")
    need(p.move_margin_s >= 0, f"[ptu] move_margin_s must be >= 0, got {p.move_margin_s}")


def _check_camera(cam: CameraConfig, need) -> None:
    need(
        cam.source in CAMERA_SOURCES,
        f"[camera] source must be one of {', '.join(CAMERA_SOURCES)}; got {cam.source!r}",
    )
    need(
        cam.width >= 16 and cam.height >= 16,
        f"[camera] width and height must be >= 16 px, got {cam.width}x{cam.height}",
    )
    need(cam.flush_grabs >= 0, f"[camera] flush_grabs must be >= 0, got {cam.flush_grabs}")
    need(
        math.isfinite(cam.blur_sigma_px) and 0 <= cam.blur_sigma_px <= 5,
        f"[camera] blur_sigma_px must be within [0, 5] px, got {cam.blur_sigma_px}",
    )
    need(
        math.isfinite(cam.mount_sigma_deg) and 0 <= cam.mount_sigma_deg <= 5,
        f"[camera] mount_sigma_deg must be within [0, 5] deg, got {cam.mount_sigma_deg}",
    )
    need(
        len(cam.devices) == 2,
        f"[camera] devices must list two cameras (left, right), got {list(cam.devices)}",
    )
    for k in ("mount_R", "camera_offset_P"):
        v = getattr(cam, k)
        need(
            len(v) == 3 and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v),
            f"[camera] {k} must be 3 numbers [m], got {list(v)}",
        )
    need(cam.source != "replay" or bool(cam.folder), '[camera] folder is required when source = "replay"')


def _check_sim(sim: SimSceneConfig, cam: CameraConfig, need) -> None:
    for k in ("robot_start", "carrier_start"):
        v = getattr(sim, k)
        need(
            len(v) == 3 and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v),
            f"[sim] {k} must be [x_m, y_m, heading_deg], got {list(v)}",
        )
    need(sim.supersample in (1, 2, 3, 4), f"[sim] supersample must be 1, 2, 3 or 4, got {sim.supersample}")
    for k in ("head_mount_deg", "camera_mount_deg"):
        v = getattr(sim, k)
        ok = len(v) == 3 and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)
        need(
            ok and all(math.isfinite(x) and abs(x) <= 10 for x in v),
            f"[sim] {k} must be [roll, pitch, yaw] in degrees, each within [-10, 10], got {list(v)}",
        )
    if cam.source == "sim":
        from lab.scene import list_worlds

        worlds = list_worlds()
        need(sim.world in worlds, f"[sim] world {sim.world!r} is not a world; worlds: {', '.join(worlds)}")


def _check_room(room: RoomConfig, need) -> None:
    def numbers(v, n: int) -> bool:
        ok = len(v) == n and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)
        return ok and all(math.isfinite(x) for x in v)

    need(
        len(room.start) == 0 or numbers(room.start, 3),
        f"[room] start must be [x_m, y_m, heading_deg] (3 finite numbers), got {list(room.start)}",
    )
    need(
        numbers(room.start_sigma, 2) and min(room.start_sigma) > 0,
        f"[room] start_sigma must be [sigma_m, sigma_deg] (2 numbers > 0), got {list(room.start_sigma)}",
    )


def _resolve_paths(c: HardwareConfig, root: Path) -> HardwareConfig:
    cam = c.camera
    changes = {}
    for k in ("calibration", "folder", "mounts"):
        v = getattr(cam, k)
        if v and not Path(v).is_absolute():
            changes[k] = str((root / v).resolve())
    c = dataclasses.replace(c, camera=dataclasses.replace(cam, **changes)) if changes else c
    if c.room.landmarks:
        p = (root / c.room.landmarks).resolve()
        if not p.is_file():
            raise ConfigError(
                f"{c.path}: [room] landmarks {c.room.landmarks!r} not found (no file {p}; the room's "
                'landmark map, e.g. landmarks = "landmarks.toml" beside this file)'
            )
        c = dataclasses.replace(c, room=dataclasses.replace(c.room, landmarks=str(p)))
    if c.room.survey and not Path(c.room.survey).is_absolute():  # `lab survey` makes it: not checked here
        c = dataclasses.replace(
            c, room=dataclasses.replace(c.room, survey=str((root / c.room.survey).resolve()))
        )
    return c
