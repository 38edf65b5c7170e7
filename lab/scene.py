"""Scene files: readable TOML descriptions of a world, parsed and validated into frozen dataclasses.

A scene file (``worlds/<name>.toml``) holds::

    name = "lab_room"
    description = "..."

    [room]                          # optional: a floor and four walls around the origin
    size = [6.0, 8.0]               # x and y extent [m]
    wall_height = 2.5
    floor_texture = "textures/floor.png"
    wall_texture = "textures/wall.png"

    [robot]
    start = [0.0, -3.0, 90.0]       # x [m], y [m], heading [deg] of the observing robot
    mast_height = 1.1               # height of the pan-tilt axes above the floor [m] (default 0.7)

    [[body]]
    name = "table_a"                # unique; how code and tests address the body
    shape = "table"                 # box | cylinder | table | shelf | textured_box | poster
    size = [1.2, 0.6, 0.75]         # box-like: x, y, z [m]; cylinder: [radius, height]
    pose = [2.0, 2.5, 0.0, 0.0]     # x, y of the centre [m], z of the UNDERSIDE [m], yaw [deg]
    color = [0.5, 0.35, 0.2]        # RGB in [0, 1] (plain shapes)
    texture = "textures/wood.png"   # tiled texture (box, table, shelf, poster)
    atlas = "textures/book.png"     # per-face atlas (textured_box)
    role = "furniture"              # furniture | obstacle | distractor | object | decor
    supports = true                 # objects may be placed on it (tables, shelves, floor-standing boxes)

``pose`` puts the underside at ``z`` so that an object on a table has ``z = 0.75``; the object frame O
is the body's centre (``z + height / 2``), see ``docs/conventions.md``.

Paths are relative to the scene file's folder. Unknown keys, shapes or roles, missing files and
malformed values raise :class:`~lab.errors.ConfigError` naming the file, the field and what is allowed.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path

from lab.errors import AssetError, ConfigError
from lab.paths import worlds_dir

__all__ = ["BodySpec", "RoomSpec", "Scene", "list_worlds", "load_scene", "SHAPES", "ROLES"]

SHAPES = ("box", "cylinder", "table", "shelf", "textured_box", "poster")
ROLES = ("furniture", "obstacle", "distractor", "object", "decor")
_BODY_KEYS = {"name", "shape", "size", "pose", "color", "texture", "atlas", "role", "supports", "description"}
_ROOM_KEYS = {"size", "wall_height", "wall_thickness", "floor_texture", "wall_texture", "tile_m"}
_TOP_KEYS = {"name", "description", "room", "robot", "body", "model"}
_MODEL_KEYS = {"name", "size", "atlas", "unique_face"}


@dataclass(frozen=True)
class BodySpec:
    """One body of a scene (see the module docstring for the fields)."""

    name: str
    shape: str
    size: tuple[float, ...]
    pose: tuple[float, float, float, float]  # x, y, z_underside [m], yaw [deg]
    role: str = "decor"
    color: tuple[float, float, float] = (0.7, 0.7, 0.7)
    texture: Path | None = None
    atlas: Path | None = None
    supports: bool = False
    description: str = ""

    @property
    def height(self) -> float:
        return self.size[1] if self.shape == "cylinder" else self.size[2]

    @property
    def centre(self) -> tuple[float, float, float]:
        """The body frame's origin (its centre) in the world [m]."""
        x, y, z, _ = self.pose
        return (x, y, z + 0.5 * self.height)

    @property
    def yaw(self) -> float:
        return math.radians(self.pose[3])

    @property
    def footprint_radius(self) -> float:
        """Radius of a circle that covers the body's footprint [m]."""
        if self.shape == "cylinder":
            return self.size[0]
        return 0.5 * math.hypot(self.size[0], self.size[1])


@dataclass(frozen=True)
class RoomSpec:
    size: tuple[float, float]
    wall_height: float = 2.5
    wall_thickness: float = 0.1
    floor_texture: Path | None = None
    wall_texture: Path | None = None
    tile_m: float = 1.0


