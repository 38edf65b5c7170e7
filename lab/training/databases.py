"""Training feature databases: render an object around its training ring and keep its 3D SIFT features.

Training (identification paper, Sec. III; search paper, Sec. III): the object is rendered from
viewpoints on an equatorial ring (every 10 degrees by default, about 1 m away, at the robot camera's
height). In each view, 3D SIFT features are extracted from the stereo pair and, with the *known*
training pose, moved into the object frame O; features outside the object's bounds are dropped.
Features seen again from another view (within ``merge_distance`` in O and with a close descriptor) are
merged, and each database feature remembers which ring viewpoints saw it (``seen_from``): the lookup
tables of the planning module need that. The colour model is the object's red-green chromaticity
histogram (search paper, Sec. III-B), accumulated over the same views.

The result is a :class:`~lab.vision.database.FeatureDatabase`. :func:`get_database` keeps them in a
versioned cache (``<cache>/databases/v<FORMAT>/<name>.npz``), rebuilding one whose textures or
training parameters changed, or whose file is corrupt, and saying so. Each is built under a lock file
beside it (:mod:`lab.training.cache`): processes that find the cache cold at once (test workers, the
workers of ``lab eval``) build each database once, and :func:`get_databases` splits a list of them.
"""

from __future__ import annotations

import hashlib
import json
import math
import sys
from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial import cKDTree

from lab.errors import AssetError, ConfigError
from lab.geometry import se3, se3_inv, transform_points
from lab.paths import cache_dir
from lab.robot import SIM_CAMERA, StereoCamera
from lab.scene import BodySpec, load_scene
from lab.training.cache import Artefact, load_or_build, load_or_build_all
from lab.vision.colour import colour_histogram
from lab.vision.database import FORMAT_VERSION, FeatureDatabase, load_database, save_database
from lab.vision.stereo import StereoParams, sift, stereo_features

__all__ = [
    "TrainingParams",
    "database_path",
    "get_database",
    "get_databases",
    "merge_view_features",
    "object_world",
    "train_database",
    "trainable_objects",
]


@dataclass(frozen=True)
class TrainingParams:
    """Settings of the training ring.

    Attributes
    ----------
    radius : float [m]
        Distance from the camera to the object's centre.
    step_deg : float
        Angle between ring viewpoints.
    elevations_deg : tuple of float
        Elevation of the camera above the object's centre; one ring per value.
    supersample : int
        Render the training views at this multiple and downsample (better 3D positions).
    merge_distance : float [m]
        Features closer than this in O, with descriptors closer than ``merge_descriptor``, are one.
    merge_descriptor : float
        L2 distance between SIFT descriptors (OpenCV scale, norms about 512) under which they merge.
    bounds_margin : float [m]
        Features farther than this from the object's surface are dropped (mismatches).
    edge_px : int [px]
        Keypoints closer than this to the object's outline are dropped (their descriptors mix in the
        background, and they match clutter).
    colour_space : str
        ``"rg"`` (red-green chromaticity, the paper's) or ``"hsv"`` (hue-saturation).
    hist_bins : int
    width, height : int [px]; fov_y_deg : float
        The training camera (the robot's).
    """

    radius: float = 1.0
    step_deg: float = 10.0
    elevations_deg: tuple[float, ...] = (12.0,)
    supersample: int = 2
    merge_distance: float = 0.01
    merge_descriptor: float = 200.0
    bounds_margin: float = 0.015
    edge_px: int = 4
    colour_space: str = "rg"
    hist_bins: int = 32
    width: int = SIM_CAMERA.width
    height: int = SIM_CAMERA.height
    fov_y_deg: float = SIM_CAMERA.fov_y_deg
    baseline: float = SIM_CAMERA.baseline

    def __post_init__(self):
        if not 0 < self.step_deg <= 180 or (360.0 / self.step_deg) % 1 > 1e-9:
            raise ConfigError(f"step_deg must divide 360 (e.g. 10, 15, 30), got {self.step_deg}")
        if not 0.2 <= self.radius <= 5.0:
            raise ConfigError(f"radius must be within [0.2, 5] m, got {self.radius}")
        if self.colour_space not in ("rg", "hsv"):
            raise ConfigError(f"colour_space must be 'rg' or 'hsv', got {self.colour_space!r}")

    @property
    def camera(self) -> StereoCamera:
        return StereoCamera.from_fov(self.width, self.height, self.fov_y_deg, self.baseline)

    def viewpoints(self) -> np.ndarray:
        """(V, 2) array of (azimuth, elevation) [rad] of the ring viewpoints, in the object frame."""
        az = np.radians(np.arange(0.0, 360.0, self.step_deg))
        return np.array([(a, math.radians(e)) for e in self.elevations_deg for a in az])


