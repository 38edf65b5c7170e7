r"""The pose EKF's update kernel: whitening, the 6x6 information-form update and Eq. (9)'s likelihood.

:class:`lab.estimation.PoseEKF` runs one filter through these functions; :class:`lab.estimation.EKFBank`
runs many, its linear algebra batched over the filters, through the same functions and the filter's
public steps (:meth:`~lab.estimation.PoseEKF.predict_staged`, :meth:`~lab.estimation.PoseEKF.begin_update`
and those after them), so that both compute the same floating-point operations in the same order.

**The update never forms the 3n x 3n innovation covariance.** ``Sigma_m`` is block-diagonal, so
with whitened residuals and Jacobian (``L_j L_j^T = Sigma_j``, ``y~_j = L_j^-1 y_j``,
``C~_j = L_j^-1 C_j``: :func:`whitened`) everything reduces to 6x6 algebra. With
``Lambda = C^T Sigma_m^-1 C``, ``g = C^T Sigma_m^-1 y`` and ``Sigma_bar = L L^T``
(:func:`information_update`):

.. math::

    S &= C \bar\Sigma C^T + \Sigma_m
        \qquad \text{(innovation covariance, never formed)} \\
    B &= I + L^T \Lambda L, \qquad M = L B^{-1} L^T = (\bar\Sigma^{-1} + \Lambda)^{-1} \\
    K &= \bar\Sigma C^T S^{-1} = M C^T \Sigma_m^{-1}
        \qquad \text{(so } K y = M g,\ K C = M\Lambda,\ K \Sigma_m K^T = M \Lambda M \text{)} \\
    \mu &= \bar\mu + K y, \qquad
    \Sigma = (I - K C)\bar\Sigma(I - K C)^T + K \Sigma_m K^T \qquad \text{(Joseph form)} \\
    y^T S^{-1} y &= \tilde y^T \tilde y - g^T M g, \qquad
    \log|S| = \log|\Sigma_m| + \log|B|

(Woodbury's identity and the matrix determinant lemma). ``B`` has all eigenvalues >= 1, so its
Cholesky factor is well conditioned however small ``Sigma_bar`` or ``Sigma_m`` are. The results equal
filterpy's dense ``ExtendedKalmanFilter.update`` (which is Joseph form too) to ~1e-12; the tests
check that over a 25-step run. With the calibration error in the state
(:mod:`lab.estimation.uncertainty`) the same algebra runs in ``6 + m`` dimensions.

A step's checked inputs travel between the stages as a :class:`Motion` (the prediction's, checked
once per step by :func:`checked_motion`) and a :class:`PendingUpdate` (an update between its checks
and its linear algebra).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lab.estimation.fit import check_matches
from lab.estimation.models import (
    OrientationChart,
    camera_motion,
    measurement_jacobian,
    measurement_jacobian_rv,
    measurement_model,
)

__all__ = [
    "LOG_2PI",
    "Motion",
    "PendingUpdate",
    "checked_motion",
    "data_log_likelihood",
    "information_update",
    "whitened",
]

#: ``log(2 pi)``, the constant of a Gaussian's log density.
LOG_2PI = math.log(2.0 * math.pi)


def whitened(r, C, S):
    """Whiten residuals ``y_j = d_j - h_j(mu_bar)`` (n, 3) and Jacobian blocks ``C_j`` (n, 3, k) by
    ``L_j^-1`` (``L_j L_j^T = Sigma_j``, the measurement covariance's blocks): ``(y~ (3n,), C~ (3n, k),
    log|Sigma_m|)``. Raises LinAlgError when a ``Sigma_j`` is not positive definite."""
    L = np.linalg.cholesky(S)  # (n, 3, 3)
    sol = np.linalg.solve(L, np.concatenate([r[..., None], C], axis=2))  # (n, 3, 1 + k)
    logdet_m = 2.0 * float(np.sum(np.log(np.diagonal(L, axis1=1, axis2=2))))
    return sol[..., 0].reshape(-1), sol[..., 1:].reshape(-1, C.shape[2]), logdet_m


def information_update(Sigma_bar, y_w, C_w, logdet_m):
    """Eq. (3)'s Kalman update, Joseph form, and Eq. (9)'s likelihood, from :func:`whitened`'s
    quantities and the prior ``Sigma_bar`` (see the module docstring). Raises LinAlgError.

    Returns the correction ``K y`` (6,), the Joseph-form posterior covariance, the NIS and the log
    likelihood; the caller adds the correction to ``mu_bar`` (in its chart)."""
    L = np.linalg.cholesky(Sigma_bar)  # Sigma_bar = L L^T
    Lam = C_w.T @ C_w  # Lambda = C^T Sigma_m^-1 C
    g = C_w.T @ y_w  # g = C^T Sigma_m^-1 y
    eye = np.eye(Sigma_bar.shape[0])  # 6, or 6 + m with the calibration error
    B = eye + L.T @ Lam @ L  # B = I + L^T Lambda L, eigenvalues >= 1
    L_B = np.linalg.cholesky(B)
    Z = np.linalg.solve(L_B, L.T)  # Z = L_B^-1 L^T
    M = Z.T @ Z  # M = L B^-1 L^T = (Sigma_bar^-1 + Lambda)^-1
    dx = M @ g  # K y: the correction, mu = mu_bar + K y
    I_KC = eye - M @ Lam  # I - K C
    Sigma = (
        I_KC @ Sigma_bar @ I_KC.T + M @ Lam @ M.T
    )  # Joseph form: (I-KC) Sigma_bar (I-KC)^T + K Sigma_m K^T
    Sigma = 0.5 * (Sigma + Sigma.T)  # remove round-off asymmetry
    nis = float(y_w @ y_w - g @ dx)  # y^T S^-1 y (Woodbury)
    logdet_S = logdet_m + 2.0 * float(np.sum(np.log(np.diag(L_B))))  # log|S| = log|Sigma_m| + log|B|
    loglik = -0.5 * (nis + logdet_S + y_w.size * LOG_2PI)  # log N(y; 0, S), Eq. (9)
    return dx, Sigma, nis, loglik


def data_log_likelihood(
    d_C, b_O, Sigma_d, mu_bar, Sigma_bar, chart: OrientationChart = OrientationChart.EULER
) -> float:
    r"""Eq. (9) of the identification paper: the data likelihood of matched features, as a log.

    .. math::

        \log p(\mathbf{D}_k \mid \mathbf{D}_{1:k-1}, \mathbf{u}_{1:k-1}, M_i)
          = \log \mathcal{N}(\mathbf{D}_k;\ \mathbf{H}(\bar\mu),\ C \bar\Sigma C^T + \Sigma_m)

    The paper writes the mean as ``C mu_bar``, the linearisation ``H(X) ~ C X``; expanded about
    ``mu_bar`` (``H(X) ~ H(mu_bar) + C (X - mu_bar)``) the mean is ``H(mu_bar)``, which is what the
    EKF uses. Computed through the 6x6 form of the module docstring (no 3n x 3n matrix).

    Parameters
    ----------
    d_C, b_O : array_like, shape (n, 3) [m]
        Matched measured features (in C) and database features (in O); all rows are used.
    Sigma_d : array_like, shape (n, 3, 3) [m^2]
    mu_bar : array_like, shape (6,)
    Sigma_bar : array_like, shape (6, 6)
        Predicted state and covariance; the covariance over ``X`` (``EULER``) or over
        ``[x_r, phi]`` (``ROTATION_VECTOR``, e.g. ``PoseEstimate.Sigma_rv``), as ``chart`` says.
    chart : OrientationChart
        The coordinates of ``Sigma_bar``'s orientation part (the likelihood is the same in both,
        up to the linearisation; the rotation-vector chart stays finite at gimbal lock).

    Returns
    -------
    float
        The log density [log of 1/m^(3n)].
    """
    d, b, S = check_matches(d_C, b_O, Sigma_d)
    mu_bar = np.asarray(mu_bar, float)
    n = d.shape[0]
    r = d - measurement_model(mu_bar, b)
    jac = measurement_jacobian if chart is OrientationChart.EULER else measurement_jacobian_rv
    C = jac(mu_bar, b).reshape(n, 3, 6)
    y_w, C_w, logdet_m = whitened(r, C, S)
    return information_update(np.asarray(Sigma_bar, float), y_w, C_w, logdet_m)[3]


def _is_rotation(G) -> bool:
    """Is the 3x3 block a proper rotation (orthonormal to 1e-6, det +1)?"""
    R = G[:3, :3]
    if np.abs(R @ R.T - np.eye(3)).max() > 1e-6:
        return False
    det = R[0, 0] * (R[1, 1] * R[2, 2] - R[1, 2] * R[2, 1]) - R[0, 1] * (
        R[1, 0] * R[2, 2] - R[1, 2] * R[2, 0]
    )
    return bool(det + R[0, 2] * (R[1, 0] * R[2, 1] - R[1, 1] * R[2, 0]) > 0)


@dataclass(frozen=True)
class PendingUpdate:
    """An update between its checks and its linear algebra (:meth:`lab.estimation.PoseEKF.begin_update`):
    the used rows' residuals ``r`` (m, 3), Jacobians ``C`` (m, 3, k), covariances ``S`` (m, 3, 3) and
    database points ``b`` (m, 3), and the prior (k, k), with the calibration error when it is modelled;
    ``n`` rows were passed in, ``n_valid`` were usable (``note`` says how many were dropped), ``keep``
    marks the usable rows the gate passed and ``inliers`` the input rows used."""

    n: int
    n_valid: int
    note: str
    keep: np.ndarray
    inliers: np.ndarray
    prior: np.ndarray
    r: np.ndarray
    C: np.ndarray
    S: np.ndarray
    b: np.ndarray  # the used rows' database points (the database error's share, Sigma_m)


@dataclass(frozen=True)
class Motion:
    """One step's checked motion inputs (:func:`checked_motion`), shared by every filter of a bank: the
    transforms ``mats`` by name, the ``bad`` ones (non-finite or absurd), ``dt`` and the camera's own
    motion ``A``."""

    mats: dict
    bad: list
    dt: float
    A: np.ndarray | None  # G_{C(k) C(k-1)}, Eq. (1) without the object (None when ``bad``)


def checked_motion(G_RC_prev, G_RC, G_odom, dt, G_OO=None) -> Motion:
    """:meth:`lab.estimation.PoseEKF.predict`'s inputs (Eqs. (1)-(2)'s ``u``), checked (ValueError for
    wrong shapes, a non-rigid transform or a bad ``dt``); transforms that are non-finite or absurd
    (> 1 km) are listed in ``bad``. The camera's motion ``A = G_{C(k) C(k-1)}`` is computed here, once
    per step for all the filters of a bank."""
    mats = {"G_RC_prev": G_RC_prev, "G_RC": G_RC, "G_odom": G_odom}
    if G_OO is not None:
        mats["G_OO"] = G_OO
    mats = {k: np.asarray(v, dtype=float) for k, v in mats.items()}
    for name, G in mats.items():
        if G.shape != (4, 4):
            raise ValueError(f"{name} must be a 4x4 homogeneous transform, got shape {G.shape}")
    dt = float(dt)
    if not (math.isfinite(dt) and dt >= 0.0):
        raise ValueError(f"dt must be finite and >= 0 s, got {dt}")
    bad = [k for k, G in mats.items() if not (np.all(np.isfinite(G)) and np.abs(G[:3, 3]).max() <= 1e3)]
    if not bad:
        for name, G in mats.items():
            if not _is_rotation(G):
                raise ValueError(f"{name} is not a rigid transform (its 3x3 block is not a rotation)")
    A = None if bad else camera_motion(mats["G_RC_prev"], mats["G_RC"], mats["G_odom"])
    return Motion(mats, bad, dt, A)
