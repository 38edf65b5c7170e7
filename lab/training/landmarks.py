"""Landmark maps and their feature databases, from a scene file or from a measured landmark file.

In the simulator every ``poster`` body of a scene is a landmark: its world pose comes from the scene
file. On the real robot the same map comes from a file beside the robot config
(``hardware/landmarks.toml``): the classroom tapes printed posters to its walls and measures them once::

    room_size = [6.0, 8.0]            # floor extent [m], centred on the origin of the map
    wall_height = 2.5                 # [m]

    [[landmark]]
    name = "poster_north"
    texture = "../worlds/textures/poster0.png"   # the printed image (path relative to this file)
    size = [1.4, 0.02, 1.0]           # extent along the landmark's x, y, z [m]; one horizontal is thin
    centre = [0.0, 3.94, 1.5]         # the poster's centre in the room [m]
    yaw_deg = 0.0                     # rotation about z [deg]
    survey_sigma_m = 0.015            # optional, per landmark or once at the top for all: how well
    survey_sigma_deg = 0.7            # the centre (x, y each) and the yaw were measured (1 sigma)

With a survey sigma above 0 (:attr:`Landmark.survey_sigma_m`, ``survey_sigma_rad``) the localizer
carries the poster's pose in its state and refines it from its sightings, as it does the simulator's
surveyed map (:mod:`lab.localization.posters`); without one the map is taken as exact. A landmark's own
value overrides the file's.

A bad file (unknown key, missing or unreadable texture, duplicate name, a landmark outside the room)
raises :class:`~lab.errors.ConfigError` with one line naming the file and the field.

Each landmark's database is trained like an object's (:mod:`lab.training.databases`): the poster is
rendered alone from viewpoints in front of its face -- azimuths up to ``max_azimuth_deg`` off its
normal, at several distances, the range the robot sees it from in the room -- and the 3D SIFT features
on its face are moved into L with the known training pose and merged across views. Databases are
cached by the texture's and the parameters' hash (``<cache>/landmarks/v<FORMAT>/<name>-<hash>.npz``),
each written atomically, and each trained under a lock file beside it (``<name>-<hash>.npz.lock``).

The lock is there for a cold cache read by several processes at once -- two test workers
(pytest-xdist), or two workers of ``lab eval``: without it each would train every poster (seconds
each); with it they split the posters. A process trains the posters whose lock is free (reading the
cache again once it holds the lock), skips those another process is training, and at the end waits
for those and reads them from the cache (:func:`lab.training.cache.load_or_build_all`, the rule of
every training cache). The locks are the operating system's (:class:`filelock.FileLock`): a crashed
process's lock is freed with it, and the next process to take it trains that poster; a lock file
left on disk holds nothing.
"""

from __future__ import annotations

import hashlib
import json
import math
import tomllib
from dataclasses import asdict, dataclass, replace
from functools import partial
from pathlib import Path

import cv2
import numpy as np

from lab.errors import AssetError, ConfigError
from lab.geometry import Rz, se3, se3_inv, transform_points
from lab.localization import Landmark, LandmarkMap, inward_normal
from lab.paths import cache_dir
from lab.robot import SIM_CAMERA, StereoCamera
from lab.scene import BodySpec, Scene, load_scene
from lab.training.cache import Artefact, load_or_build_all
from lab.training.databases import TrainingParams, merge_view_features
from lab.vision.database import FORMAT_VERSION, FeatureDatabase, load_database, save_database
from lab.vision.stereo import StereoParams, sift, stereo_features

__all__ = [
    "LandmarkTraining",
    "landmark_map_from_scene",
    "load_landmark_map",
    "train_landmark_database",
    "trained_landmark_map",
]

_SURVEY_KEYS = {"survey_sigma_m": 0.5, "survey_sigma_deg": 30.0}  # each key's largest allowed value
_FILE_KEYS = {"room_size", "wall_height", "landmark", *_SURVEY_KEYS}
_LANDMARK_KEYS = {"name", "texture", "size", "centre", "yaw_deg", *_SURVEY_KEYS}


