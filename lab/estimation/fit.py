r"""Pose from matched 3D-3D correspondences: closed-form fit, RANSAC, and the initial covariance.

The EKF needs a first pose (the search paper: "object initialization is based on the minimum number
of observed SIFT matches and the covariance of object pose"). Given matched pairs ``d_j`` (measured,
in C) and ``b_j`` (database, in O), we

1. draw minimal samples of 3 pairs with a seeded generator and fit each in closed form
   (:func:`fit_rigid_transform`, Kabsch/Umeyama without scale),
2. keep the hypothesis with the lowest truncated Mahalanobis cost (MSAC) over all pairs,
3. refit on its inliers, refine by Gauss-Newton on the weighted measurement model Eq. (3), and
   re-select the inliers until they settle,
4. take the Gauss-Newton covariance ``(C^T Sigma_m^-1 C)^-1`` (scaled) as the initial ``Sigma``
   (computed over a rotation vector, then expressed in Euler angles).

The closed-form fit minimises ``sum_j w_j |d_j - (R b_j + t)|^2``. With centroids ``b_bar``,
``d_bar`` and the cross-covariance ``M = sum_j w_j (d_j - d_bar)(b_j - b_bar)^T = U S V^T``:

.. math:: R = U \,\mathrm{diag}(1, 1, \det(U V^T))\, V^T, \qquad t = \bar d - R \bar b

(the ``det`` term keeps ``R`` a rotation, not a reflection).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from scipy.stats import chi2

from lab.estimation.models import (
    measurement_jacobian_rv,
    measurement_model,
    retract_rv,
    rv_to_euler_jacobian,
)
from lab.geometry import R_to_euler_zyx

# Validity bounds for a matched feature (not tuning knobs): a coordinate beyond a kilometre or a
# standard deviation outside [1 nm, 1 km] is a broken measurement, and would overflow the algebra.
_MAX_COORD_M = 1e3
_MIN_VAR_M2 = 1e-18
_MAX_VAR_M2 = 1e6

__all__ = ["RansacConfig", "InitResult", "fit_rigid_transform", "ransac_pose", "point_spread"]


@lru_cache(maxsize=256)
def chi2_quantile(prob: float, dof: int) -> float:
    """``chi2.ppf(prob, dof)``, cached (it costs ~40 us and the same few values recur)."""
    return float(chi2.ppf(prob, dof))


@dataclass(frozen=True)
class RansacConfig:
    """Settings of the RANSAC initialisation.

    Attributes
    ----------
    min_matches : int
        Matches needed before an initialisation is tried (at least 3).
    n_hypotheses : int
        Minimal samples drawn (all at once, so the result does not depend on timing).
    inlier_prob : float
        A pair is an inlier when its Mahalanobis distance under its own covariance is within this
        chi-square(3) quantile (0.999 -> 16.3, about 4 sigma)...
    dist_max_m : float [m]
        ... and its Euclidean residual is within this distance.
    min_sample_area_m2 : float [m^2]
        Minimal samples whose triangle (in O) is smaller are skipped as degenerate.
    min_spread_m : float [m]
        RMS distance of the model points from their best-fit line below which the set is
        degenerate (collinear or coincident) and no pose is returned.
    refine_iterations : int
        Gauss-Newton iterations on the inliers.
    Sigma0_scale : float
        Factor on the Gauss-Newton covariance for the initial ``Sigma`` (> 1 is conservative).
    """

    min_matches: int = 4
    n_hypotheses: int = 256
    inlier_prob: float = 0.999
    dist_max_m: float = 0.15
    min_sample_area_m2: float = 1e-4
    min_spread_m: float = 5e-3
    refine_iterations: int = 10
    Sigma0_scale: float = 2.0

    def __post_init__(self):
        if self.min_matches < 3:
            raise ValueError(f"RansacConfig.min_matches must be >= 3, got {self.min_matches}")
        if self.n_hypotheses < 1:
            raise ValueError(f"RansacConfig.n_hypotheses must be >= 1, got {self.n_hypotheses}")
        if not 0.0 < self.inlier_prob < 1.0:
            raise ValueError(f"RansacConfig.inlier_prob must be in (0, 1), got {self.inlier_prob}")
        if not self.Sigma0_scale > 0:
            raise ValueError(f"RansacConfig.Sigma0_scale must be > 0, got {self.Sigma0_scale}")


@dataclass(frozen=True)
class InitResult:
    """Outcome of :func:`ransac_pose`.

    Attributes
    ----------
    success : bool
    reason : str
        What happened, in words (why it failed, or how many inliers it found).
    mu : ndarray, shape (6,) or None [m, rad]
        The pose ``X`` of the object in C.
    Sigma : ndarray, shape (6, 6) or None
        Its covariance.
    inliers : ndarray, shape (n,), bool
        Which input pairs support the pose (all False on failure).
    Sigma_rv : ndarray, shape (6, 6) or None
        The same covariance over ``[x_r, phi]``, ``phi`` a small rotation vector in C (finite at
        every orientation; ``Sigma`` is derived from it and blows up at Euler gimbal lock).
    """

    success: bool
    reason: str
    mu: np.ndarray | None = field(default=None, repr=False)
    Sigma: np.ndarray | None = field(default=None, repr=False)
    inliers: np.ndarray = field(default_factory=lambda: np.zeros(0, bool), repr=False)
    Sigma_rv: np.ndarray | None = field(default=None, repr=False)

    @property
    def n_inliers(self) -> int:
        return int(np.count_nonzero(self.inliers))


def fit_rigid_transform(b_O, d_C, weights=None) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form rigid fit (Kabsch/Umeyama without scale): ``d_j ~ R b_j + t``.

    Parameters
    ----------
    b_O : array_like, shape (n, 3) [m]
        Model points in O.
    d_C : array_like, shape (n, 3) [m]
        The matching measured points in C.
    weights : array_like, shape (n,), optional
        Non-negative weights; uniform if omitted.

    Returns
    -------
    R : ndarray, shape (3, 3)
        Rotation of ``G_CO`` (a proper rotation, det = +1).
    t : ndarray, shape (3,) [m]
    """
    b = np.asarray(b_O, dtype=float)
    d = np.asarray(d_C, dtype=float)
    if b.ndim != 2 or b.shape[1] != 3 or d.shape != b.shape:
        raise ValueError(f"b_O and d_C must both have shape (n, 3), got {b.shape} and {d.shape}")
    if b.shape[0] < 3:
        raise ValueError(f"a rigid fit needs at least 3 pairs, got {b.shape[0]}")
    w = np.ones(b.shape[0]) if weights is None else np.asarray(weights, dtype=float)
    R, t = _kabsch_batch(b[None], d[None], w[None])
    return R[0], t[0]


