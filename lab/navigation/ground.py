"""Ground-plane estimation from world-frame stereo points (object-search paper, Sec. III-D).

The costmap labels a cell by "comparing points in the cell with the estimated ground plane". The plane
is estimated, not assumed to be ``z = 0``: odometry, a mis-calibrated tilt or a floor that is not level
all move it. :func:`fit_ground_plane` is a RANSAC fit (MSAC score) restricted to near-horizontal
planes close to ``z = 0``, refined by total least squares on its inliers.

A plane is written ``n . p + d = 0`` with a unit normal ``n`` pointing up (``n_z > 0``), so that
``h(p) = n . p + d`` is the signed height [m] of a point above the floor.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lab.errors import LabError

__all__ = ["GroundPlane", "NoGroundPlane", "fit_ground_plane"]


class NoGroundPlane(LabError, RuntimeError):
    """No near-horizontal plane close to z = 0 has enough support among the points."""


def as_points3(points, name: str = "points_W") -> np.ndarray:
    """``points`` as a float array of shape (n, 3); a single point (3,) becomes (1, 3).

    Raises
    ------
    ValueError
        Any other shape (e.g. (n, 2) image points), naming ``name``.
    """
    P = np.asarray(points, dtype=float)
    if P.ndim == 1 and P.shape == (3,):
        P = P[None, :]
    if P.ndim != 2 or P.shape[1] != 3:
        raise ValueError(f"{name} must have shape (n, 3) [m], got {P.shape}")
    return P


@dataclass(frozen=True)
class GroundPlane:
    """The floor as a plane in the world frame W: ``h(p) = normal . p + offset`` is the height [m].

    Attributes
    ----------
    normal : tuple of 3 floats
        Unit normal pointing up (``normal[2] > 0``).
    offset : float [m]
        ``d`` in ``n . p + d = 0``; for a level floor at height ``z0``, ``normal = (0, 0, 1)`` and
        ``offset = -z0``.
    n_inliers : int
        Points within the fit's inlier threshold of the plane.
    n_points : int
        Finite points the plane was fitted to.
    rms : float [m]
        Root-mean-square height of the inliers above the plane.
    """

    normal: tuple[float, float, float]
    offset: float
    n_inliers: int = 0
    n_points: int = 0
    rms: float = 0.0

    def __post_init__(self):
        n = np.asarray(self.normal, dtype=float)
        if n.shape != (3,) or not np.all(np.isfinite(n)) or not math.isfinite(self.offset):
            raise ValueError(f"ground plane needs a finite 3-vector normal and offset, got {self!r}")
        norm = float(np.linalg.norm(n))
        if norm < 1e-12 or n[2] <= 0:
            raise ValueError(f"ground plane normal must be non-zero and point up (n_z > 0), got {n}")
        object.__setattr__(self, "normal", tuple(float(v) for v in n / norm))
        object.__setattr__(self, "offset", float(self.offset) / norm)

    @classmethod
    def horizontal(cls, z0: float = 0.0) -> GroundPlane:
        """A level floor at height ``z0`` [m]."""
        return cls((0.0, 0.0, 1.0), -float(z0))

    def height(self, points_W: np.ndarray) -> np.ndarray:
        """Signed height [m] of points above the plane, shape (n, 3) -> (n,)."""
        p = as_points3(points_W)
        return p @ np.asarray(self.normal) + self.offset

    def z_at(self, x, y):
        """Height ``z`` [m] of the plane above the world point(s) ``(x, y)``."""
        nx, ny, nz = self.normal
        return -(self.offset + nx * np.asarray(x, dtype=float) + ny * np.asarray(y, dtype=float)) / nz

    @property
    def tilt(self) -> float:
        """Angle [rad] between the plane's normal and W's z axis."""
        return float(math.acos(min(1.0, self.normal[2])))


def _planes_through(P: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Planes through point triples ``P`` (k, 3, 3): unit normals (k, 3) up, offsets (k,), valid (k,)."""
    n = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])
    norm = np.linalg.norm(n, axis=1)
    valid = norm > 1e-9
    n = n / np.where(valid, norm, 1.0)[:, None]
    n = np.where((n[:, 2] < 0)[:, None], -n, n)
    d = -np.einsum("kj,kj->k", n, P[:, 0])
    return n, d, valid


