"""Matching a measured feature set against a database: the correspondence vector ``J_i``.

:class:`Matcher` finds it with Lowe's Best-Bin-First search (a FLANN KD-tree, or an exact matrix
product) and an alias-aware ratio test; :class:`Correspondences` holds the candidates.
:class:`JointIndex` searches several databases at once, exactly: one matrix product over their
distinct descriptors (the box models share three faces), each model's nearest neighbours picked from it.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from lab.errors import ConfigError
from lab.vision.database import FeatureDatabase
from lab.vision.stereo import Features3D, small_integer_descriptors

__all__ = ["Correspondences", "JointIndex", "Matcher"]


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


def _k_smallest_by_partition(d2: np.ndarray, idx: np.ndarray | None = None, k: int | None = None):
    """The ``k`` smallest entries of each row of ``d2`` (indices and values, (n, k), smallest first):
    ``argpartition``, then a stable sort of the k. Among equal values the order is ``argpartition``'s.
    With ``idx`` given: those columns, sorted."""
    if idx is None:
        idx = np.argpartition(d2, k - 1, axis=1)[:, :k]
    part = np.take_along_axis(d2, idx, axis=1)
    order = np.argsort(part, axis=1, kind="stable")
    return np.take_along_axis(idx, order, axis=1), np.take_along_axis(part, order, axis=1)


def _k_smallest(d2: np.ndarray, k: int):
    """:func:`_k_smallest_by_partition`'s result, about twice as fast on the identification's frames.

    The ``k + 1`` smallest of every row by ``k + 1`` vectorised ``argmin`` passes (each a fast
    reduction; ``argpartition`` costs ~10 us per row of 700). Where those ``k + 1`` values are all
    distinct, the k nearest and their order are unique, so any exact method gives them. Where two are
    equal (a database stores some descriptors twice, and SIFT's integer-valued descriptors give integer
    squared distances, so ties are common: ~20 % of the rows on the box databases), the order among
    them is ``argpartition``'s, which no other method reproduces: those rows are recomputed by it, row
    for row. So the result equals :func:`_k_smallest_by_partition`'s, bit for bit
    (``tests/test_vision_matching.py``).
    """
    n, N = d2.shape
    if not (k < N and np.isfinite(d2).all()):
        return _k_smallest_by_partition(d2, k=k)
    work = d2.copy()
    rows = np.arange(n)
    idx = np.empty((n, k + 1), np.intp)
    val = np.empty((n, k + 1), d2.dtype)
    for j in range(k + 1):
        a = work.argmin(axis=1)
        idx[:, j] = a
        val[:, j] = work[rows, a]
        work[rows, a] = np.inf
    tie = np.flatnonzero((val[:, 1:] == val[:, :-1]).any(axis=1))
    idx, val = idx[:, :k], val[:, :k]
    if len(tie):
        idx[tie], val[tie] = _k_smallest_by_partition(d2[tie], k=k)
    return idx, val


def _nearest(d2: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` nearest columns of each row of the squared distances ``d2`` (n, N): indices (n, k) and
    L2 distances (n, k), nearest first (all N, sorted, when ``k >= N``)."""
    if k < d2.shape[1]:
        idx, part = _k_smallest(d2, k)
    else:
        idx, part = _k_smallest_by_partition(d2, np.tile(np.arange(d2.shape[1]), (len(d2), 1)))
    return idx, np.sqrt(np.maximum(part, 0.0))