def _kabsch_batch(b, d, w):
    """Weighted Kabsch on stacks: b, d (K, m, 3), w (K, m) -> R (K, 3, 3), t (K, 3)."""
    w = w / np.sum(w, axis=1, keepdims=True)
    b_bar = np.einsum("km,kma->ka", w, b)
    d_bar = np.einsum("km,kma->ka", w, d)
    M = np.einsum("km,kma,kmb->kab", w, d - d_bar[:, None], b - b_bar[:, None])  # sum w (d-d_bar)(b-b_bar)^T
    U, _, Vt = np.linalg.svd(M)
    s = np.sign(np.linalg.det(U @ Vt))
    s[s == 0] = 1.0
    D = np.ones((len(s), 3))
    D[:, 2] = s
    R = (U * D[:, None, :]) @ Vt  # R = U diag(1, 1, det(U V^T)) V^T
    t = d_bar - np.einsum("kab,kb->ka", R, b_bar)  # t = d_bar - R b_bar
    return R, t


def point_spread(b_O) -> float:
    """RMS distance [m] of points (n, 3) from their best-fit line: ~0 for collinear or coincident sets."""
    b = np.asarray(b_O, dtype=float)
    if b.shape[0] < 2:
        return 0.0
    c = b - b.mean(axis=0)
    lam = np.linalg.eigvalsh(c.T @ c)  # squared singular values of the centred points, ascending
    return float(np.sqrt(max(0.0, lam[0] + lam[1]) / b.shape[0]))


