r"""Probability lookup tables: the identification paper's Table I, built offline, and the sampling of W.

**What a table holds** (Sec. III-B, after Eq. (15)). For a true model ``M_i`` viewed from a training
pose ``X~`` and a candidate model ``M_j``: the probability ``P^j_{b_l}`` that database feature ``b_l``
of ``M_j`` corresponds to a feature measured on ``M_i``. With ``tau`` matches in ``T`` comparisons,

.. math:: P^j_{\mathbf{b}_l} = \frac{\tau}{T}

One table per pair ``(i, j)``, one row per training pose (the ring viewpoints of the databases,
``FeatureDatabase.viewpoints``), one column per feature of ``M_j``. The paper needs the ``L (L - 1)``
cross tables; the diagonal ``i = j`` is built as well: it gives ``W_ii``, how many features the true
model itself explains, which the likelihood of Eq. (15) is compared against.

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

**How W is sampled** (:class:`LookupTables`). ``W_ij``, the number of features of ``M_j`` that
correspond, is the sum of independent Bernoulli draws with the row's probabilities: a Poisson-binomial
variable, whose distribution is computed exactly from the row. The paper draws each ``W_ij`` on its own;
drawn independently, two models that look identical from a viewpoint (a shared face: equal rows) get
different counts by chance, and Eq. (15) turns that chance into spurious information. Here the
``W_ij`` of one sample share one quantile level ``u``: ``W_ij = F_ij^{-1}(u)`` for every ``j`` (a
comonotone coupling: each ``W_ij`` keeps the paper's distribution, and the counts of all models rise
and fall together with how good the frame is, as they do in a real frame). The expected entropy
uses ``S`` stratified levels ``u_s = (s + 1/2) / S`` (:attr:`LookupTables.W_quantiles`).

**The cache.** One file per true model in ``<cache>/tables/v<FORMAT>/<name>.npz`` (the arrays, and
JSON metadata with the digests of the databases it was built from, the parameters and the digest of
its own arrays), written atomically, as the feature databases are (:mod:`lab.vision.database`). A file
whose databases or parameters changed is *stale*, one whose digest does not match is *corrupt*: both
raise :class:`~lab.errors.AssetError` from :func:`load_tables`, and :func:`get_tables` rebuilds them.
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import os
import sys
import zlib
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from lab.errors import AssetError, ConfigError
from lab.geometry import G_to_pose6, se3_inv
from lab.identification.scoring import ModelScorer, ScoringConfig, pose_estimate_rv
from lab.identification.shared import shared_features
from lab.paths import cache_dir
from lab.robot import StereoCamera
from lab.vision import FeatureDatabase

__all__ = [
    "TABLE_FORMAT_VERSION",
    "LookupTables",
    "ModelTables",
    "TableParams",
    "box_model_names",
    "build_model_tables",
    "get_model_tables",
    "get_tables",
    "load_model_tables",
    "load_tables",
    "poisson_binomial_pmf",
    "poisson_binomial_quantiles",
    "save_model_tables",
    "tables_path",
]

#: Bump when the file layout or the building algorithm changes: older tables are then rebuilt.
TABLE_FORMAT_VERSION = 1


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
    width: int = 320
    height: int = 240
    fov_y_deg: float = 60.0
    baseline: float = 0.12
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


def _freeze(a, dtype=None) -> np.ndarray:
    a = np.array(a, dtype=dtype)
    a.flags.writeable = False
    return a


@dataclass(frozen=True)
class ModelTables:
    """The L tables of one true model ``M_i``: ``P^j_{b_l}`` for every database model ``M_j``.

    Attributes
    ----------
    true_model : str
    names : tuple of str
        The models ``M_j``, in order (the true model among them).
    viewpoints : ndarray, shape (V, 2) [rad]
        Azimuth and elevation of each row's training pose around O.
    poses : ndarray, shape (V, 6) [m, rad]
        The nominal relative pose ``X~ = [x, y, z, alpha, beta, gamma]`` of O in C of each row
        (Table I's pose column).
    P : tuple of ndarray, shape (V, N_j), float32
        ``P[j][v, l]`` = ``P^j_{b_l}`` at training pose ``v``.
    meta : dict
        Format version, parameters and the digests of the databases they were built from.
    """

    true_model: str
    names: tuple[str, ...]
    viewpoints: np.ndarray = field(repr=False)
    poses: np.ndarray = field(repr=False)
    P: tuple[np.ndarray, ...] = field(repr=False)
    meta: dict = field(default_factory=dict, repr=False)

    def __post_init__(self):
        object.__setattr__(self, "names", tuple(self.names))
        object.__setattr__(self, "viewpoints", _freeze(self.viewpoints, float))
        object.__setattr__(self, "poses", _freeze(self.poses, float))
        object.__setattr__(self, "P", tuple(_freeze(p, np.float32) for p in self.P))
        V = len(self.viewpoints)
        if len(self.P) != len(self.names) or any(p.ndim != 2 or p.shape[0] != V for p in self.P):
            raise ConfigError(f"tables of {self.true_model}: need one (V, N_j) array per model, V = {V}")
        if self.true_model not in self.names:
            raise ConfigError(f"true model {self.true_model!r} is not among the models {self.names}")

    def table(self, j: int | str) -> np.ndarray:
        """Table I for ``(M_i, M_j)``: rows are training poses, columns the features of ``M_j``."""
        return self.P[_index(self.names, j)]

    def _arrays(self) -> dict[str, np.ndarray]:
        out = {"viewpoints": self.viewpoints, "poses": self.poses}
        out.update({f"P_{k}": p for k, p in enumerate(self.P)})
        return out

    def digest(self) -> str:
        """SHA-256 of the arrays and the model order (detects corruption; equal builds are identical)."""
        h = hashlib.sha256(json.dumps([self.true_model, list(self.names)]).encode())
        for k, a in sorted(self._arrays().items()):
            h.update(k.encode())
            h.update(np.ascontiguousarray(a).tobytes())
        return h.hexdigest()


def _index(names: Sequence[str], model: int | str) -> int:
    """Position of a model given by index or name; ConfigError naming the allowed ones otherwise."""
    if isinstance(model, str):
        if model not in names:
            raise ConfigError(f"unknown model {model!r}; models: {', '.join(names)}")
        return list(names).index(model)
    if isinstance(model, (bool, np.bool_)) or int(model) != model or not 0 <= int(model) < len(names):
        raise ConfigError(f"unknown model index {model!r}; valid indices are 0..{len(names) - 1}")
    return int(model)


# --- W: Poisson-binomial counts ---------------------------------------------------------------------


def poisson_binomial_pmf(p) -> np.ndarray:
    """Distribution of the number of successes of independent Bernoulli draws with probabilities ``p``.

    Returns ``pmf`` of shape (n + 1,): ``pmf[w] = P(W = w)`` (exact, by the recursion over draws).
    """
    p = np.asarray(p, dtype=float).ravel()
    pmf = np.zeros(len(p) + 1)
    pmf[0] = 1.0
    for k, q in enumerate(p):
        pmf[1 : k + 2] = pmf[1 : k + 2] * (1.0 - q) + pmf[0 : k + 1] * q
        pmf[0] *= 1.0 - q
    return pmf


def poisson_binomial_quantiles(P_rows, levels) -> np.ndarray:
    """Quantiles ``F^{-1}(u) = min{w : P(W <= w) >= u}`` of the Poisson-binomial count of each row.

    Parameters
    ----------
    P_rows : ndarray, shape (R, N)
        One row of probabilities per count.
    levels : ndarray, shape (S,)
        Quantile levels in (0, 1).

    Returns
    -------
    ndarray, shape (R, S), int32
    """
    P_rows = np.asarray(P_rows, dtype=float)
    levels = np.asarray(levels, dtype=float)
    R = P_rows.shape[0]
    nz = P_rows > 0
    K = int(nz.sum(axis=1).max(initial=0))
    if K == 0:
        return np.zeros((R, len(levels)), np.int32)
    # the nonzero probabilities of each row, left-aligned and padded with zeros (which change nothing)
    order = np.argsort(~nz, axis=1, kind="stable")[:, :K]
    q = np.take_along_axis(P_rows, order, axis=1)
    pmf = np.zeros((R, K + 1))
    pmf[:, 0] = 1.0
    for k in range(K):  # the recursion of poisson_binomial_pmf, for all rows at once
        qk = q[:, k : k + 1]
        pmf[:, 1 : k + 2] = pmf[:, 1 : k + 2] * (1.0 - qk) + pmf[:, 0 : k + 1] * qk
        pmf[:, 0] *= 1.0 - qk[:, 0]
    cdf = np.cumsum(pmf, axis=1)
    W = np.sum(cdf[:, None, :] < levels[None, :, None] - 1e-12, axis=2)
    return np.minimum(W, K).astype(np.int32)


class LookupTables:
    """All ``L x L`` tables of a model database, with the quantiles of ``W`` that the planner samples.

    Parameters
    ----------
    names : sequence of str, length L
    viewpoints : ndarray, shape (V, 2) [rad]
        The rows' training poses (the same for every table).
    P : sequence of sequences of ndarray
        ``P[i][j]``, shape (V, N_j): true model ``i`` against model ``j``.
    n_levels : int
        ``S``, the stratified quantile levels of :attr:`W_quantiles`.
    shared : sequence of ndarray (N_j,) bool, optional
        The shared features of the databases the tables were built from
        (:func:`~lab.identification.shared.shared_features`): what the lookup-table evaluator
        leaves out of ``W`` where the scoring pools shared evidence. :func:`get_tables` fills it in.

    Attributes
    ----------
    W_quantiles : ndarray, shape (L, L, V, S), int32
        ``W_quantiles[i, j, v, s] = F_ijv^{-1}((s + 1/2) / S)``.
    W_mean : ndarray, shape (L, L, V)
        ``E[W_ij]`` at each training pose: the sum of the row.
    """

    def __init__(self, names, viewpoints, P, n_levels: int = 16, shared=None):
        self.names = tuple(names)
        L = len(self.names)
        if L == 0:
            raise ConfigError("lookup tables need at least one model")
        if len(set(self.names)) != L:
            raise ConfigError(f"model names must be distinct, got {self.names}")
        self.viewpoints = _freeze(viewpoints, float)
        V = len(self.viewpoints)
        if self.viewpoints.ndim != 2 or self.viewpoints.shape[1] != 2 or V == 0:
            raise ConfigError(f"viewpoints must be a non-empty (V, 2) array, got {self.viewpoints.shape}")
        if len(P) != L or any(len(row) != L for row in P):
            raise ConfigError(f"need an L x L set of tables for L = {L}")
        self.P = tuple(tuple(_freeze(P[i][j], np.float32) for j in range(L)) for i in range(L))
        for i in range(L):
            for j in range(L):
                p = self.P[i][j]
                if p.ndim != 2 or p.shape[0] != V or p.shape[1] != self.P[0][j].shape[1]:
                    raise ConfigError(f"table ({self.names[i]}, {self.names[j]}) has shape {p.shape}")
                if not np.all(np.isfinite(p)) or np.any(p < 0) or np.any(p > 1):
                    raise ConfigError(f"table ({self.names[i]}, {self.names[j]}) has values outside [0, 1]")
        if int(n_levels) != n_levels or n_levels < 1:
            raise ConfigError(f"n_levels must be a positive integer, got {n_levels}")
        self.levels = (np.arange(n_levels) + 0.5) / n_levels
        Wq = np.zeros((L, L, V, n_levels), np.int32)
        Wm = np.zeros((L, L, V))
        for j in range(L):  # rows of one j share a column count: one vectorised pass per j
            rows = np.concatenate([self.P[i][j] for i in range(L)])  # (L V, N_j)
            Wq[:, j] = poisson_binomial_quantiles(rows, self.levels).reshape(L, V, n_levels)
            Wm[:, j] = rows.sum(axis=1).reshape(L, V)
        self.W_quantiles = _freeze(Wq)
        self.W_mean = _freeze(Wm)
        self.shared = None if shared is None else tuple(self._checked_masks(shared))

    def _checked_masks(self, masks) -> list[np.ndarray]:
        """One bool mask per model over its features, or ConfigError naming the one that is not."""
        if len(masks) != self.n_models:
            raise ConfigError(f"need one feature mask per model: {len(masks)} for {self.n_models} models")
        out = []
        for j, m in enumerate(masks):
            m = np.asarray(m)
            n = self.P[0][j].shape[1]
            if m.dtype != bool or m.shape != (n,):
                raise ConfigError(
                    f"the feature mask of {self.names[j]} must be a bool array of shape ({n},), "
                    f"got {m.dtype} {m.shape}"
                )
            out.append(_freeze(m))
        return out

    @property
    def n_models(self) -> int:
        return len(self.names)

    def without_features(self, masks: Sequence[np.ndarray]) -> LookupTables:
        """The same tables with some features of each model never counted in ``W``.

        Parameters
        ----------
        masks : sequence of ndarray, shape (N_j,), bool, length L
            Per model ``M_j``: the features to leave out of ``W_ij`` for every true model ``i`` (the
            shared features, :func:`~lab.identification.shared.shared_features`, when the model
            probabilities pool shared evidence: they explain a frame equally for every model, so only
            the other features' count tells the models apart).

        Returns
        -------
        LookupTables
            Their probabilities set to 0 in the masked columns; ``W_quantiles`` and ``W_mean`` follow.
        """
        L = self.n_models
        keep = [~m for m in self._checked_masks(masks)]
        P = [[np.where(keep[j], self.P[i][j], 0.0) for j in range(L)] for i in range(L)]
        return LookupTables(self.names, self.viewpoints, P, len(self.levels), self.shared)

    def index(self, model: int | str) -> int:
        """Position of a model (index or name); :class:`~lab.errors.ConfigError` for an unknown one."""
        return _index(self.names, model)

    def table(self, i: int | str, j: int | str) -> np.ndarray:
        """Table I for true model ``i`` and model ``j``: shape (V, N_j)."""
        return self.P[self.index(i)][self.index(j)]

    def sample_W(self, i: int | str, j: int | str, v: int, rng: np.random.Generator, size: int = 1):
        """The paper's literal draw of ``W_ij`` at training pose ``v``: one Bernoulli per feature of
        ``M_j`` with probability ``P^j_{b_l}``, summed (``size`` independent draws)."""
        if not 0 <= int(v) < len(self.viewpoints):
            raise ConfigError(f"training pose {v} is outside 0..{len(self.viewpoints) - 1}")
        p = self.table(i, j)[int(v)]
        return (rng.random((size, len(p))) < p).sum(axis=1)

    @classmethod
    def from_model_tables(
        cls, tables: Sequence[ModelTables], n_levels: int = 16, shared=None
    ) -> LookupTables:
        """Assemble from one :class:`ModelTables` per true model (all built against the same models)."""
        if not tables:
            raise ConfigError("no model tables given")
        names = tables[0].names
        by_name = {t.true_model: t for t in tables}
        for t in tables:
            if t.names != names:
                raise ConfigError(f"tables of {t.true_model} were built against {t.names}, not {names}")
            if not np.allclose(t.viewpoints, tables[0].viewpoints):
                raise ConfigError(f"tables of {t.true_model} have other training poses")
        missing = [n for n in names if n not in by_name]
        if missing:
            raise ConfigError(f"no tables for true model(s) {', '.join(missing)}")
        P = [list(by_name[n].P) for n in names]
        return cls(names, tables[0].viewpoints, P, n_levels, shared)


# --- building ----------------------------------------------------------------------------------------


def box_model_names() -> tuple[str, ...]:
    """The identification database's models (``worlds/box_database.toml``): M0..M3."""
    from lab.scene import load_scene

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
    from lab.sim import viewpoint_G_WC
    from lab.vision.database import _object_world, trainable_objects
    from lab.vision.stereo import StereoParams, sift, stereo_features

    params = params or TableParams()
    scoring = (scoring or ScoringConfig()).for_camera(params.camera)  # the training camera's clutter
    names = [db.name for db in dbs]
    if true_model not in names:
        raise ConfigError(f"true model {true_model!r} is not among the databases {', '.join(names)}")
    objects = trainable_objects()
    if true_model not in objects:
        raise ConfigError(f"unknown object {true_model!r}; trainable objects: {', '.join(objects)}")
    db_i = dbs[names.index(true_model)]
    views = np.asarray(db_i.viewpoints, dtype=float)
    V = len(views)
    rows = range(V) if viewpoint_indices is None else [int(v) for v in viewpoint_indices]
    if any(not 0 <= v < V for v in rows):
        raise ConfigError(f"viewpoint indices must be within 0..{V - 1}")
    cam = params.camera
    scorers = [ModelScorer(db, scoring) for db in dbs]
    hits = [np.zeros((V, len(db)), np.int32) for db in dbs]
    poses = np.zeros((V, 6))
    det = sift(StereoParams().n_features, StereoParams().contrast_threshold)
    Sigma_gate = params.gate_covariance()
    name_seed = zlib.crc32(true_model.encode())
    world, G_WO = _object_world(objects[true_model], params.supersample)
    centre = G_WO[:3, 3]
    jobs = [(v, t) for v in rows for t in range(params.repeats)]
    it = jobs
    if progress:
        from tqdm import tqdm

        it = tqdm(
            jobs, desc=f"tables {true_model}", unit="render", leave=False, file=sys.stderr, disable=None
        )

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


# --- persistence ---------------------------------------------------------------------------------------


def tables_path(true_model: str, folder: Path | None = None) -> Path:
    """``<cache>/tables/v<FORMAT>/<true_model>.npz`` (``folder`` replaces ``<cache>/tables``)."""
    return Path(folder or cache_dir() / "tables") / f"v{TABLE_FORMAT_VERSION}" / f"{true_model}.npz"


def save_model_tables(t: ModelTables, path: Path) -> None:
    """Write atomically: arrays + JSON metadata (with the arrays' digest) in one .npz."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    meta = dict(t.meta, true_model=t.true_model, names=list(t.names), digest=t.digest())
    buf = io.BytesIO()
    np.savez(buf, meta=np.array(json.dumps(meta)), **t._arrays())
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    tmp.write_bytes(buf.getvalue())
    os.replace(tmp, path)


def load_model_tables(path: Path, true_model: str | None = None) -> ModelTables:
    """Read one true model's tables, checking format, digest and content; AssetError when unusable."""
    path = Path(path)
    hint = "rebuild them with `lab tables`"
    if not path.is_file():
        raise AssetError(f"lookup tables {path} do not exist (build them with `lab tables`)")
    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            names = tuple(meta["names"])
            arrays = {k: z[k] for k in z.files if k != "meta"}
        P = tuple(arrays[f"P_{k}"] for k in range(len(names)))
        viewpoints, poses = arrays["viewpoints"], arrays["poses"]
    except Exception as e:  # zip, JSON or missing-key damage
        raise AssetError(f"lookup tables {path} are corrupt ({type(e).__name__}: {e}); {hint}") from None
    if meta.get("format_version") != TABLE_FORMAT_VERSION:
        raise AssetError(
            f"lookup tables {path} have format {meta.get('format_version')}, expected "
            f"{TABLE_FORMAT_VERSION}; {hint}"
        )
    if len(viewpoints) == 0 or len(names) == 0:
        raise AssetError(f"lookup tables {path} are empty (no training poses or no models); {hint}")
    try:
        t = ModelTables(meta["true_model"], names, viewpoints, poses, P, meta)
    except (ConfigError, KeyError) as e:
        raise AssetError(f"lookup tables {path} are corrupt ({e}); {hint}") from None
    if t.digest() != meta.get("digest"):
        raise AssetError(f"lookup tables {path} are corrupt (digest mismatch); {hint}")
    if true_model is not None and t.true_model != true_model:
        raise AssetError(f"lookup tables {path} hold {t.true_model!r}, expected {true_model!r}")
    return t


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
    from lab.vision import get_database

    return [get_database(n, progress=False) for n in names]


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

    A rebuild says so on stderr, with the reason.
    """
    params, scoring = params or TableParams(), scoring or ScoringConfig()
    path = tables_path(true_model, folder)
    key = _key(true_model, dbs, params, scoring)
    reason = "rebuild requested" if rebuild else None
    if reason is None:
        try:
            t = load_model_tables(path, true_model)
            reason = _stale_reason(t, key)
            if reason is None:
                return t
        except AssetError as e:
            reason = "they are not in the cache" if not path.is_file() else str(e)
    if progress:
        print(f"lab: building the lookup tables of {true_model} ({reason}) -> {path}", file=sys.stderr)
    t = build_model_tables(true_model, dbs, params, scoring, progress=progress)
    save_model_tables(t, path)
    return t


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
    stale or corrupt (:func:`get_model_tables` for each true model), with the databases' shared
    features under ``scoring`` (:attr:`LookupTables.shared`)."""
    names = tuple(names or box_model_names())
    dbs = _databases(names, dbs)
    out = [get_model_tables(n, dbs, folder, params, scoring, rebuild, progress) for n in names]
    return LookupTables.from_model_tables(out, n_levels, shared_features(dbs, scoring))