# --- what can be trained ----------------------------------------------------------------------------


@dataclass(frozen=True)
class _Trainable:
    name: str
    shape: str  # "box" or "cylinder"
    size: tuple[float, ...]
    texture: Path | None
    color: tuple[float, float, float]


def trainable_objects() -> dict[str, _Trainable]:
    """Objects with a database: the identification box models (M0..M3) and the lab room's objects."""
    out = {}
    for m in load_scene("box_database").models:
        out[m.name] = _Trainable(m.name, "box", m.size, m.atlas, (1, 1, 1))
    for b in load_scene("lab_room").bodies:
        if b.role == "object":
            shape = "cylinder" if b.shape == "cylinder" else "box"
            out[b.name] = _Trainable(b.name, shape, b.size, b.atlas, b.color)
    return out


def _asset_hash(obj: _Trainable, params: TrainingParams) -> str:
    h = hashlib.sha256()
    h.update(json.dumps([obj.name, obj.shape, list(obj.size), list(obj.color)]).encode())
    if obj.texture is not None:
        h.update(Path(obj.texture).read_bytes())
    h.update(json.dumps(asdict(params), sort_keys=True, default=list).encode())
    stereo = asdict(StereoParams())
    del stereo["parallel"]  # how the work is spread over threads: the same features either way
    del stereo["sift_blur_px"], stereo["sharpen"]  # training renders with a sharp camera (blur 0)
    h.update(json.dumps(stereo, sort_keys=True).encode())
    h.update(str(FORMAT_VERSION).encode())
    return h.hexdigest()[:32]


def object_world(obj: _Trainable, supersample: int):
    """A bare-floor world with the object alone, its centre at (0, 0, 0.49): returns (world, G_WO)."""
    from lab.sim import RenderSettings, SimWorld  # the simulator only when rendering: a cached
    # database loads without it

    scene = load_scene("box_database")
    centre_z = 0.49
    if obj.shape == "cylinder":
        spec = BodySpec(
            obj.name, "cylinder", obj.size, (0.0, 0.0, centre_z - obj.size[1] / 2, 0.0), "object", obj.color
        )
    else:
        spec = BodySpec(
            obj.name,
            "textured_box",
            obj.size,
            (0.0, 0.0, centre_z - obj.size[2] / 2, 0.0),
            "object",
            atlas=obj.texture,
        )
    world = SimWorld(replace(scene, bodies=(spec,), models=()), RenderSettings(supersample=supersample))
    return world, se3(None, (0.0, 0.0, centre_z))


def _on_surface(points_O: np.ndarray, obj: _Trainable, margin: float) -> np.ndarray:
    """Points within ``margin`` of the object's surface (one deep inside or far outside is a mismatch)."""
    if obj.shape == "cylinder":
        r, h = obj.size
        rho, z = np.hypot(points_O[:, 0], points_O[:, 1]), np.abs(points_O[:, 2])
        inside = (rho <= r + margin) & (z <= h / 2 + margin)
        near = (np.abs(rho - r) <= margin) | (np.abs(z - h / 2) <= margin)
        return inside & near
    half = 0.5 * np.asarray(obj.size)
    a = np.abs(points_O)
    inside = np.all(a <= half + margin, axis=1)
    near = np.any(np.abs(a - half) <= margin, axis=1)
    return inside & near