def _tls_plane(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Total-least-squares plane through points (m, 3): the normal is the eigenvector of the scatter
    matrix with the smallest eigenvalue (the direction in which the points spread least)."""
    c = points.mean(axis=0)
    X = points - c
    _, V = np.linalg.eigh(X.T @ X)  # eigenvalues ascending
    n = V[:, 0]
    if n[2] < 0:
        n = -n
    return n, float(-n @ c)


def fit_ground_plane(
    points_W: np.ndarray,
    rng: np.random.Generator | int | None = None,
    *,
    inlier_threshold: float = 0.03,
    max_tilt: float = math.radians(10.0),
    max_offset: float = 0.3,
    n_hypotheses: int = 300,
    max_score_points: int = 3000,
    min_inliers: int = 50,
    min_inlier_fraction: float = 0.05,
    refine_iterations: int = 3,
) -> GroundPlane:
    """Estimate the floor plane from world-frame points by constrained RANSAC.

    Hypotheses are planes through three random points. Only near-horizontal planes (tilt of the normal
    at most ``max_tilt``) whose height under the points' centre is within ``max_offset`` of ``z = 0``
    are admitted, so a table top, a shelf or a wall never wins even when it has more points. Among
    those, the plane with the lowest MSAC cost ``sum(min(h_i^2, t^2))`` over a random subset of the
    points wins (a truncated quadratic: it counts inliers and rewards them for being close); it is
    then refined by total least squares on its inliers over all points, ``refine_iterations`` times.

    Parameters
    ----------
    points_W : ndarray, shape (n, 3) [m]
        Points in the world frame (non-finite rows are dropped).
    rng : numpy Generator or int seed
        Source of the random samples; the same seed gives the same plane.
    inlier_threshold : float [m]
        ``t``: a point within ``t`` of the plane supports it. Stereo points on the floor a few metres
        away scatter by 1-2 cm in height, hence the 3 cm default.
    max_tilt : float [rad]
        Largest admitted angle between the plane's normal and W's z axis.
    max_offset : float [m]
        Largest admitted ``|z|`` of the plane under the centre (median x, y) of the points.
    n_hypotheses : int
        Number of three-point samples.
    max_score_points : int
        Hypotheses are scored on at most this many randomly chosen points.
    min_inliers, min_inlier_fraction : int, float
        The fit fails unless at least ``max(min_inliers, min_inlier_fraction * n)`` points support it.
    refine_iterations : int
        Least-squares refinements on the inlier set.

    Returns
    -------
    GroundPlane

    Raises
    ------
    NoGroundPlane
        Fewer than three finite points, or no admitted plane with enough inliers (the camera sees no
        floor, e.g. it faces a wall).
    """
    rng = np.random.default_rng(rng)
    P = as_points3(points_W)
    P = P[np.isfinite(P).all(axis=1)]
    n_pts = len(P)
    need = max(int(min_inliers), math.ceil(min_inlier_fraction * n_pts), 3)
    if n_pts < need:
        raise NoGroundPlane(f"ground plane: only {n_pts} finite points, need at least {need}")
    t = float(inlier_threshold)
    window = _Admitted(max_tilt, float(max_offset), np.median(P[:, :2], axis=0), n_pts)
    pool = _sampling_pool(P, window, t)
    S = P if n_pts <= max_score_points else P[rng.choice(n_pts, max_score_points, replace=False)]
    n, d = _best_sampled_plane(pool, S, rng, int(n_hypotheses), window, t)
    n, d = _refined(P, n, d, window, t, int(refine_iterations))
    h_all = P @ n + d
    inl = np.abs(h_all) <= t
    n_inl = int(inl.sum())
    if n_inl < need:
        raise NoGroundPlane(
            f"ground plane: best near-horizontal plane has {n_inl} inliers among {n_pts} points, "
            f"need at least {need}"
        )
    rms = float(np.sqrt(np.mean(h_all[inl] ** 2)))
    return GroundPlane(tuple(n), d, n_inl, n_pts, rms)


@dataclass(frozen=True, eq=False)
class _Admitted:
    """Which planes :func:`fit_ground_plane` admits: tilted at most ``max_tilt`` [rad], and within
    ``max_offset`` [m] of ``z = 0`` under the centre ``centre_xy`` [m] of the ``n_points`` points."""

    max_tilt: float
    max_offset: float
    centre_xy: np.ndarray
    n_points: int

    @property
    def cos_max_tilt(self) -> float:
        return math.cos(self.max_tilt)

    @property
    def max_tilt_deg(self) -> float:
        return math.degrees(self.max_tilt)

    def __call__(self, n: np.ndarray, d) -> np.ndarray:
        """Admission of planes with unit normals ``n`` (..., 3) and offsets ``d`` (...,)."""
        c = self.centre_xy
        z_c = -(d + n[..., 0] * c[0] + n[..., 1] * c[1]) / np.maximum(n[..., 2], 1e-12)
        return (n[..., 2] >= self.cos_max_tilt) & (np.abs(z_c) <= self.max_offset)


def _sampling_pool(P: np.ndarray, window: _Admitted, t: float) -> np.ndarray:
    """The points that can lie on an admitted plane (the sampling prior): within the band of z = 0 that
    such a plane sweeps at their distance from the centre, plus the inlier threshold ``t`` [m]."""
    r_xy = np.linalg.norm(P[:, :2] - window.centre_xy, axis=1)
    pool = P[np.abs(P[:, 2]) <= window.max_offset + t + math.tan(window.max_tilt) * r_xy]
    if len(pool) < 3:
        raise NoGroundPlane(
            f"ground plane: no points within {window.max_offset:.2f} m of z = 0 among {len(P)}"
        )
    return pool


def _best_sampled_plane(
    pool: np.ndarray, S: np.ndarray, rng: np.random.Generator, n_hypotheses: int, window: _Admitted, t: float
) -> tuple[np.ndarray, float]:
    """RANSAC: planes through ``n_hypotheses`` random triples of ``pool``; among the admitted ones, the
    lowest MSAC cost ``sum(min(h_i^2, t^2))`` over the scoring points ``S`` wins (NoGroundPlane: none
    admitted)."""
    idx = rng.integers(0, len(pool), size=(n_hypotheses, 3))
    normals, offsets, valid = _planes_through(pool[idx])
    valid &= window(normals, offsets)
    if not valid.any():
        raise NoGroundPlane(
            f"ground plane: no sampled plane within {window.max_tilt_deg:.0f} deg of horizontal "
            f"and {window.max_offset:.2f} m of z = 0 among {window.n_points} points"
        )
    normals, offsets = normals[valid], offsets[valid]
    h = S @ normals.T + offsets  # (m, k) heights of the scoring points above each hypothesis
    msac = np.minimum(h * h, t * t).sum(axis=0)
    best = int(np.argmin(msac))  # argmin takes the first of equals: deterministic
    return normals[best], float(offsets[best])


def _refined(
    P: np.ndarray, n: np.ndarray, d: float, window: _Admitted, t: float, iterations: int
) -> tuple[np.ndarray, float]:
    """Total least squares on the plane's inliers among all points, ``iterations`` times (stopping
    early when too few inliers are left or the refit would not be admitted)."""
    for _ in range(iterations):
        inl = np.abs(P @ n + d) <= t
        if inl.sum() < 3:
            break
        n_new, d_new = _tls_plane(P[inl])
        if not window(n_new, d_new):
            break
        n, d = n_new, d_new
    return n, d