@dataclass(frozen=True)
class LandmarkTraining:
    """Settings of a landmark's training views.

    Attributes
    ----------
    distances_m : tuple of float [m]
        Distances from the poster's centre to the training cameras.
    max_azimuth_deg, step_deg : float [deg]
        The cameras stand at azimuths ``-max..max`` off the face normal, every ``step_deg``.
    face_margin_m : float [m]
        Features farther than this from the printed face's rectangle are dropped.
    supersample : int
        Render supersampling of the training views.
    """

    distances_m: tuple[float, ...] = (1.2, 2.4, 4.0)
    max_azimuth_deg: float = 60.0
    step_deg: float = 15.0
    face_margin_m: float = 0.02
    supersample: int = 2

    def viewpoints(self) -> np.ndarray:
        """(V, 2): azimuth off the normal [rad] and distance [m] of each training view."""
        az = np.radians(np.arange(-self.max_azimuth_deg, self.max_azimuth_deg + 1e-9, self.step_deg))
        return np.array([(a, r) for r in self.distances_m for a in az])


# --- the map ----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Poster:
    landmark: Landmark
    texture: Path


def _poster_of(b: BodySpec) -> _Poster:
    size = tuple(float(v) for v in b.size)
    lm = Landmark(b.name, tuple(b.centre), b.yaw, size, inward_normal(b.centre, b.yaw, size))
    return _Poster(lm, Path(b.texture))


def _posters_of_scene(scene: Scene) -> list[_Poster]:
    return [_poster_of(b) for b in scene.bodies if b.shape == "poster"]


def landmark_map_from_scene(scene: Scene | str = "lab_room") -> LandmarkMap:
    """The scene's posters as an (untrained) landmark map."""
    scene = scene if isinstance(scene, Scene) else load_scene(scene)
    size = scene.room.size if scene.room is not None else (12.0, 12.0)
    return LandmarkMap(
        tuple(p.landmark for p in _posters_of_scene(scene)), tuple(size), f"scene {scene.name}"
    )


def _numbers(v, n: int, where: str) -> tuple[float, ...]:
    if (
        not isinstance(v, list)
        or len(v) != n
        or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)
    ):
        raise ConfigError(f"{where}: expected a list of {n} numbers, got {v!r}")
    out = tuple(float(x) for x in v)
    if not all(math.isfinite(x) for x in out):
        raise ConfigError(f"{where}: expected finite numbers, got {v!r}")
    return out


def _survey_value(table: dict, key: str, where: str, default: float) -> float:
    """A survey sigma of ``table`` (``default`` when absent): a finite number in [0, its largest]."""
    v = table.get(key, default)
    hi = _SURVEY_KEYS[key]
    unit = "m" if key.endswith("_m") else "deg"
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and 0 <= v <= hi):
        raise ConfigError(
            f"{where}: the survey's standard deviation must be a number within [0, {hi:g}] {unit} "
            f"(0: exact), got {v!r}"
        )
    return float(v)


def _read_landmark_file(path: Path) -> tuple[list[_Poster], tuple[float, float]]:
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"landmark map {path} does not exist")
    try:
        d = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{path}: not valid TOML ({e})") from None
    unknown = set(d) - _FILE_KEYS
    if unknown:
        raise ConfigError(f"{path}: unknown key(s) {sorted(unknown)}; allowed: {sorted(_FILE_KEYS)}")
    if "room_size" not in d:
        raise ConfigError(f"{path}: missing required key 'room_size' ([x, y] extent of the floor, m)")
    room = _numbers(d["room_size"], 2, f"{path} room_size")
    if min(room) <= 0:
        raise ConfigError(f"{path} room_size: both extents must be > 0 m, got {list(room)}")
    wall_height = float(d.get("wall_height", 2.5))
    survey = {k: _survey_value(d, k, f"{path} {k}", 0.0) for k in _SURVEY_KEYS}
    entries = d.get("landmark", [])
    if not isinstance(entries, list) or not entries:
        raise ConfigError(f"{path}: needs at least one [[landmark]] table")
    out: list[_Poster] = []
    seen: set[str] = set()
    for i, e in enumerate(entries):
        where = f"{path} landmark[{i}]"
        if not isinstance(e, dict):
            raise ConfigError(f"{where}: expected a table, got {e!r}")
        bad = set(e) - _LANDMARK_KEYS
        if bad:
            raise ConfigError(f"{where}: unknown key(s) {sorted(bad)}; allowed: {sorted(_LANDMARK_KEYS)}")
        for k in ("name", "texture", "size", "centre"):
            if k not in e:
                raise ConfigError(f"{where}: missing required key {k!r}")
        name = e["name"]
        if not isinstance(name, str) or not name:
            raise ConfigError(f"{where} name: expected a non-empty string, got {name!r}")
        if name in seen:
            raise ConfigError(f"{where} name: duplicate landmark name {name!r} (names must be unique)")
        seen.add(name)
        where = f"{path} landmark[{i}] ({name})"
        tex = e["texture"]
        if not isinstance(tex, str):
            raise ConfigError(f"{where} texture: expected a file path string, got {tex!r}")
        tex_path = (path.parent / tex).resolve()
        if not tex_path.is_file():
            raise ConfigError(f"{where} texture: unknown texture {tex!r} (no file {tex_path})")
        if cv2.imread(str(tex_path)) is None:
            raise ConfigError(f"{where} texture: {tex!r} is not a readable image (PNG or JPEG)")
        size = _numbers(e["size"], 3, f"{where} size")
        if min(size) <= 0:
            raise ConfigError(f"{where} size: all three extents must be > 0 m, got {list(size)}")
        centre = _numbers(e["centre"], 3, f"{where} centre")
        yaw_deg = e.get("yaw_deg", 0.0)
        if isinstance(yaw_deg, bool) or not isinstance(yaw_deg, (int, float)) or not math.isfinite(yaw_deg):
            raise ConfigError(f"{where} yaw_deg: expected a finite number of degrees, got {yaw_deg!r}")
        hx, hy = 0.5 * room[0], 0.5 * room[1]
        if not (abs(centre[0]) <= hx and abs(centre[1]) <= hy and 0.0 <= centre[2] <= wall_height):
            raise ConfigError(
                f"{where} centre: {list(centre)} is outside the room (x within +-{hx:g} m, "
                f"y within +-{hy:g} m, z within [0, {wall_height:g}] m)"
            )
        yaw = math.radians(float(yaw_deg))
        sm, sd = (_survey_value(e, k, f"{where} {k}", survey[k]) for k in _SURVEY_KEYS)
        lm = Landmark(name, centre, yaw, size, inward_normal(centre, yaw, size), None, sm, math.radians(sd))
        out.append(_Poster(lm, tex_path))
    return out, room


