r"""Building the probability lookup tables of the identification paper (Table I), and their cache.

**How they are built** (:func:`build_model_tables`, ``lab tables``). Model ``M_i`` alone is rendered
with the robot's camera from each ring viewpoint ``T`` times (``TableParams.repeats``), each time
from a pose perturbed within the viewpoint's bin: the azimuth within half a ring step (a decision
looks up the *nearest* row, so a row must stand for its whole bin), the elevation and the distance
within the ranges the robot's camera sees the object from. Every render's stereo features are matched
against each database ``M_j`` exactly as the model probabilities do it
(:meth:`~lab.identification.scoring.ModelScorer.explain`: descriptor distance and the geometric
gate, at the true relative pose with a small tracking uncertainty), and each feature of ``M_j`` that
explains a measured feature counts one match. The perturbations come from a generator seeded by
``(seed, model, viewpoint, repetition)``, so a build is deterministic and its rows independent.

**The cache.** One file per true model in ``<cache>/tables/v<FORMAT>/<name>.npz`` (the arrays, and
JSON metadata with the digests of the databases it was built from, the parameters and the digest of
its own arrays), written atomically, as the feature databases are (:mod:`lab.training.databases`). A file
whose databases or parameters changed is *stale*, one whose digest does not match is *corrupt*: both
raise :class:`~lab.errors.AssetError` from :func:`load_tables`, and :func:`get_tables` rebuilds them.
Each file is built under a lock file beside it (:mod:`lab.training.cache`): processes that find the
cache cold at once (the workers of ``lab eval identify``) split the true models instead of each
building all of them.
"""

from __future__ import annotations

import json
import math
import sys
import zlib
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from lab.errors import AssetError, ConfigError
from lab.geometry import G_to_pose6, se3_inv
from lab.identification.scoring import ModelScorer, ScoringConfig, pose_estimate_rv
from lab.identification.shared import shared_features
from lab.identification.tables import (
    TABLE_FORMAT_VERSION,
    LookupTables,
    ModelTables,
    load_model_tables,
    save_model_tables,
)
from lab.paths import cache_dir
from lab.robot import SIM_CAMERA, StereoCamera
from lab.scene import load_scene
from lab.training.cache import Artefact, load_or_build, load_or_build_all
from lab.training.databases import get_databases, object_world, trainable_objects
from lab.vision import FeatureDatabase
from lab.vision.stereo import StereoParams, sift, stereo_features

__all__ = [
    "TableParams",
    "box_model_names",
    "build_model_tables",
    "get_model_tables",
    "get_tables",
    "load_tables",
    "tables_path",
]