def _silhouette_mask(obj: _Trainable, G_CO: np.ndarray, camera: StereoCamera) -> np.ndarray:
    """Pixels covered by the object's (convex) outline, from its known pose: for the colour model."""
    if obj.shape == "cylinder":
        r, h = obj.size
        a = np.linspace(0, 2 * np.pi, 24, endpoint=False)
        ring = np.stack([r * np.cos(a), r * np.sin(a)], axis=1)
        pts = np.concatenate([np.c_[ring, np.full(24, -h / 2)], np.c_[ring, np.full(24, h / 2)]])
    else:
        s = 0.5 * np.asarray(obj.size)
        pts = np.array([[x, y, z] for x in (-s[0], s[0]) for y in (-s[1], s[1]) for z in (-s[2], s[2])])
    uv = camera.project(transform_points(G_CO, pts))
    hull = cv2.convexHull(np.round(uv).astype(np.int32))
    mask = np.zeros((camera.height, camera.width), np.uint8)
    cv2.fillConvexPoly(mask, hull, 255)
    return cv2.erode(mask, np.ones((3, 3), np.uint8))


def train_database(
    name: str, params: TrainingParams | None = None, progress: bool = False
) -> FeatureDatabase:
    """Build the feature database and colour model of object ``name`` from its training ring."""
    from lab.sim import viewpoint_G_WC

    params = params or TrainingParams()
    objects = trainable_objects()
    if name not in objects:
        raise ConfigError(f"unknown object {name!r}; trainable objects: {', '.join(objects)}")
    obj = objects[name]
    cam = params.camera
    stereo_params = StereoParams()
    det = sift(stereo_params.n_features, stereo_params.contrast_threshold)
    views = params.viewpoints()
    points: list[np.ndarray] = []
    descs: list[np.ndarray] = []
    seen: list[set[int]] = []
    counts: list[int] = []
    hist = None
    world, G_WO = object_world(obj, params.supersample)
    it = range(len(views))
    if progress:
        from tqdm import tqdm

        it = tqdm(it, desc=f"train {name}", unit="view", leave=False, file=sys.stderr, disable=None)
    with world:
        centre = G_WO[:3, 3]
        for v in it:
            az, el = views[v]
            eye = centre + params.radius * np.array(
                [math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)]
            )
            G_WC = viewpoint_G_WC(eye, centre)
            left, right = world.render_stereo(G_WC, cam)
            G_CO = se3_inv(G_WC) @ G_WO
            silhouette = _silhouette_mask(obj, G_CO, cam)
            h = colour_histogram(left, silhouette, params.colour_space, params.hist_bins)
            hist = h if hist is None else hist + h
            f = stereo_features(left, right, cam, stereo_params, detector=det)
            if len(f) == 0:
                continue
            p_O = transform_points(se3_inv(G_CO), f.points_C)
            # keypoints on the outline describe background as much as the object: keep the interior only
            interior = cv2.erode(silhouette, np.ones((2 * params.edge_px + 1,) * 2, np.uint8))
            u = np.clip(np.round(f.uv).astype(int), 0, [cam.width - 1, cam.height - 1])
            keep = _on_surface(p_O, obj, params.bounds_margin) & (interior[u[:, 1], u[:, 0]] > 0)
            merge_view_features(points, descs, seen, counts, p_O[keep], f.descriptors[keep], v, params)
    V = len(views)
    N = len(points)
    seen_from = np.zeros((N, V), bool)
    for i, s in enumerate(seen):
        seen_from[i, sorted(s)] = True
    hist = (hist / max(hist.sum(), 1e-12)).astype(np.float32)
    extent = np.array(obj.size if obj.shape == "box" else (2 * obj.size[0], 2 * obj.size[0], obj.size[1]))
    meta = {
        "format_version": FORMAT_VERSION,
        "name": name,
        "asset_hash": _asset_hash(obj, params),
        "params": asdict(params),
        "colour_space": params.colour_space,
        "camera": asdict(cam),
    }
    return FeatureDatabase(
        name,
        np.array(points, dtype=np.float64).reshape(-1, 3),
        np.array(descs, dtype=np.float32).reshape(-1, 128),
        seen_from,
        views,
        extent.astype(np.float64),
        hist,
        meta,
    )