def load_landmark_map(path: str | Path) -> LandmarkMap:
    """A measured landmark map (see the module docstring), validated but not trained."""
    posters, room = _read_landmark_file(Path(path))
    return LandmarkMap(tuple(p.landmark for p in posters), room, str(path))


# --- training ---------------------------------------------------------------------------------------


def _asset_hash(p: _Poster, params: LandmarkTraining, camera: StereoCamera) -> str:
    h = hashlib.sha256()
    h.update(json.dumps([list(p.landmark.size), list(p.landmark.normal_W)]).encode())
    h.update(p.texture.read_bytes())
    h.update(json.dumps(asdict(params), sort_keys=True, default=list).encode())
    cam, stereo = asdict(camera), asdict(StereoParams())
    del stereo["parallel"]
    if cam["blur_sigma_px"] == 0:  # a sharp camera (the simulator's): nothing is sharpened, and the
        del cam["blur_sigma_px"], stereo["sift_blur_px"], stereo["sharpen"]  # hash is as before the blur
    h.update(json.dumps(cam, sort_keys=True, default=list).encode())
    h.update(json.dumps(stereo, sort_keys=True).encode())
    h.update(f"landmark-{FORMAT_VERSION}".encode())
    return h.hexdigest()[:32]


def train_landmark_database(
    poster: _Poster, params: LandmarkTraining | None = None, camera: StereoCamera | None = None
) -> FeatureDatabase:
    """Render the poster alone from its training views and keep the 3D SIFT features on its face, in L."""
    from lab.sim import RenderSettings, SimWorld, viewpoint_G_WC  # only when rendering

    params = params or LandmarkTraining()
    cam = camera or SIM_CAMERA.camera()
    lm = poster.landmark
    centre_z = 1.5
    # the poster at the origin of a bare floor, with its own yaw: then L = G_WL below and its normal
    # is the map's
    spec = BodySpec(
        lm.name,
        "poster",
        lm.size,
        (0.0, 0.0, centre_z - lm.size[2] / 2, math.degrees(lm.yaw)),
        texture=poster.texture,
    )
    scene = replace(load_scene("box_database"), bodies=(spec,), models=())
    G_WL = se3(Rz(lm.yaw), (0.0, 0.0, centre_z))
    n = np.array([*lm.normal_W, 0.0])
    side = np.array([-n[1], n[0], 0.0])
    half = 0.5 * np.asarray(lm.size)
    n_L = se3_inv(G_WL)[:3, :3] @ n
    thin = int(np.argmax(np.abs(n_L[:2])))
    stereo_params = StereoParams()
    det = sift(stereo_params.n_features, stereo_params.contrast_threshold)
    tp = TrainingParams()  # the objects' merge thresholds
    points, descs, seen, counts = [], [], [], []
    views = params.viewpoints()
    with SimWorld(scene, RenderSettings(supersample=params.supersample)) as world:
        centre = G_WL[:3, 3]
        for v, (az, r) in enumerate(views):
            eye = centre + r * (math.cos(az) * n + math.sin(az) * side)
            G_WC = viewpoint_G_WC(eye, centre)
            left, right = world.render_stereo(G_WC, cam)
            f = stereo_features(left, right, cam, stereo_params, detector=det)
            if len(f) == 0:
                continue
            p_L = transform_points(se3_inv(G_WL) @ G_WC, f.points_C)
            on_face = np.abs(p_L[:, thin] - np.sign(n_L[thin]) * half[thin]) <= params.face_margin_m
            inside = np.all(
                np.abs(np.delete(p_L, thin, axis=1)) <= np.delete(half, thin) - params.face_margin_m, axis=1
            )
            keep = on_face & inside
            merge_view_features(points, descs, seen, counts, p_L[keep], f.descriptors[keep], v, tp)
    N, V = len(points), len(views)
    seen_from = np.zeros((N, V), bool)
    for i, s in enumerate(seen):
        seen_from[i, sorted(s)] = True
    meta = {
        "format_version": FORMAT_VERSION,
        "name": lm.name,
        "kind": "landmark",
        "asset_hash": _asset_hash(poster, params, cam),
        "params": asdict(params),
        "camera": asdict(cam),
    }
    return FeatureDatabase(
        lm.name,
        np.array(points, dtype=np.float64).reshape(-1, 3),
        np.array(descs, dtype=np.float32).reshape(-1, 128),
        seen_from,
        views,
        np.asarray(lm.size, dtype=np.float64),
        np.full((1, 1), 1.0, np.float32),
        meta,
    )