@dataclass(frozen=True)
class TableParams:
    """How the tables are built.

    Attributes
    ----------
    repeats : int
        ``T``, renders per true model and training pose.
    azimuth_jitter_deg : float
        Renders are spread uniformly over +- this around the viewpoint's azimuth (half the ring step
        covers the bin whose decisions look this row up).
    elevation_deg : (float, float)
        Range of the camera's elevation above the object's centre (the robot's camera, 0.7 m high,
        looking at a box centre 0.49 m high from 0.85-1.2 m: 10-14 degrees).
    distance_m : (float, float) [m]
        Range of the camera's distance from the object's centre.
    position_std_m, rotation_std_deg : float
        Pose uncertainty of the geometric gate (a well-tracked pose) when matching a render against a
        database at the true relative pose.
    seed : int
    width, height, fov_y_deg, baseline, supersample :
        The robot's camera and the render settings of its frames.
    """

    repeats: int = 8
    azimuth_jitter_deg: float = 5.0
    elevation_deg: tuple[float, float] = (8.0, 16.0)
    distance_m: tuple[float, float] = (0.85, 1.2)
    position_std_m: float = 0.01
    rotation_std_deg: float = 1.0
    seed: int = 0
    width: int = SIM_CAMERA.width
    height: int = SIM_CAMERA.height
    fov_y_deg: float = SIM_CAMERA.fov_y_deg
    baseline: float = SIM_CAMERA.baseline
    supersample: int = 1

    def __post_init__(self):
        if int(self.repeats) != self.repeats or self.repeats < 1:
            raise ConfigError(f"repeats must be a positive integer, got {self.repeats}")
        lo, hi = self.elevation_deg
        if not -80 <= lo <= hi <= 80:
            raise ConfigError(
                f"elevation_deg must be an increasing pair within [-80, 80], got {self.elevation_deg}"
            )
        lo, hi = self.distance_m
        if not 0.3 <= lo <= hi <= 5.0:
            raise ConfigError(
                f"distance_m must be an increasing pair within [0.3, 5] m, got {self.distance_m}"
            )
        if not 0 <= self.azimuth_jitter_deg <= 90:
            raise ConfigError(f"azimuth_jitter_deg must be within [0, 90], got {self.azimuth_jitter_deg}")
        if not (self.position_std_m > 0 and self.rotation_std_deg > 0):
            raise ConfigError("position_std_m and rotation_std_deg must be > 0")

    @property
    def camera(self) -> StereoCamera:
        return StereoCamera.from_fov(self.width, self.height, self.fov_y_deg, self.baseline)

    def gate_covariance(self) -> np.ndarray:
        """The (6, 6) pose covariance over ``[x_r, phi]`` used by the gate while building."""
        return np.diag([self.position_std_m**2] * 3 + [math.radians(self.rotation_std_deg) ** 2] * 3)


# --- building ----------------------------------------------------------------------------------------


def box_model_names() -> tuple[str, ...]:
    """The identification database's models (``worlds/box_database.toml``): M0..M3."""

    return tuple(m.name for m in load_scene("box_database").models)


def _key(
    true_model: str, dbs: Sequence[FeatureDatabase], params: TableParams, scoring: ScoringConfig
) -> dict:
    """What a table file depends on: a file whose key differs is stale."""
    return {
        "format_version": TABLE_FORMAT_VERSION,
        "true_model": true_model,
        "names": [db.name for db in dbs],
        "db_digests": [db.digest() for db in dbs],
        "params": json.loads(json.dumps(asdict(params))),
        "scoring": {
            "max_descriptor_distance": scoring.max_descriptor_distance,
            "k_neighbours": scoring.k_neighbours,
            "gate_prob": scoring.gate_prob,
            "dist_max_m": scoring.dist_max_m,
        },
    }


def _training_rows(true_model: str, names: list[str], dbs, viewpoint_indices):
    """The true model's ring viewpoints (V, 2) [rad] and the rows to build; ConfigError when the true
    model is not among the databases or not trainable, or a row is outside the ring."""
    if true_model not in names:
        raise ConfigError(f"true model {true_model!r} is not among the databases {', '.join(names)}")
    objects = trainable_objects()
    if true_model not in objects:
        raise ConfigError(f"unknown object {true_model!r}; trainable objects: {', '.join(objects)}")
    views = np.asarray(dbs[names.index(true_model)].viewpoints, dtype=float)
    V = len(views)
    rows = range(V) if viewpoint_indices is None else [int(v) for v in viewpoint_indices]
    if any(not 0 <= v < V for v in rows):
        raise ConfigError(f"viewpoint indices must be within 0..{V - 1}")
    return views, rows


def _progress(jobs: list, desc: str, show: bool):
    """``jobs``, with a progress bar on stderr when ``show``."""
    if not show:
        return jobs
    from tqdm import tqdm

    return tqdm(jobs, desc=desc, unit="render", leave=False, file=sys.stderr, disable=None)


