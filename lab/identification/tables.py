r"""Probability lookup tables: the identification paper's Table I, and the sampling of W.

**What a table holds** (Sec. III-B, after Eq. (15)). For a true model ``M_i`` viewed from a training
pose ``X~`` and a candidate model ``M_j``: the probability ``P^j_{b_l}`` that database feature ``b_l``
of ``M_j`` corresponds to a feature measured on ``M_i``. With ``tau`` matches in ``T`` comparisons,

.. math:: P^j_{\mathbf{b}_l} = \frac{\tau}{T}

One table per pair ``(i, j)``, one row per training pose (the ring viewpoints of the databases,
``FeatureDatabase.viewpoints``), one column per feature of ``M_j``. The paper needs the ``L (L - 1)``
cross tables; the diagonal ``i = j`` is built as well: it gives ``W_ii``, how many features the true
model itself explains, which the likelihood of Eq. (15) is compared against.

The tables are built offline by rendering (:mod:`lab.training.tables`, ``lab tables``); this module
holds what the planner uses of them, and their file format.

**How W is sampled** (:class:`LookupTables`). ``W_ij``, the number of features of ``M_j`` that
correspond, is the sum of independent Bernoulli draws with the row's probabilities: a Poisson-binomial
variable, whose distribution is computed exactly from the row. The paper draws each ``W_ij`` on its own;
drawn independently, two models that look identical from a viewpoint (a shared face: equal rows) get
different counts by chance, and Eq. (15) turns that chance into spurious information. Here the
``W_ij`` of one sample share one quantile level ``u``: ``W_ij = F_ij^{-1}(u)`` for every ``j`` (a
comonotone coupling: each ``W_ij`` keeps the paper's distribution, and the counts of all models rise
and fall together with how good the frame is, as they do in a real frame). The expected entropy
uses ``S`` stratified levels ``u_s = (s + 1/2) / S`` (:attr:`LookupTables.W_quantiles`).

**The file.** One file per true model (the arrays, and JSON metadata with the digests of the
databases it was built from, the parameters and the digest of its own arrays), written atomically
(:func:`save_model_tables`); :func:`load_model_tables` raises :class:`~lab.errors.AssetError` for a
file that is corrupt or of another format. Which file is current, and rebuilding a stale one, is the
training cache's business (:func:`lab.training.tables.get_tables`).
"""

from __future__ import annotations

import hashlib
import io
import json
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lab.errors import AssetError, ConfigError

__all__ = [
    "TABLE_FORMAT_VERSION",
    "LookupTables",
    "ModelTables",
    "load_model_tables",
    "poisson_binomial_pmf",
    "poisson_binomial_quantiles",
    "save_model_tables",
]

#: Bump when the file layout or the building algorithm changes: older tables are then rebuilt.
TABLE_FORMAT_VERSION = 1


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
        leaves out of ``W`` where the scoring pools shared evidence; :func:`lab.training.get_tables`
        fills it in.

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


# --- the file ---------------------------------------------------------------------------------------


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