def merge_view_features(points, descs, seen, counts, p_O, d, view, params: TrainingParams) -> None:
    """Merge one view's features into the growing database (a running mean of positions).

    ``points``, ``descs``, ``seen`` and ``counts`` are the database's growing lists (changed in place);
    ``p_O`` and ``d`` the view's points and descriptors, ``view`` its index among the views.
    """
    n_before = len(points)  # match against the database as it was before this view
    if n_before:
        tree = cKDTree(np.asarray(points))
        P = np.asarray(descs)
    for p, desc in zip(p_O, d, strict=True):
        target = -1
        if n_before:
            cand = tree.query_ball_point(p, params.merge_distance)
            if cand:
                dd = np.linalg.norm(P[cand] - desc, axis=1)
                k = int(np.argmin(dd))
                if dd[k] < params.merge_descriptor:
                    target = cand[k]
        if target >= 0:
            n = counts[target]
            points[target] = (points[target] * n + p) / (n + 1)
            counts[target] = n + 1
            seen[target].add(view)
        else:
            points.append(np.array(p, dtype=float))
            descs.append(np.array(desc, dtype=np.float32))
            seen.append({view})
            counts.append(1)


# --- the cache -------------------------------------------------------------------------------------


def database_path(name: str, folder: Path | None = None) -> Path:
    return Path(folder or cache_dir() / "databases") / f"v{FORMAT_VERSION}" / f"{name}.npz"


def _cached(name: str, obj: _Trainable, path: Path, params: TrainingParams, progress: bool) -> Artefact:
    """The database of ``name`` as an artefact of the cache (:mod:`lab.training.cache`)."""

    def load():
        try:
            db = load_database(path, name)
        except AssetError as e:
            return None, "it is not in the cache" if not path.is_file() else str(e)
        if db.meta.get("asset_hash") != _asset_hash(obj, params):
            return None, "its textures or training parameters changed"
        return db, ""

    return Artefact(
        path,
        f"the feature database of {name}",
        load,
        lambda: train_database(name, params, progress),
        save_database,
    )


def get_database(
    name: str,
    folder: Path | None = None,
    params: TrainingParams | None = None,
    rebuild: bool = False,
    progress: bool = True,
) -> FeatureDatabase:
    """The database of ``name`` from the cache; built (and cached) first when missing, stale or corrupt.

    A rebuild says so on stderr, with the reason. It is built under a lock file beside it
    (:func:`lab.training.cache.load_or_build`): a process that finds another building it waits, then
    reads that one's file.
    """
    params = params or TrainingParams()
    objects = trainable_objects()
    if name not in objects:
        raise ConfigError(f"unknown object {name!r}; trainable objects: {', '.join(objects)}")
    path = database_path(name, folder)
    return load_or_build(_cached(name, objects[name], path, params, progress), progress, rebuild)


def get_databases(
    names: Sequence[str],
    folder: Path | None = None,
    params: TrainingParams | None = None,
    progress: bool = True,
) -> list[FeatureDatabase]:
    """The databases of ``names``, in order, as :func:`get_database` gives each; processes that find the
    cache cold at once split the building (:func:`lab.training.cache.load_or_build_all`)."""
    params = params or TrainingParams()
    objects = trainable_objects()
    for n in names:
        if n not in objects:
            raise ConfigError(f"unknown object {n!r}; trainable objects: {', '.join(objects)}")
    cached = [_cached(n, objects[n], database_path(n, folder), params, progress) for n in names]
    return load_or_build_all(cached, progress)