def build_model_tables(
    true_model: str,
    dbs: Sequence[FeatureDatabase],
    params: TableParams | None = None,
    scoring: ScoringConfig | None = None,
    progress: bool = False,
    viewpoint_indices: Sequence[int] | None = None,
) -> ModelTables:
    """Render ``true_model`` around its training ring and tabulate which features of each database match.

    Parameters
    ----------
    true_model : str
        A trainable object (its database must be among ``dbs``).
    dbs : sequence of FeatureDatabase
        The models ``M_j`` (all share the ring viewpoints of the true model's database).
    params : TableParams, optional
    scoring : ScoringConfig, optional
        The association rule (descriptor distance, gate), the same as the model probabilities'.
    progress : bool
        Show a progress bar on stderr.
    viewpoint_indices : sequence of int, optional
        Build only these rows (the others stay 0): for tests and quick looks.

    Returns
    -------
    ModelTables
    """
    from lab.sim import viewpoint_G_WC  # the simulator only when rendering

    params = params or TableParams()
    scoring = (scoring or ScoringConfig()).for_camera(params.camera)  # the training camera's clutter
    names = [db.name for db in dbs]
    views, rows = _training_rows(true_model, names, dbs, viewpoint_indices)
    V = len(views)
    cam = params.camera
    scorers = [ModelScorer(db, scoring) for db in dbs]
    hits = [np.zeros((V, len(db)), np.int32) for db in dbs]
    poses = np.zeros((V, 6))
    det = sift(StereoParams().n_features, StereoParams().contrast_threshold)
    Sigma_gate = params.gate_covariance()
    name_seed = zlib.crc32(true_model.encode())
    world, G_WO = object_world(trainable_objects()[true_model], params.supersample)
    centre = G_WO[:3, 3]
    it = _progress([(v, t) for v in rows for t in range(params.repeats)], f"tables {true_model}", progress)

    def eye(az, el, r):
        return centre + r * np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])

    with world:
        for v in rows:  # Table I's pose column: the nominal relative pose of the row
            az, el = views[v]
            poses[v] = G_to_pose6(se3_inv(viewpoint_G_WC(eye(az, el, 1.0), centre)) @ G_WO)
        for v, t in it:
            rng = np.random.default_rng([params.seed, name_seed, v, t])
            az = views[v, 0] + math.radians(
                rng.uniform(-params.azimuth_jitter_deg, params.azimuth_jitter_deg)
            )
            el = math.radians(rng.uniform(*params.elevation_deg))
            r = rng.uniform(*params.distance_m)
            G_WC = viewpoint_G_WC(eye(az, el, r), centre)
            left, right = world.render_stereo(G_WC, cam)
            f = stereo_features(left, right, cam, detector=det)
            truth = pose_estimate_rv(G_to_pose6(se3_inv(G_WC) @ G_WO), Sigma_gate)
            for j, s in enumerate(scorers):
                e = s.explain(f, truth)
                hits[j][v, np.unique(e.idx_db[e.explained])] += 1  # tau: feature l of M_j matched
    P = [(h / params.repeats).astype(np.float32) for h in hits]  # P^j_{b_l} = tau / T
    meta = _key(true_model, dbs, params, scoring)
    return ModelTables(true_model, tuple(names), views, poses, tuple(P), meta)


# --- the cache -------------------------------------------------------------------------------------


def tables_path(true_model: str, folder: Path | None = None) -> Path:
    """``<cache>/tables/v<FORMAT>/<true_model>.npz`` (``folder`` replaces ``<cache>/tables``)."""
    return Path(folder or cache_dir() / "tables") / f"v{TABLE_FORMAT_VERSION}" / f"{true_model}.npz"


def _stale_reason(t: ModelTables, key: dict) -> str | None:
    """Why a loaded file does not belong to the current databases and parameters (None: it does)."""
    if list(t.names) != key["names"]:
        return f"they were built for the models {', '.join(t.names)}, not {', '.join(key['names'])}"
    if t.meta.get("db_digests") != key["db_digests"]:
        old = list(t.meta.get("db_digests") or []) + [None] * len(key["names"])
        changed = [
            n
            for n, a, b in zip(key["names"], old[: len(key["names"])], key["db_digests"], strict=True)
            if a != b
        ]
        return f"the feature database(s) {', '.join(changed) or '?'} changed since they were built"
    if t.meta.get("params") != key["params"] or t.meta.get("scoring") != key["scoring"]:
        return "the table or matching parameters changed"
    return None


