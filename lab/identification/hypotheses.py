"""What the planner knows: each model's probability and where that model says the object is.

Each EKF of the bank estimates the object's pose ``G_CO`` in the *current* camera frame C, for its own
model (the models can disagree: with three identical faces, one filter may believe the box is turned
by 90 degrees with respect to another). The planner moves the camera, so the hypotheses are kept in the
world frame W (``G_WO = G_WC G_CO``, ``G_WC`` from odometry and the pan-tilt state) and re-expressed in
the camera frame of each candidate goal (:meth:`ModelHypotheses.relative_to`).

Uncertainty is carried over ``[p, phi]``: position and a small rotation vector, as the rotation-vector
chart of :mod:`lab.estimation` (``R_true = Exp(phi) R``). Changing frames by a rotation ``R_AB`` maps
both parts by ``R_AB``: ``Sigma_A = T Sigma_B T^T`` with ``T = diag(R_AB, R_AB)``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from lab.errors import ConfigError, LabError
from lab.estimation import PoseEstimate
from lab.geometry import se3_inv

__all__ = ["ModelHypotheses", "NoObjectEstimate"]


class NoObjectEstimate(LabError, RuntimeError):
    """No model has a pose estimate: there is no object to plan around (scan for it first)."""


def _rotate_cov(R: np.ndarray, Sigma: np.ndarray) -> np.ndarray:
    T = np.zeros(Sigma.shape[:-2] + (6, 6))
    T[..., :3, :3] = R
    T[..., 3:, 3:] = R
    out = T @ Sigma @ np.swapaxes(T, -1, -2)
    return 0.5 * (out + np.swapaxes(out, -1, -2))


def _frozen(a) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.flags.writeable = False
    return a


@dataclass(frozen=True)
class ModelHypotheses:
    """The model probabilities and every model's object pose in the world W.

    Attributes
    ----------
    P : ndarray, shape (L,)
        ``P(M_i | D_{1:k})``.
    G_WO : ndarray, shape (L, 4, 4)
        Object frame O of each model in W.
    Sigma_W : ndarray, shape (L, 6, 6) [m^2, m rad, rad^2]
        Uncertainty of each pose over ``[p_W, phi_W]``.
    known : ndarray, shape (L,), bool
        False for a model whose filter has no estimate; its rows then hold the pose of the most
        probable known model (all models share the box's geometry: the object is where the others
        say, only its identity is in doubt).
    """

    P: np.ndarray
    G_WO: np.ndarray = field(repr=False)
    Sigma_W: np.ndarray = field(repr=False)
    known: np.ndarray = field(repr=False)

    def __post_init__(self):
        P = _frozen(self.P)
        G, S = _frozen(self.G_WO), _frozen(self.Sigma_W)
        known = np.array(self.known, dtype=bool)
        known.flags.writeable = False
        L = len(P)
        if P.ndim != 1 or L == 0 or abs(P.sum() - 1.0) > 1e-6 or np.any(P < 0):
            raise ConfigError(f"P must be a probability vector over the models, got {self.P}")
        if G.shape != (L, 4, 4) or S.shape != (L, 6, 6) or known.shape != (L,):
            raise ConfigError(
                f"need G_WO (L, 4, 4), Sigma_W (L, 6, 6) and known (L,) for L = {L}: "
                f"got {G.shape}, {S.shape}, {known.shape}"
            )
        if not (np.all(np.isfinite(G)) and np.all(np.isfinite(S))):
            raise ConfigError("model poses and covariances must be finite")
        object.__setattr__(self, "P", P)
        object.__setattr__(self, "G_WO", G)
        object.__setattr__(self, "Sigma_W", S)
        object.__setattr__(self, "known", known)

    @property
    def n_models(self) -> int:
        return len(self.P)

    @classmethod
    def from_estimates(cls, P, estimates: Sequence[PoseEstimate | None], G_WC: np.ndarray) -> ModelHypotheses:
        """From the bank's estimates (object in the current camera C) and the camera's pose in W.

        Parameters
        ----------
        P : array_like, shape (L,)
        estimates : sequence of PoseEstimate or None, length L
            ``EKFBank.estimates``.
        G_WC : ndarray, shape (4, 4)
            The current camera in the world (odometry pose ``G_WR`` times ``G_RC(pan, tilt)``).

        Raises
        ------
        NoObjectEstimate
            When no model has an estimate.
        """
        P = np.asarray(P, dtype=float)
        if len(estimates) != len(P):
            raise ConfigError(f"need one estimate per model: {len(estimates)} for {len(P)} models")
        G_WC = np.asarray(G_WC, dtype=float)
        if G_WC.shape != (4, 4) or not np.all(np.isfinite(G_WC)):
            raise ConfigError(f"G_WC must be a finite 4x4 transform, got shape {G_WC.shape}")
        known = np.array([e is not None for e in estimates])
        if not known.any():
            raise NoObjectEstimate("no model has a pose estimate yet: scan until a filter initialises")
        G = np.zeros((len(P), 4, 4))
        S = np.zeros((len(P), 6, 6))
        R = G_WC[:3, :3]
        for i, e in enumerate(estimates):
            if e is not None:
                G[i] = G_WC @ e.G_CO
                S[i] = _rotate_cov(R, e.Sigma_rv)
        best = int(np.flatnonzero(known)[np.argmax(P[known])])
        G[~known], S[~known] = G[best], S[best]
        return cls(P, G, S, known)

    def object_centre_W(self) -> np.ndarray:
        """The probability-weighted object origin in W (the paper's ``P_obj``, Sec. IV), shape (3,).

        Models without an estimate do not vote (their weight goes to the others).
        """
        w = np.where(self.known, self.P, 0.0)
        w = w / w.sum()
        return w @ self.G_WO[:, :3, 3]

    def relative_to(self, G_WC) -> tuple[np.ndarray, np.ndarray]:
        """Every model's pose and uncertainty seen from a camera at ``G_WC`` (a candidate goal).

        Parameters
        ----------
        G_WC : ndarray, shape (4, 4) or (A, 4, 4)

        Returns
        -------
        G_CO : ndarray, shape (L, 4, 4) or (A, L, 4, 4)
        Sigma_rv : ndarray, shape (L, 6, 6) or (A, L, 6, 6)
            Over ``[x_r, phi]`` in that camera frame (the rotation-vector chart).
        """
        G_WC = np.asarray(G_WC, dtype=float)
        single = G_WC.ndim == 2
        G_CW = np.stack([se3_inv(g) for g in np.atleast_3d(G_WC).reshape(-1, 4, 4)])  # (A, 4, 4)
        G_CO = G_CW[:, None] @ self.G_WO[None]  # (A, L, 4, 4)
        R = np.broadcast_to(G_CW[:, None, :3, :3], G_CO.shape[:2] + (3, 3))
        S = _rotate_cov(R, np.broadcast_to(self.Sigma_W, G_CO.shape[:2] + (6, 6)))
        return (G_CO[0], S[0]) if single else (G_CO, S)