def _mahalanobis_sq(r, W):
    """``r_j^T W_j r_j`` for residuals (..., n, 3) and information matrices (n, 3, 3)."""
    return np.einsum("...na,nab,...nb->...n", r, W, r)


def _gauss_newton(X, b, d, W, iterations):
    """Weighted least squares on Eq. (3): minimise sum_j r_j^T W_j r_j, r_j = d_j - H_j(X).

    Steps are taken in the rotation-vector chart (``x_r + dx_r``, ``R <- Exp(phi) R``), which is
    well conditioned at every orientation, Euler gimbal lock included. Returns the refined X and
    the information matrix ``Lambda = C^T Sigma_m^-1 C`` (6, 6) in that chart.
    """
    n = b.shape[0]
    for _ in range(max(1, iterations)):
        C = measurement_jacobian_rv(X, b).reshape(n, 3, 6)
        r = d - measurement_model(X, b)
        WC = W @ C  # (n, 3, 6)
        Lam = np.einsum("nai,naj->ij", C, WC)  # Lambda = C^T Sigma_m^-1 C
        g = np.einsum("nai,na->i", WC, r)  # C^T Sigma_m^-1 r
        try:
            L = np.linalg.cholesky(Lam)
        except np.linalg.LinAlgError:
            return X, None
        step = np.linalg.solve(L.T, np.linalg.solve(L, g))  # normal equations Lambda step = g
        X = retract_rv(X, step)
        if np.max(np.abs(step)) < 1e-12:
            break
    C = measurement_jacobian_rv(X, b).reshape(n, 3, 6)
    return X, np.einsum("nai,nab,nbj->ij", C, W, C)


def ransac_pose(
    d_C, b_O, Sigma_d, rng: np.random.Generator, config: RansacConfig | None = None
) -> InitResult:
    """Initial pose and covariance of the object from matched pairs, robust to wrong matches.

    Never raises for bad data (too few pairs, NaN rows, degenerate geometry): it returns
    ``success=False`` with the reason. Rows with non-finite values or a covariance that is not
    symmetric positive definite are ignored (their ``inliers`` entry is False).

    Parameters
    ----------
    d_C : array_like, shape (n, 3) [m]
        Measured 3D features in the camera frame C.
    b_O : array_like, shape (n, 3) [m]
        Their matched database features in the object frame O (row j matches row j).
    Sigma_d : array_like, shape (n, 3, 3) [m^2]
        Covariance of each measured feature.
    rng : numpy.random.Generator
        Seeded generator for the minimal samples (same seed, same result, bit for bit).
    config : RansacConfig, optional

    Returns
    -------
    InitResult
    """
    cfg = config or RansacConfig()
    d, b, S = check_matches(d_C, b_O, Sigma_d)
    valid = valid_rows(d, b, S)
    inliers = np.zeros(d.shape[0], bool)

    def failed(why: str) -> InitResult:
        return InitResult(False, why, inliers=inliers)

    n_valid = int(np.count_nonzero(valid))
    if n_valid < cfg.min_matches:
        return failed(f"too few valid matches to initialise: {n_valid} < {cfg.min_matches}")
    idx = np.flatnonzero(valid)
    d, b, S = d[idx], b[idx], S[idx]
    if point_spread(b) < cfg.min_spread_m:
        return failed("degenerate geometry: the model points are collinear or coincident")
    W = np.linalg.inv(S)  # 3x3 information matrices, one per feature
    thr = chi2_quantile(cfg.inlier_prob, 3)

    hypotheses = _minimal_sample_hypotheses(b, d, rng, cfg)
    if hypotheses is None:
        return failed("degenerate geometry: every minimal sample is (nearly) collinear")
    sel = _best_hypothesis_inliers(*hypotheses, b, d, W, thr, cfg)
    X, Lam, sel = _refit_on_inliers(sel, b, d, S, W, thr, cfg)
    n_in = int(np.count_nonzero(sel))
    if X is None or Lam is None or n_in < cfg.min_matches:
        return failed(f"too few inliers for a pose: {n_in} < {cfg.min_matches} (of {n_valid} valid matches)")
    if point_spread(b[sel]) < cfg.min_spread_m:
        return failed("degenerate geometry: the inliers are collinear or coincident")
    covariances = _initial_covariances(X, Lam, cfg)
    if covariances is None:
        return failed("degenerate geometry: the pose is not observable from the inliers")
    Sigma, Sigma_rv = covariances
    if not (np.all(np.isfinite(X)) and np.all(np.isfinite(Sigma_rv))):
        return failed("initial pose is not finite")
    inliers[idx[sel]] = True
    why = f"initialised from {n_in} of {n_valid} valid matches"
    return InitResult(True, why, X, Sigma, inliers, Sigma_rv)