@dataclass(frozen=True)
class ModelSpec:
    """A box model of the identification database: its size, atlas and which face is unique."""

    name: str
    size: tuple[float, float, float]
    atlas: Path
    unique_face: str = "+X"


@dataclass(frozen=True)
class Scene:
    name: str
    path: Path
    description: str = ""
    room: RoomSpec | None = None
    robot_start: tuple[float, float, float] = (0.0, 0.0, 0.0)  # x, y [m], heading [deg]
    robot_mast_height: float = 0.7  # height of the robot's pan-tilt axes above the floor [m]
    bodies: tuple[BodySpec, ...] = ()
    models: tuple[ModelSpec, ...] = field(default=())

    def body(self, name: str) -> BodySpec:
        for b in self.bodies:
            if b.name == name:
                return b
        raise ConfigError(f"scene {self.name!r} has no body {name!r}; bodies: {', '.join(self.names())}")

    def names(self, role: str | None = None) -> list[str]:
        return [b.name for b in self.bodies if role is None or b.role == role]

    def with_pose(self, name: str, pose) -> Scene:
        """The same scene with body ``name`` moved to ``pose = (x, y, z_underside, yaw_deg)``."""
        pose = _floats(pose, 4, f"{self.path}: pose of {name}")
        self.body(name)  # raises with the list of names
        bodies = tuple(replace(b, pose=pose) if b.name == name else b for b in self.bodies)
        return replace(self, bodies=bodies)


def list_worlds() -> list[str]:
    """Names of the scene files in the worlds folder."""
    return sorted(p.stem for p in worlds_dir().glob("*.toml"))


def _floats(v, n, where) -> tuple[float, ...]:
    if not isinstance(v, (list, tuple)) or (n is not None and len(v) != n):
        raise ConfigError(f"{where}: expected a list of {n} numbers, got {v!r}")
    out = []
    for x in v:
        if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
            raise ConfigError(f"{where}: expected finite numbers, got {v!r}")
        out.append(float(x))
    return tuple(out)


def _asset(base: Path, rel, where) -> Path:
    if not isinstance(rel, str):
        raise ConfigError(f"{where}: expected a file path string, got {rel!r}")
    p = (base / rel).resolve()
    if not p.is_file():
        raise AssetError(f"{where}: file {p} does not exist")
    return p


def _check_keys(d: dict, allowed: set, where: str) -> None:
    unknown = set(d) - allowed
    if unknown:
        raise ConfigError(f"{where}: unknown key(s) {sorted(unknown)}; allowed: {sorted(allowed)}")


def _parse_body(d: dict, base: Path, where: str) -> BodySpec:
    if not isinstance(d, dict):
        raise ConfigError(f"{where}: expected a table, got {d!r}")
    _check_keys(d, _BODY_KEYS, where)
    for k in ("name", "shape", "size", "pose"):
        if k not in d:
            raise ConfigError(f"{where}: missing required key {k!r}")
    name = d["name"]
    if not isinstance(name, str) or not name:
        raise ConfigError(f"{where}: name must be a non-empty string")
    where = f"{where} ({name})"
    shape = d["shape"]
    if shape not in SHAPES:
        raise ConfigError(f"{where}: shape {shape!r} is not one of {', '.join(SHAPES)}")
    size = _floats(d["size"], 2 if shape == "cylinder" else 3, f"{where}: size")
    if any(s <= 0 for s in size):
        raise ConfigError(f"{where}: size must be positive, got {list(size)}")
    role = d.get("role", "decor")
    if role not in ROLES:
        raise ConfigError(f"{where}: role {role!r} is not one of {', '.join(ROLES)}")
    color = _floats(d.get("color", [0.7, 0.7, 0.7]), 3, f"{where}: color")
    if any(not 0 <= c <= 1 for c in color):
        raise ConfigError(f"{where}: color components must be within [0, 1], got {list(color)}")
    texture = _asset(base, d["texture"], f"{where}: texture") if "texture" in d else None
    atlas = _asset(base, d["atlas"], f"{where}: atlas") if "atlas" in d else None
    if shape == "textured_box" and atlas is None:
        raise ConfigError(f"{where}: shape 'textured_box' needs an 'atlas' texture")
    if shape == "poster" and texture is None:
        raise ConfigError(f"{where}: shape 'poster' needs a 'texture'")
    return BodySpec(
        name=name,
        shape=shape,
        size=size,
        pose=_floats(d["pose"], 4, f"{where}: pose"),
        role=role,
        color=color,
        texture=texture,
        atlas=atlas,
        supports=bool(d.get("supports", False)),
        description=str(d.get("description", "")),
    )


