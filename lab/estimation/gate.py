"""The geometric feasibility check (search paper Sec. III-C) applied to matches before an EKF update:
a match passes when its residual under the predicted pose is plausible, in metres and in Mahalanobis
distance."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lab.estimation.fit import check_matches, chi2_quantile, valid_rows
from lab.estimation.models import (
    OrientationChart,
    euler_rate_matrix,
    measurement_jacobian,
    measurement_jacobian_rv,
    measurement_model,
    skew,
)
from lab.geometry import euler_zyx_to_R

__all__ = ["GateConfig", "gate_matches"]


@dataclass(frozen=True)
class GateConfig:
    """The geometric feasibility check (search paper Sec. III-C) applied before each update.

    Attributes
    ----------
    dist_max_m : float [m]
        Reject a match whose measured point is farther than this from where the predicted pose puts
        its database feature (the papers' distance threshold). ``inf`` disables it.
    gate_prob : float or None
        Reject a match whose Mahalanobis distance under its predicted covariance
        ``C_j Sigma_bar C_j^T + Sigma_j`` exceeds the chi-square(3) quantile of this probability
        (0.999 -> 16.27). ``None`` disables it.
    min_matches : int
        Fewest matches (after gating) for an update; below it the update is skipped (>= 3).
    min_spread_m : float [m]
        Skip the update when the used model points are collinear or coincident (RMS distance from
        their best-fit line below this).
    """

    dist_max_m: float = 0.15
    gate_prob: float | None = 0.999
    min_matches: int = 3
    min_spread_m: float = 5e-3

    def __post_init__(self):
        if self.min_matches < 3:
            raise ValueError(f"GateConfig.min_matches must be >= 3, got {self.min_matches}")
        if self.gate_prob is not None and not 0.0 < self.gate_prob < 1.0:
            raise ValueError(f"GateConfig.gate_prob must be in (0, 1) or None, got {self.gate_prob}")
        if not self.dist_max_m > 0:
            raise ValueError(f"GateConfig.dist_max_m must be > 0, got {self.dist_max_m}")


def gate_rows(mu_bar, Sigma_bar, d, b, S, gate: GateConfig, chart=OrientationChart.EULER):
    """The gate of :func:`gate_matches` on usable rows (already checked: ``lab.estimation.fit.valid_rows``),
    with what the update goes on with: ``(keep (n,), r (n, 3), C (n, 3, 6))``, the verdicts, the
    residuals ``r_j = d_j - h_j(mu_bar)`` and the Jacobians ``C_j`` of Eq. (3). ``Sigma_bar`` is in
    ``chart``."""
    n = d.shape[0]
    jac = measurement_jacobian if chart is OrientationChart.EULER else measurement_jacobian_rv
    C = jac(mu_bar, b).reshape(n, 3, 6)
    r = d - measurement_model(mu_bar, b)  # residual of each match under the predicted pose
    keep = np.ones(n, bool)
    if np.isfinite(gate.dist_max_m):
        keep &= np.linalg.norm(r, axis=1) <= gate.dist_max_m  # Euclidean feasibility check
    if gate.gate_prob is not None:
        S_jj = C @ Sigma_bar @ np.swapaxes(C, 1, 2) + S  # predicted covariance of each match, (n, 3, 3)
        m2 = np.einsum("na,na->n", r, np.linalg.solve(S_jj, r[..., None])[..., 0])
        keep &= m2 <= chi2_quantile(gate.gate_prob, 3)  # Mahalanobis gate, 3 dof
    return keep, r, C


def gate_rows_many(mus, Sigmas, ds, bs, Ss, gate: GateConfig, chart=OrientationChart.EULER) -> list:
    """:func:`gate_rows` of several filters at once, their matches' rows stacked (a bank's update): the
    residuals ``r_j = d_j - (x_r + R b_j)``, the Jacobians ``C_j = [I, -[R b_j]_x E]`` (``E = I`` in
    the rotation-vector chart) and both gates over all rows in one pass; ``[(keep, r, C), ...]``, one per
    filter, as ``gate_rows(mus[i], Sigmas[i], ds[i], bs[i], Ss[i], gate, chart)`` gives to round-off."""
    counts = [len(d) for d in ds]
    fi = np.repeat(np.arange(len(counts)), counts)  # each row's filter
    d, b, S = np.concatenate(ds), np.concatenate(bs), np.concatenate(Ss)
    mus = np.asarray(mus, dtype=float)
    R = np.stack([euler_zyx_to_R(mu[3], mu[4], mu[5]) for mu in mus])  # (F, 3, 3)
    q = np.einsum("nij,nj->ni", R[fi], b)  # q_j = R b_j
    r = d - (q + mus[fi, :3])  # residual of each match under its filter's predicted pose
    C = np.zeros((len(d), 3, 6))
    C[:, 0, 0] = C[:, 1, 1] = C[:, 2, 2] = 1.0
    if chart is OrientationChart.EULER:
        E = np.stack([euler_rate_matrix(mu[3], mu[4]) for mu in mus])
        C[:, :, 3:] = -skew(q) @ E[fi]  # d d_j / d x_o = -[q_j]_x E
    else:
        C[:, :, 3:] = -skew(q)
    keep = np.ones(len(d), bool)
    if np.isfinite(gate.dist_max_m):
        keep &= np.linalg.norm(r, axis=1) <= gate.dist_max_m  # Euclidean feasibility check
    if gate.gate_prob is not None:
        Sigma_bar = np.asarray(Sigmas, dtype=float)[fi]
        S_jj = C @ Sigma_bar @ np.swapaxes(C, 1, 2) + S  # predicted covariance of each match
        m2 = np.einsum("na,na->n", r, np.linalg.solve(S_jj, r[..., None])[..., 0])
        keep &= m2 <= chi2_quantile(gate.gate_prob, 3)  # Mahalanobis gate, 3 dof
    bounds = np.cumsum([0] + counts)
    return [(keep[a:z], r[a:z], C[a:z]) for a, z in zip(bounds[:-1], bounds[1:], strict=True)]


def gate_matches(mu_bar, Sigma_bar, d_C, b_O, Sigma_d, gate: GateConfig | None = None) -> np.ndarray:
    """The geometric feasibility check: which matches are consistent with the predicted pose.

    A match ``(d_j, b_j)`` passes when its residual ``r_j = d_j - (x_r + R b_j)`` is within
    ``gate.dist_max_m`` and ``r_j^T (C_j Sigma_bar C_j^T + Sigma_j)^-1 r_j`` is within the
    chi-square(3) quantile ``gate.gate_prob``. Rows with non-finite values fail.

    Parameters
    ----------
    mu_bar : array_like, shape (6,)
    Sigma_bar : array_like, shape (6, 6)
    d_C, b_O : array_like, shape (n, 3) [m]
    Sigma_d : array_like, shape (n, 3, 3) [m^2]
    gate : GateConfig, optional

    Returns
    -------
    inliers : ndarray, shape (n,), bool
    """
    d, b, S = check_matches(d_C, b_O, Sigma_d)
    valid = valid_rows(d, b, S)
    out = np.zeros(d.shape[0], bool)
    if np.any(valid):
        keep, _, _ = gate_rows(
            np.asarray(mu_bar, float),
            np.asarray(Sigma_bar, float),
            d[valid],
            b[valid],
            S[valid],
            gate or GateConfig(),
        )
        out[np.flatnonzero(valid)[keep]] = True
    return out