def _minimal_sample_hypotheses(b, d, rng: np.random.Generator, cfg: RansacConfig):
    """Step 1: ``n_hypotheses`` minimal samples of 3 pairs, all drawn up front (deterministic for a
    given generator state), and the rigid transform ``(R, t)`` of each sample that is not (nearly)
    collinear; None when none is usable."""
    m = len(b)
    samples = np.argpartition(rng.random((cfg.n_hypotheses, m)), 2, axis=1)[:, :3]
    bs, ds = b[samples], d[samples]  # (K, 3, 3)
    area = 0.5 * np.linalg.norm(np.cross(bs[:, 1] - bs[:, 0], bs[:, 2] - bs[:, 0]), axis=1)
    ok = area >= cfg.min_sample_area_m2
    if not np.any(ok):
        return None
    return _kabsch_batch(bs[ok], ds[ok], np.ones((int(ok.sum()), 3)))


def _best_hypothesis_inliers(R, t, b, d, W, thr: float, cfg: RansacConfig) -> np.ndarray:
    """Step 2: score every hypothesis on every pair with a truncated Mahalanobis cost (MSAC) and
    return the inliers (m,) bool of the best."""
    r = d[None] - (np.einsum("kab,nb->kna", R, b) + t[:, None])  # (K, m, 3)
    m2 = _mahalanobis_sq(r, W)
    inl = (m2 <= thr) & (np.linalg.norm(r, axis=2) <= cfg.dist_max_m)
    cost = np.where(inl, m2, thr).sum(axis=1)
    return inl[int(np.argmin(cost))]


def _refit_on_inliers(sel, b, d, S, W, thr: float, cfg: RansacConfig):
    """Step 3: refit on the inliers, refine (Gauss-Newton), re-select, until the inlier set settles
    (at most 5 rounds). Returns the pose ``X`` (6,), its information ``Lam`` (6, 6) (None when the fit
    failed) and the final inliers."""
    X = None
    Lam = None
    for _ in range(5):
        if np.count_nonzero(sel) < max(cfg.min_matches, 3):
            break
        wts = 1.0 / np.trace(S[sel], axis1=1, axis2=2)
        R0, t0 = fit_rigid_transform(b[sel], d[sel], wts)
        X0 = np.concatenate([t0, R_to_euler_zyx(R0)])
        X, Lam = _gauss_newton(X0, b[sel], d[sel], W[sel], cfg.refine_iterations)
        if Lam is None:
            break
        r = d - measurement_model(X, b)
        new = (_mahalanobis_sq(r, W) <= thr) & (np.linalg.norm(r, axis=1) <= cfg.dist_max_m)
        if np.array_equal(new, sel):
            break
        sel = new
    return X, Lam, sel


