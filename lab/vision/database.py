"""Feature databases and colour models from a training ring, their matching, and their cache.

Training (identification paper, Sec. III; search paper, Sec. III): the object is rendered from
viewpoints on an equatorial ring (every 10 degrees by default, about 1 m away, at the robot camera's
height). In each view, 3D SIFT features are extracted from the stereo pair and, with the *known*
training pose, moved into the object frame O; features outside the object's bounds are dropped.
Features seen again from another view (within ``merge_distance`` in O and with a close descriptor) are
merged, and each database feature remembers which ring viewpoints saw it (``seen_from``): the lookup
tables of the planning module need that. The colour model is the object's red-green chromaticity
histogram (search paper, Sec. III-B), accumulated over the same views.

The result, :class:`FeatureDatabase`, is the paper's ``B_i = [b_0 ... b_N]`` with descriptors.
:class:`Matcher` finds the correspondence vector ``J_i`` of a measured feature set against it with
Lowe's Best-Bin-First search (a FLANN KD-tree) and the ratio test.
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import os
import sys
from dataclasses import asdict, dataclass, field
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial import cKDTree

from lab.errors import AssetError, ConfigError
from lab.geometry import se3, se3_inv, transform_points
from lab.paths import cache_dir
from lab.robot import StereoCamera
from lab.vision.colour import colour_histogram
from lab.vision.stereo import Features3D, StereoParams, sift, stereo_features

__all__ = [
    "FORMAT_VERSION",
    "Correspondences",
    "FeatureDatabase",
    "Matcher",
    "TrainingParams",
    "database_path",
    "get_database",
    "load_database",
    "save_database",
    "train_database",
    "trainable_objects",
]

#: Bump when the file layout or the training algorithm changes: older caches are then rebuilt.
FORMAT_VERSION = 1


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
    width: int = 320
    height: int = 240
    fov_y_deg: float = 60.0
    baseline: float = 0.12

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


@dataclass(frozen=True)
class FeatureDatabase:
    """The trained model of one object: 3D SIFT features in O, their visibility, and a colour model.

    Attributes
    ----------
    name : str
    points_O : ndarray, shape (N, 3) [m]
        Feature positions in the object frame O (centre of the object).
    descriptors : ndarray, shape (N, 128), float32
    seen_from : ndarray, shape (N, V), bool
        ``seen_from[l, v]``: feature l was extracted in ring viewpoint v.
    viewpoints : ndarray, shape (V, 2) [rad]
        Azimuth and elevation of each ring viewpoint around O.
    extent : ndarray, shape (3,) [m]
        The object's bounding box size (x, y, z in O).
    histogram : ndarray, shape (bins, bins), float32
        Colour model (sums to 1) in ``meta["colour_space"]``.
    meta : dict
        Format version, parameters, camera, the asset hash the database was built from.
    """

    name: str
    points_O: np.ndarray = field(repr=False)
    descriptors: np.ndarray = field(repr=False)
    seen_from: np.ndarray = field(repr=False)
    viewpoints: np.ndarray = field(repr=False)
    extent: np.ndarray = field(repr=False)
    histogram: np.ndarray = field(repr=False)
    meta: dict = field(default_factory=dict, repr=False)

    def __len__(self) -> int:
        return len(self.points_O)

    def _arrays(self) -> dict[str, np.ndarray]:
        return {
            "points_O": self.points_O,
            "descriptors": self.descriptors,
            "seen_from": self.seen_from,
            "viewpoints": self.viewpoints,
            "extent": self.extent,
            "histogram": self.histogram,
        }

    def digest(self) -> str:
        """SHA-256 of the arrays (detects corruption, and shows that two trainings are identical)."""
        h = hashlib.sha256()
        for k, a in sorted(self._arrays().items()):
            h.update(k.encode())
            h.update(np.ascontiguousarray(a).tobytes())
        return h.hexdigest()


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
    from lab.scene import load_scene

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
    h.update(json.dumps(stereo, sort_keys=True).encode())
    h.update(str(FORMAT_VERSION).encode())
    return h.hexdigest()[:32]


def _object_world(obj: _Trainable, supersample: int):
    """A bare-floor world with the object alone, its centre at (0, 0, 0.49): returns (world, G_WO)."""
    from lab.scene import BodySpec
    from lab.sim import RenderSettings, SimWorld, load_scene

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
    from dataclasses import replace

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
    world, G_WO = _object_world(obj, params.supersample)
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
            _merge(points, descs, seen, counts, p_O[keep], f.descriptors[keep], v, params)
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


def _merge(points, descs, seen, counts, p_O, d, view, params: TrainingParams) -> None:
    """Merge one view's features into the growing database (a running mean of positions)."""
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


# --- persistence -----------------------------------------------------------------------------------


def database_path(name: str, folder: Path | None = None) -> Path:
    return Path(folder or cache_dir() / "databases") / f"v{FORMAT_VERSION}" / f"{name}.npz"