class JointIndex:
    r"""One exact nearest-neighbour index over the features of several databases ``B_1 .. B_L``.

    Each distinct descriptor is stored once, with the models that hold it (the box models' three shared
    faces: 2753 descriptors of the four box databases are 1534 distinct ones). A frame's descriptors
    ``q`` are compared with all of them in one matrix product,

    .. math:: d^2(q, b) = |q|^2 + |b|^2 - 2\, q \cdot b,

    and each model's ``k`` nearest are picked from its own columns, in its database's order: the very
    neighbours (indices into ``B_i``, distances, order among equals) of ``Matcher(B_i,
    method="brute", k=k)``. That holds because SIFT's descriptors are integers (at most 255), so every
    squared distance is an integer below 2^24, exact in float32 however the product sums it; a set with
    other descriptors is searched model by model, as the matcher would.

    Parameters
    ----------
    databases : sequence of FeatureDatabase
    k : int
        Neighbours per model (at most each database's size).
    """

    def __init__(self, databases, k: int = 8):
        self.dbs = list(databases)
        if not self.dbs:
            raise ConfigError("a JointIndex needs at least one database")
        if int(k) != k or k < 1:
            raise ConfigError(f"k must be a positive integer, got {k}")
        self.k = [min(int(k), len(db)) for db in self.dbs]
        D = [np.ascontiguousarray(db.descriptors, dtype=np.float32) for db in self.dbs]
        self.exact = all(small_integer_descriptors(d) for d in D)
        if self.exact:
            stacked = np.concatenate(D) if sum(len(d) for d in D) else np.zeros((0, 128), np.float32)
            self.descriptors, inverse = np.unique(stacked, axis=0, return_inverse=True)
            bounds = np.cumsum([0] + [len(d) for d in D])
            #: each model's features as columns of the distinct descriptors, in the database's order
            self.columns = [inverse.reshape(-1)[a:b] for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
            #: which models hold each distinct descriptor, (U, L) bool
            self.members = np.zeros((len(self.descriptors), len(D)), bool)
            for i, c in enumerate(self.columns):
                self.members[c, i] = True
            self._sq = np.einsum("ij,ij->i", self.descriptors, self.descriptors)
        self._per_model: list | None = None  # Matcher(B_i, brute) each, for other descriptors (on first use)
        self._cache: tuple | None = None  # (descriptors, result) of the last search

    def __len__(self) -> int:
        """Distinct descriptors stored (the databases' total without an exact index)."""
        return len(self.descriptors) if self.exact else sum(len(db) for db in self.dbs)

    def neighbours(self, descriptors: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        """Every model's ``k`` nearest database features of each descriptor (n, 128): per model, indices
        into its database (n, k_i) and L2 distances (n, k_i), nearest first. The last search is kept:
        asking again with the same array returns it."""
        c = self._cache
        if c is not None and c[0] is descriptors:
            return c[1]
        q = np.ascontiguousarray(descriptors, dtype=np.float32)
        if not self.exact or not small_integer_descriptors(q):
            out = [
                Matcher(db, method="brute", k=k).neighbours(q) for db, k in zip(self.dbs, self.k, strict=True)
            ]
        else:
            d2 = np.einsum("ij,ij->i", q, q)[:, None] + self._sq[None, :] - 2.0 * q @ self.descriptors.T
            out = [_nearest(d2[:, cols], k) for cols, k in zip(self.columns, self.k, strict=True)]
        self._cache = (descriptors, out)
        return out


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
        self._alias_table: np.ndarray | None = None  # (N, N) bool, on first use (_aliases)
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
        return _nearest(d2, self.k)

    _ALIAS_TABLE_MAX = 4096  # database features up to which the alias table is kept (16 MB at most)

    def _aliases(self, idx: np.ndarray) -> np.ndarray:
        """(n, k) bool: neighbour ``idx[m, c]``'s descriptor lies within ``alias_distance`` of the nearest
        one's, ``idx[m, 0]``, read from a table of every pair of the database's features made on first
        use (databases up to ``_ALIAS_TABLE_MAX`` features; larger ones compute it directly).

        For SIFT's integer descriptors the table's squared distances come from one matrix product:
        integers below 2^24, exact in float32 however summed, so the table is the direct
        ``norm(D_a - D_b) < alias_distance``'s, pair for pair; other descriptors fill it in chunks by
        that very expression."""
        if len(self._D) > self._ALIAS_TABLE_MAX:
            return np.linalg.norm(self._D[idx] - self._D[idx[:, :1]], axis=2) < self.alias_distance
        if self._alias_table is None:
            D = self._D
            if small_integer_descriptors(D):
                sq = np.einsum("ij,ij->i", D, D)
                d2 = np.maximum(sq[:, None] + sq[None, :] - 2.0 * D @ D.T, 0.0)
                self._alias_table = np.sqrt(d2) < self.alias_distance
            else:
                table = np.empty((len(D), len(D)), bool)
                for a in range(0, len(D), 64):
                    table[a : a + 64] = (
                        np.linalg.norm(D[a : a + 64, None, :] - D[None], axis=2) < self.alias_distance
                    )
                self._alias_table = table
        return self._alias_table[idx[:, :1], idx]

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
        alias = self._aliases(idx)
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