def _path(name: str, asset_hash: str, folder: Path | None) -> Path:
    # the hash in the name: two worlds may have posters of one name but other sizes or images
    return Path(folder or cache_dir() / "landmarks") / f"v{FORMAT_VERSION}" / f"{name}-{asset_hash[:12]}.npz"


def _load_cached(path: Path, name: str, want: str) -> tuple[FeatureDatabase | None, str]:
    """The database cached at ``path`` when it was trained for hash ``want``; else None and why not."""
    try:
        db = load_database(path, name)
        if db.meta.get("asset_hash") == want:
            return db, ""
        return None, "its texture, pose or training parameters changed"
    except AssetError as e:
        return None, "it is not in the cache" if not path.is_file() else str(e)


def _cached_databases(posters: list[_Poster], params, camera, folder, progress: bool, train) -> list:
    """Each poster's database, from the cache or trained. Processes on one cold cache split the posters
    (:func:`lab.training.cache.load_or_build_all`)."""
    cached = []
    for p in posters:
        name, want = p.landmark.name, _asset_hash(p, params, camera)
        path = _path(name, want, folder)
        cached.append(
            Artefact(
                path,
                f"the landmark database of {name}",
                partial(_load_cached, path, name, want),
                partial(train, p, params, camera),
                save_database,
            )
        )
    return load_or_build_all(cached, progress)


def trained_landmark_map(
    source: Scene | str | Path = "lab_room",
    params: LandmarkTraining | None = None,
    camera: StereoCamera | None = None,
    folder: Path | None = None,
    progress: bool = True,
    _train=train_landmark_database,  # tests: a stand-in trainer
) -> LandmarkMap:
    """The landmark map of a scene (name or Scene) or of a landmark file (``*.toml`` path other than a
    scene), each landmark with its (cached) database."""
    params = params or LandmarkTraining()
    camera = camera or SIM_CAMERA.camera()
    if (
        isinstance(source, (str, Path))
        and str(source).endswith(".toml")
        and Path(source).is_file()
        and ("landmark" in tomllib.loads(Path(source).read_text()))
    ):
        posters, room = _read_landmark_file(Path(source))
        where = str(source)
    else:
        scene = source if isinstance(source, Scene) else load_scene(source)
        posters = _posters_of_scene(scene)
        room = scene.room.size if scene.room is not None else (12.0, 12.0)
        where = f"scene {scene.name}"
    dbs = _cached_databases(posters, params, camera, folder, progress, _train)
    lms = tuple(replace(p.landmark, database=db) for p, db in zip(posters, dbs, strict=True))
    return LandmarkMap(lms, tuple(room), where)
