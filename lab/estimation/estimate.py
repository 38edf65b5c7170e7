"""The pose estimate a filter hands on (object O in the camera frame C, with its uncertainty in both
orientation charts) and its consistency measure, the NEES."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from lab.estimation.models import OrientationChart, euler_to_rv_jacobian, state_residual
from lab.geometry import pose6_to_G

__all__ = ["PoseEstimate", "nees"]


def _frozen(a) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.flags.writeable = False
    return a


@dataclass(frozen=True)
class PoseEstimate:
    """A pose estimate of the object in the camera frame C at time ``t``.

    Attributes
    ----------
    mu : ndarray, shape (6,) [m, rad]
        ``[x, y, z, alpha, beta, gamma]`` (read-only).
    Sigma : ndarray, shape (6, 6)
        Its covariance [m^2, m rad, rad^2] over ``X`` (Euler angles; read-only).
    t : float [s]
    Sigma_rv : ndarray, shape (6, 6)
        The same uncertainty over ``[x_r, phi]``, ``phi`` a small rotation vector in C
        (``R_true = Exp(phi) R``): ``T Sigma T^T`` with ``T = diag(I, E)``. Computed from ``Sigma``
        when not given; finite at every orientation when given by a rotation-vector filter.
    """

    mu: np.ndarray = field(repr=False)
    Sigma: np.ndarray = field(repr=False)
    t: float = 0.0
    Sigma_rv: np.ndarray | None = field(default=None, repr=False)

    def __post_init__(self):
        mu, Sigma = _frozen(self.mu), _frozen(self.Sigma)
        if mu.shape != (6,) or Sigma.shape != (6, 6):
            raise ValueError(f"PoseEstimate needs mu (6,) and Sigma (6, 6), got {mu.shape}, {Sigma.shape}")
        if self.Sigma_rv is None:
            T = euler_to_rv_jacobian(mu)
            Sigma_rv = T @ Sigma @ T.T
            Sigma_rv = _frozen(0.5 * (Sigma_rv + Sigma_rv.T))
        else:
            Sigma_rv = _frozen(self.Sigma_rv)
            if Sigma_rv.shape != (6, 6):
                raise ValueError(f"PoseEstimate needs Sigma_rv (6, 6), got {Sigma_rv.shape}")
        object.__setattr__(self, "mu", mu)
        object.__setattr__(self, "Sigma", Sigma)
        object.__setattr__(self, "Sigma_rv", Sigma_rv)

    @property
    def G_CO(self) -> np.ndarray:
        """The pose as a 4x4 transform (object frame O in the camera frame C)."""
        return pose6_to_G(self.mu)

    @property
    def std(self) -> np.ndarray:
        """Standard deviations of the six components, shape (6,) [m, rad]."""
        return np.sqrt(np.diag(self.Sigma))

    def __repr__(self) -> str:
        x = ", ".join(f"{v:.4f}" for v in self.mu)
        s = ", ".join(f"{v:.2g}" for v in self.std)
        return f"PoseEstimate(t={self.t:.3f}, mu=[{x}], std=[{s}])"


def nees(X_true, estimate: PoseEstimate, chart: OrientationChart = OrientationChart.EULER) -> float:
    """Normalised estimation error squared ``e^T Sigma^-1 e``; chi-square(6) if the filter is consistent.

    ``EULER``: ``e`` is the Euler-state difference (angles wrapped) and ``Sigma`` the estimate's.
    ``ROTATION_VECTOR``: ``e = [x_r - x_r_true, phi]`` with ``Exp(phi) = R R_true^T`` and ``Sigma_rv``.
    """
    if chart is OrientationChart.EULER:
        e, Sigma = state_residual(estimate.mu, X_true), estimate.Sigma
    else:
        R = pose6_to_G(estimate.mu)[:3, :3] @ pose6_to_G(X_true)[:3, :3].T
        e = np.concatenate([estimate.mu[:3] - np.asarray(X_true, float)[:3], _rotation_vector(R)])
        Sigma = estimate.Sigma_rv
    L = np.linalg.cholesky(Sigma)
    z = np.linalg.solve(L, e)
    return float(z @ z)


def _rotation_vector(R) -> np.ndarray:
    """``Log(R)``: the rotation vector (3,) of a rotation matrix (angle < pi)."""
    c = min(1.0, max(-1.0, 0.5 * (np.trace(R) - 1.0)))
    th = math.acos(c)
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    return 0.5 * w * (th / math.sin(th) if th > 1e-8 else 1.0)