def _databases(names, dbs):
    if dbs is not None:
        dbs = list(dbs)
        if [d.name for d in dbs] != list(names):
            raise ConfigError(f"databases {[d.name for d in dbs]} do not match the models {list(names)}")
        return dbs
    return get_databases(names, progress=False)


def load_tables(
    names: Sequence[str] | None = None,
    folder: Path | None = None,
    params: TableParams | None = None,
    scoring: ScoringConfig | None = None,
    dbs: Sequence[FeatureDatabase] | None = None,
    n_levels: int = 16,
) -> LookupTables:
    """The cached tables of ``names`` (default: the box models), strictly: never builds.

    Raises
    ------
    AssetError
        A file is missing, empty, corrupt, of another format, or stale (built from other databases
        or parameters); the message says which and how to rebuild.
    """
    names = tuple(names or box_model_names())
    params, scoring = params or TableParams(), scoring or ScoringConfig()
    dbs = _databases(names, dbs)
    out = []
    for n in names:
        path = tables_path(n, folder)
        t = load_model_tables(path, n)
        why = _stale_reason(t, _key(n, dbs, params, scoring))
        if why is not None:
            raise AssetError(f"lookup tables {path} are stale: {why}; rebuild them with `lab tables`")
        out.append(t)
    return LookupTables.from_model_tables(out, n_levels)


def _cached(
    true_model: str, dbs: Sequence[FeatureDatabase], folder, params: TableParams, scoring, progress: bool
) -> Artefact:
    """One true model's tables as an artefact of the cache (:mod:`lab.training.cache`)."""
    path = tables_path(true_model, folder)
    key = _key(true_model, dbs, params, scoring)

    def load():
        try:
            t = load_model_tables(path, true_model)
        except AssetError as e:
            return None, "they are not in the cache" if not path.is_file() else str(e)
        reason = _stale_reason(t, key)
        return (t, "") if reason is None else (None, reason)

    def build():
        return build_model_tables(true_model, dbs, params, scoring, progress=progress)

    return Artefact(path, f"the lookup tables of {true_model}", load, build, save_model_tables)


def get_model_tables(
    true_model: str,
    dbs: Sequence[FeatureDatabase],
    folder: Path | None = None,
    params: TableParams | None = None,
    scoring: ScoringConfig | None = None,
    rebuild: bool = False,
    progress: bool = True,
) -> ModelTables:
    """One true model's tables from the cache; built (and cached) first when missing, stale or corrupt.

    A rebuild says so on stderr, with the reason. It is built under a lock file beside it
    (:func:`lab.training.cache.load_or_build`): a process that finds another building it waits, then
    reads that one's file.
    """
    params, scoring = params or TableParams(), scoring or ScoringConfig()
    return load_or_build(_cached(true_model, dbs, folder, params, scoring, progress), progress, rebuild)


def get_tables(
    names: Sequence[str] | None = None,
    folder: Path | None = None,
    params: TableParams | None = None,
    scoring: ScoringConfig | None = None,
    dbs: Sequence[FeatureDatabase] | None = None,
    rebuild: bool = False,
    progress: bool = True,
    n_levels: int = 16,
) -> LookupTables:
    """The tables of ``names`` (default: the box models) from the cache, building what is missing,
    stale or corrupt (as :func:`get_model_tables` does for one true model), with the databases' shared
    features under ``scoring`` (:attr:`LookupTables.shared`). Processes that find the cache cold at
    once split the true models (:func:`lab.training.cache.load_or_build_all`): each table takes minutes."""
    names = tuple(names or box_model_names())
    params, scoring = params or TableParams(), scoring or ScoringConfig()
    dbs = _databases(names, dbs)
    cached = [_cached(n, dbs, folder, params, scoring, progress) for n in names]
    out = load_or_build_all(cached, progress, rebuild)
    return LookupTables.from_model_tables(out, n_levels, shared_features(dbs, scoring))