def _initial_covariances(X, Lam, cfg: RansacConfig):
    """Step 4: the pose covariance ``Sigma0_scale (C^T Sigma_m^-1 C)^-1`` from the information ``Lam``,
    in the rotation-vector chart and in Euler coordinates (huge near gimbal lock): ``(Sigma,
    Sigma_rv)``, or None when ``Lam`` is not positive definite (the pose is not observable)."""
    try:
        L = np.linalg.cholesky(Lam)
    except np.linalg.LinAlgError:
        return None
    Linv = np.linalg.solve(L, np.eye(6))
    Sigma_rv = cfg.Sigma0_scale * (Linv.T @ Linv)  # (C^T Sigma_m^-1 C)^-1, a 6x6 inverse via Cholesky
    Sigma_rv = 0.5 * (Sigma_rv + Sigma_rv.T)
    T_inv = rv_to_euler_jacobian(X)
    Sigma = T_inv @ Sigma_rv @ T_inv.T  # in Euler coordinates
    Sigma = 0.5 * (Sigma + Sigma.T)
    return Sigma, Sigma_rv


def check_matches(d_C, b_O, Sigma_d):
    """Matched features as float arrays ``(d (n, 3), b (n, 3), S (n, 3, 3))``. Shapes are the caller's
    responsibility: raise ValueError for them (values are checked later, :func:`valid_rows`)."""
    d = np.asarray(d_C, dtype=float)
    b = np.asarray(b_O, dtype=float)
    S = np.asarray(Sigma_d, dtype=float)
    if d.ndim != 2 or d.shape[1] != 3:
        raise ValueError(f"d_C must have shape (n, 3) [m], got {d.shape}")
    if b.shape != d.shape:
        raise ValueError(f"b_O must have the same shape as d_C {d.shape}, got {b.shape}")
    if S.shape != (d.shape[0], 3, 3):
        raise ValueError(f"Sigma_d must have shape (n, 3, 3) = {(d.shape[0], 3, 3)} [m^2], got {S.shape}")
    return d, b, S


def valid_rows(d, b, S) -> np.ndarray:
    """Rows a filter can use: finite coordinates within ``_MAX_COORD_M`` and a symmetric covariance
    whose eigenvalues lie in [``_MIN_VAR_M2``, ``_MAX_VAR_M2``] (anything else is a broken feature)."""
    X = np.abs(np.concatenate([d, b, S.reshape(len(S), 9)], axis=1))  # (n, 15): one pass for all rows
    finite = np.all(np.isfinite(X), axis=1)
    sane = finite & (X[:, :6].max(axis=1, initial=0.0) <= _MAX_COORD_M)
    sane &= X[:, 6:].max(axis=1, initial=0.0) <= _MAX_VAR_M2
    Sf = np.where(sane[:, None, None], S, np.eye(3))
    scale = np.abs(Sf).max(axis=(1, 2))
    sym = np.all(np.abs(Sf - np.swapaxes(Sf, 1, 2)) <= 1e-9 * scale[:, None, None], axis=(1, 2))
    # positive definite by Sylvester's criterion (leading minors > 0) ...
    m2 = Sf[:, 0, 0] * Sf[:, 1, 1] - Sf[:, 0, 1] * Sf[:, 1, 0]
    det = (
        Sf[:, 0, 0] * (Sf[:, 1, 1] * Sf[:, 2, 2] - Sf[:, 1, 2] * Sf[:, 2, 1])
        - Sf[:, 0, 1] * (Sf[:, 1, 0] * Sf[:, 2, 2] - Sf[:, 1, 2] * Sf[:, 2, 0])
        + Sf[:, 0, 2] * (Sf[:, 1, 0] * Sf[:, 2, 1] - Sf[:, 1, 1] * Sf[:, 2, 0])
    )
    ok = sane & sym & (Sf[:, 0, 0] > 0) & (m2 > 0) & (det > 0)
    # ... with smallest eigenvalue >= _MIN_VAR_M2: det / trace^2 is a lower bound; check the rest exactly
    tr = np.trace(Sf, axis1=1, axis2=2)
    unsure = ok & ~(det >= _MIN_VAR_M2 * tr * tr)
    if np.any(unsure):
        ok[unsure] = np.linalg.eigvalsh(Sf[unsure])[:, 0] >= _MIN_VAR_M2
    return ok