def load_scene(name_or_path: str | Path) -> Scene:
    """Read and validate a scene by world name (``"lab_room"``) or by path to a ``.toml`` file."""
    p = Path(name_or_path)
    if p.suffix != ".toml":
        p = worlds_dir() / f"{name_or_path}.toml"
        if not p.is_file():
            raise ConfigError(f"unknown world {str(name_or_path)!r}; available: {', '.join(list_worlds())}")
    if not p.is_file():
        raise AssetError(f"scene file {p} does not exist")
    try:
        d = tomllib.loads(p.read_text())
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{p}: not valid TOML ({e})") from None
    where = str(p)
    _check_keys(d, _TOP_KEYS, where)
    base = p.parent
    room = None
    if "room" in d:
        r = d["room"]
        _check_keys(r, _ROOM_KEYS, f"{where} [room]")
        if "size" not in r:
            raise ConfigError(f"{where} [room]: missing required key 'size'")
        room = RoomSpec(
            size=_floats(r["size"], 2, f"{where} [room] size"),
            wall_height=float(r.get("wall_height", 2.5)),
            wall_thickness=float(r.get("wall_thickness", 0.1)),
            floor_texture=_asset(base, r["floor_texture"], f"{where} [room] floor_texture")
            if "floor_texture" in r
            else None,
            wall_texture=_asset(base, r["wall_texture"], f"{where} [room] wall_texture")
            if "wall_texture" in r
            else None,
            tile_m=float(r.get("tile_m", 1.0)),
        )
    start = (0.0, 0.0, 0.0)
    mast = 0.7
    if "robot" in d:
        _check_keys(d["robot"], {"start", "mast_height"}, f"{where} [robot]")
        start = _floats(d["robot"].get("start", [0, 0, 0]), 3, f"{where} [robot] start")
        mast = _floats([d["robot"].get("mast_height", mast)], 1, f"{where} [robot] mast_height")[0]
        if not 0.4 <= mast <= 2.0:
            raise ConfigError(
                f"{where} [robot] mast_height: {mast} m is outside 0.4-2.0 m (the pan-tilt axes must "
                "stand above the 0.3 m base and below the ceiling)"
            )
    bodies = tuple(
        _parse_body(b, base, f"{where} [[body]] #{i + 1}") for i, b in enumerate(d.get("body", []))
    )
    names = [b.name for b in bodies]
    dup = {n for n in names if names.count(n) > 1}
    if dup:
        raise ConfigError(f"{where}: body names must be unique; repeated: {sorted(dup)}")
    models = []
    for i, m in enumerate(d.get("model", [])):
        w = f"{where} [[model]] #{i + 1}"
        _check_keys(m, _MODEL_KEYS, w)
        for k in ("name", "size", "atlas"):
            if k not in m:
                raise ConfigError(f"{w}: missing required key {k!r}")
        uf = m.get("unique_face", "+X")
        if uf not in ("+X", "-X", "+Y", "-Y"):
            raise ConfigError(f"{w}: unique_face {uf!r} is not one of +X, -X, +Y, -Y")
        models.append(
            ModelSpec(
                str(m["name"]), _floats(m["size"], 3, f"{w} size"), _asset(base, m["atlas"], f"{w} atlas"), uf
            )
        )
    return Scene(
        name=str(d.get("name", p.stem)),
        path=p,
        description=str(d.get("description", "")),
        room=room,
        robot_start=start,
        robot_mast_height=float(mast),
        bodies=bodies,
        models=tuple(models),
    )
