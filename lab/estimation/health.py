"""When a pose filter is declared diverged: its configuration and the health check of its state.

A state is unusable when it is non-finite, its covariance is not symmetric positive definite, its
covariance has blown up past :class:`DivergenceConfig`'s bounds, or (Euler chart) it sits at gimbal
lock. :func:`health_many` checks several states at once, so that a bank of filters
(:class:`lab.estimation.EKFBank`) checks all of them in one pass; :class:`lab.estimation.PoseEKF` checks
its own through the same function. The NIS and gating runs of :class:`DivergenceConfig` are watched by
the filter itself, update by update.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["DivergenceConfig", "health_many"]


@dataclass(frozen=True)
class DivergenceConfig:
    """When a filter is declared diverged (it is then re-initialised from the next matches).

    Attributes
    ----------
    max_position_std_m : float [m]
        Largest standard deviation of the position (square root of the largest eigenvalue of the
        position block of ``Sigma``) before the track counts as lost.
    max_rotation_std_rad : float [rad]
        The same for the Euler angles.
    nis_prob : float
        An update's NIS ``y^T S^-1 y`` is "huge" above this chi-square(3n) quantile ...
    nis_patience : int
        ... and the filter diverged after this many consecutive huge ones.
    gating_patience : int
        Diverged after this many consecutive frames whose matches (>= the minimum) the gate rejected.
    min_cos_beta : float
        ``|cos(beta)|`` below this is (near) gimbal lock, where the Euler state is singular.
    """

    max_position_std_m: float = 0.5
    max_rotation_std_rad: float = 1.0
    nis_prob: float = 0.99999
    nis_patience: int = 5
    gating_patience: int = 5
    min_cos_beta: float = 1e-3


def health_many(dc: DivergenceConfig, euler: bool, mu: np.ndarray, P: np.ndarray) -> list[str | None]:
    """Why each of k states ``mu`` (k, 6) with covariance ``P`` (k, 6, 6) is not a usable estimate, or
    None: the first of non-finite, not symmetric, not positive definite, a covariance blow-up (the
    largest position or angle standard deviation over ``dc``'s bound), gimbal lock (``euler``: the
    covariance is over the Euler angles). The checks run on all k at once (one Cholesky call: a bank
    checks its filters together)."""
    k = len(mu)
    out: list[str | None] = [None] * k
    finite = np.isfinite(mu).all(axis=1) & np.isfinite(P).all(axis=(1, 2))
    with np.errstate(invalid="ignore"):  # non-finite ones are reported as such
        scale = np.maximum(1.0, np.abs(P).max(axis=(1, 2), initial=0.0))
        sym = np.abs(P - np.swapaxes(P, 1, 2)).max(axis=(1, 2), initial=0.0) <= 1e-9 * scale
    for i in range(k):
        if not finite[i]:
            out[i] = "non-finite state or covariance"
        elif not sym[i]:
            out[i] = "covariance is not symmetric"
    rest = [i for i in range(k) if out[i] is None]
    if not rest:
        return out
    try:
        np.linalg.cholesky(P[rest])
    except np.linalg.LinAlgError:  # which ones: each alone
        for i in rest:
            try:
                np.linalg.cholesky(P[i])
            except np.linalg.LinAlgError:
                out[i] = "covariance is not positive definite"
        rest = [i for i in rest if out[i] is None]
    # the largest variance of each block is at most its trace (P is positive definite): only a block
    # whose trace exceeds its bound needs its eigenvalues
    tr_pos = P[:, 0, 0] + P[:, 1, 1] + P[:, 2, 2]
    tr_rot = P[:, 3, 3] + P[:, 4, 4] + P[:, 5, 5]
    for i in rest:
        if tr_pos[i] > dc.max_position_std_m**2 or tr_rot[i] > dc.max_rotation_std_rad**2:
            top = np.linalg.eigvalsh(np.stack([P[i, :3, :3], P[i, 3:, 3:]]))[:, -1]  # largest variances
            pos_std, rot_std = math.sqrt(max(0.0, float(top[0]))), math.sqrt(max(0.0, float(top[1])))
            if pos_std > dc.max_position_std_m:
                out[i] = f"covariance blow-up: position std {pos_std:.3g} m > {dc.max_position_std_m} m"
                continue
            if rot_std > dc.max_rotation_std_rad:
                out[i] = f"covariance blow-up: angle std {rot_std:.3g} rad > {dc.max_rotation_std_rad} rad"
                continue
        if euler and abs(math.cos(mu[i, 4])) < dc.min_cos_beta:
            out[i] = f"gimbal lock: beta = {mu[i, 4]:.6f} rad, the Euler state is singular"
    return out