def save_database(db: FeatureDatabase, path: Path) -> None:
    """Write a database atomically: arrays + JSON metadata (with the arrays' digest) in one .npz."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    meta = dict(db.meta, digest=db.digest())
    buf = io.BytesIO()
    np.savez(buf, meta=np.array(json.dumps(meta)), **db._arrays())
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    tmp.write_bytes(buf.getvalue())
    os.replace(tmp, path)


def load_database(path: Path, name: str | None = None) -> FeatureDatabase:
    """Read a database, checking its format version and digest; raises AssetError when corrupt."""
    path = Path(path)
    if not path.is_file():
        raise AssetError(f"feature database {path} does not exist (build it with `lab train`)")
    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            arrays = {
                k: z[k] for k in ("points_O", "descriptors", "seen_from", "viewpoints", "extent", "histogram")
            }
    except Exception as e:  # zip, JSON or missing-key damage
        raise AssetError(
            f"feature database {path} is corrupt ({type(e).__name__}: {e}); rebuild with `lab train`"
        ) from None
    if meta.get("format_version") != FORMAT_VERSION:
        raise AssetError(
            f"feature database {path} has format {meta.get('format_version')}, expected {FORMAT_VERSION}"
        )
    db = FeatureDatabase(meta["name"], meta=meta, **arrays)
    if db.digest() != meta.get("digest"):
        raise AssetError(f"feature database {path} is corrupt (digest mismatch); rebuild with `lab train`")
    if name is not None and db.name != name:
        raise AssetError(f"feature database {path} holds {db.name!r}, expected {name!r}")
    return db


def get_database(
    name: str,
    folder: Path | None = None,
    params: TrainingParams | None = None,
    rebuild: bool = False,
    progress: bool = True,
) -> FeatureDatabase:
    """The database of ``name`` from the cache; built (and cached) first when missing, stale or corrupt.

    A rebuild says so on stderr, with the reason.
    """
    params = params or TrainingParams()
    objects = trainable_objects()
    if name not in objects:
        raise ConfigError(f"unknown object {name!r}; trainable objects: {', '.join(objects)}")
    path = database_path(name, folder)
    reason = "rebuild requested" if rebuild else None
    if reason is None:
        try:
            db = load_database(path, name)
            if db.meta.get("asset_hash") == _asset_hash(objects[name], params):
                return db
            reason = "its textures or training parameters changed"
        except AssetError as e:
            reason = "it is not in the cache" if not path.is_file() else str(e)
    if progress:
        print(f"lab: building the feature database of {name} ({reason}) -> {path}", file=sys.stderr)
    db = train_database(name, params, progress=progress)
    save_database(db, path)
    return db


# --- matching ----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Correspondences:
    """Matches of a measured feature set D against a database B: measured ``idx_meas[k]`` may be
    database feature ``idx_db[k]``.

    A measured feature can have several candidates: the database *aliases*, look-alike features such as
    the same printed page on three faces of a box. Geometry (RANSAC, the EKF's gate) decides which one
    it is; ``primary`` marks the nearest descriptor of each measured feature.

    Attributes
    ----------
    idx_meas : ndarray, shape (m,), int
    idx_db : ndarray, shape (m,), int
    distance : ndarray, shape (m,)
        Descriptor distance of each candidate.
    primary : ndarray, shape (m,), bool
    """

    idx_meas: np.ndarray
    idx_db: np.ndarray
    distance: np.ndarray
    primary: np.ndarray

    def __len__(self) -> int:
        return len(self.idx_meas)

    @property
    def n_matched(self) -> int:
        """Number of distinct measured features with at least one candidate."""
        return int(len(np.unique(self.idx_meas)))

    def best(self) -> Correspondences:
        """Only the nearest candidate of each measured feature (the plain correspondence vector J)."""
        return Correspondences(
            self.idx_meas[self.primary],
            self.idx_db[self.primary],
            self.distance[self.primary],
            self.primary[self.primary],
        )

    @classmethod
    def empty(cls) -> Correspondences:
        return cls(np.zeros(0, int), np.zeros(0, int), np.zeros(0), np.zeros(0, bool))

    def pairs(self, features: Features3D, db: FeatureDatabase) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The EKF's inputs for these matches: ``d_C`` (m, 3), ``b_O`` (m, 3) and ``Sigma_d`` (m, 3, 3).

        One row per candidate, so a measured feature with aliases appears once per alias; RANSAC and
        the EKF's feasibility gate keep the geometrically consistent one.
        """
        return (
            features.points_C[self.idx_meas],
            db.points_O[self.idx_db],
            features.covariances[self.idx_meas],
        )


class Matcher:
    """Lowe's Best-Bin-First matching of measured features against one database (FLANN KD-tree).

    The ratio test is alias-aware: the nearest database descriptor must beat the nearest *different*
    one by ``ratio``. Two database features are aliases (not different) when

    * their descriptors lie within ``alias_distance`` of each other: a page printed on three faces
      would otherwise fail the plain ratio test everywhere, since its three copies are each other's
      second-nearest neighbours; or
    * (with ``alias_radius`` > 0) they lie within ``alias_radius`` [m] of each other in the object
      frame: one physical point seen from training views far apart (another ring, another side)
      gives descriptors too different to merge into one database feature, and each is then the
      other's second-nearest neighbour -- the ratio test would reject the very point that matched
      best. The search's databases, trained from several rings, need this (measured: an object on
      the floor found in 5 of 6 fixed views with it, 3 of 6 without).

    All aliases of the nearest are returned as candidates.

    The index is built once per database. ``method="brute"`` gives exact nearest neighbours by one
    matrix product (an independent check, and as fast for databases of a few thousand features).
    FLANN's KD-trees are randomised; the seed is fixed, so runs repeat exactly.
    """

    def __init__(
        self,
        db: FeatureDatabase,
        ratio: float = 0.75,
        method: str = "flann",
        trees: int = 4,
        checks: int = 64,
        k: int = 8,
        alias_distance: float = 120.0,
        alias_radius: float = 0.0,
    ):
        if method not in ("flann", "brute"):
            raise ConfigError(f"method must be 'flann' or 'brute', got {method!r}")
        if not 0 < ratio <= 1:
            raise ConfigError(f"ratio must be within (0, 1], got {ratio}")
        if not alias_radius >= 0:
            raise ConfigError(f"alias_radius must be >= 0 m, got {alias_radius}")
        self.db, self.ratio, self.method, self.alias_distance = db, ratio, method, alias_distance
        self.alias_radius = float(alias_radius)
        self.k = min(k, len(db))
        self._D = np.ascontiguousarray(db.descriptors, dtype=np.float32)
        self._checks = checks
        if method == "flann" and len(db) < 64:  # FLANN asserts on tiny indexes; exact search is as fast there
            self.method = method = "brute"
        if method == "flann" and len(db) >= 2:
            cv2.setRNGSeed(0)
            self._index = cv2.flann_Index(self._D, {"algorithm": 1, "trees": trees})
        else:
            self._D_sq = np.einsum("ij,ij->i", self._D, self._D)

    def neighbours(self, descriptors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The k nearest database features of each descriptor: indices (n, k) and L2 distances (n, k)."""
        q = np.ascontiguousarray(descriptors, dtype=np.float32)
        if self.method == "flann":
            idx, d2 = self._index.knnSearch(q, self.k, params={"checks": self._checks})
            return idx.astype(int), np.sqrt(np.maximum(d2, 0.0))
        d2 = np.einsum("ij,ij->i", q, q)[:, None] + self._D_sq[None, :] - 2.0 * q @ self._D.T
        idx = (
            np.argpartition(d2, self.k - 1, axis=1)[:, : self.k]
            if self.k < len(self._D)
            else np.tile(np.arange(len(self._D)), (len(q), 1))
        )
        part = np.take_along_axis(d2, idx, axis=1)
        order = np.argsort(part, axis=1, kind="stable")
        idx = np.take_along_axis(idx, order, axis=1)
        return idx, np.sqrt(np.maximum(np.take_along_axis(part, order, axis=1), 0.0))

    def match(
        self, features: Features3D, neighbours: tuple[np.ndarray, np.ndarray] | None = None
    ) -> Correspondences:
        """Candidates of every measured feature that passes the alias-aware ratio test.

        Parameters
        ----------
        features : Features3D
        neighbours : (ndarray (n, k) int, ndarray (n, k)), optional
            The k nearest database features of each measured descriptor and their L2 distances, in
            increasing distance, as :meth:`neighbours` returns them: a search already made for this
            frame (the model probabilities make the same exact search) is reused instead of repeated.
            With the exact neighbours the result is that of ``method="brute"``.
        """
        if len(features) == 0 or len(self.db) < 2:
            return Correspondences.empty()
        if neighbours is None:
            idx, dist = self.neighbours(features.descriptors)
        else:
            idx, dist = (np.asarray(a) for a in neighbours)
            if idx.shape != (len(features), self.k) or dist.shape != idx.shape:
                raise ConfigError(
                    f"neighbours must be two ({len(features)}, {self.k}) arrays (one row per measured "
                    f"feature, this matcher's k = {self.k}), got {idx.shape} and {dist.shape}"
                )
        n, k = idx.shape
        # aliases: neighbours whose database descriptor is close to the nearest one's
        alias = np.linalg.norm(self._D[idx] - self._D[idx[:, :1]], axis=2) < self.alias_distance
        if self.alias_radius > 0:  # the same physical point, seen from far-apart training views
            P = self.db.points_O
            alias |= np.linalg.norm(P[idx] - P[idx[:, :1]], axis=2) < self.alias_radius
        has_other = ~alias.all(axis=1)
        first_other = np.argmax(~alias, axis=1)  # column of the nearest non-alias (when there is one)
        d_other = dist[np.arange(n), first_other]
        passed = np.where(has_other, dist[:, 0] < self.ratio * d_other, True)
        # candidates: aliases nearer than the first non-alias
        cols = np.arange(k)[None, :]
        cand = alias & passed[:, None] & np.where(has_other[:, None], cols < first_other[:, None], True)
        rows, c = np.nonzero(cand)
        if len(rows) == 0:
            return Correspondences.empty()
        return Correspondences(rows, idx[rows, c], dist[rows, c], c == 0)
