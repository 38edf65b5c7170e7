r"""The pose EKF's process noise ``eta`` of Eq. (2): the object's own motion, the odometry's error and
Eq. (4)'s floor, mapped into the predicted state as ``Q`` (:func:`process_noise_covariance`).

The object's motion is a random walk (:class:`ObjectNoiseKind`, :class:`ProcessNoise`); the robot's
odometry error is a twist in the robot frame (:func:`odometry_covariance`); both enter the predicted
state ``X_k`` through the first-order Jacobians of :func:`motion_noise_jacobians`, in either
orientation chart (:class:`lab.estimation.models.OrientationChart`).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

import numpy as np

from lab.estimation.models import (
    OrientationChart,
    check_G,
    check_state,
    euler_rate_matrix_inv,
    skew,
)
from lab.geometry import euler_zyx_to_R, se3_inv

__all__ = [
    "ObjectNoiseKind",
    "ProcessNoise",
    "motion_noise_jacobians",
    "odometry_covariance",
    "process_noise_covariance",
]


def motion_noise_jacobians(
    X, G_RC, chart: OrientationChart = OrientationChart.EULER
) -> tuple[np.ndarray, np.ndarray]:
    r"""How the object's and the robot's motion noise enter the predicted state ``X = X_k``.

    Returns ``(L_O, L_R)``, each (6, 6), such that to first order

    * ``G_{O(k-1)O(k)} = G_OO Exp(delta_O)`` (object twist ``delta_O = [rho, phi]`` in O(k): metres,
      radians) moves ``X_k`` by ``L_O delta_O``, with

      .. math:: L_O = \begin{bmatrix} R_k & 0 \\ 0 & E(x_o^k)^{-1} R_k \end{bmatrix};

    * ``G_{R(k-1)R(k)} = G_odom Exp(delta_R)`` (odometry error twist in R(k)) moves ``X_k`` by
      ``L_R delta_R``. It multiplies ``G_{C_k O_k}`` on the left by ``Exp(-Ad(G_CR) delta_R)``:

      .. math::

          L_R = -\begin{bmatrix} I & -[t_k]_\times \\ 0 & E(x_o^k)^{-1} \end{bmatrix}
                 \mathrm{Ad}(G_{C R}), \qquad
          \mathrm{Ad}(G) = \begin{bmatrix} R & [p]_\times R \\ 0 & R \end{bmatrix}

    Twists are ordered ``[translation (3), rotation (3)]``. In the rotation-vector chart every
    ``E^-1`` above is replaced by the identity.

    Parameters
    ----------
    X : array_like, shape (6,)
        The predicted state ``X_k`` (output of :func:`motion_model`).
    G_RC : ndarray, shape (4, 4)
        Camera in robot at step k.
    chart : OrientationChart
    """
    X = check_state(X)
    G_CR = se3_inv(check_G(G_RC, "G_RC"))
    R_k = euler_zyx_to_R(X[3], X[4], X[5])
    E_inv = euler_rate_matrix_inv(X[3], X[4]) if chart is OrientationChart.EULER else np.eye(3)
    L_O = np.zeros((6, 6))
    L_O[:3, :3] = R_k
    L_O[3:, 3:] = E_inv @ R_k
    R, p = G_CR[:3, :3], G_CR[:3, 3]
    Ad = np.zeros((6, 6))
    Ad[:3, :3] = R
    Ad[:3, 3:] = skew(p) @ R
    Ad[3:, 3:] = R
    left = np.zeros((6, 6))  # d X_k / d (left twist on G_CO(k))
    left[:3, :3] = np.eye(3)
    left[:3, 3:] = -skew(X[:3])
    left[3:, 3:] = E_inv
    L_R = -left @ Ad
    return L_O, L_R


class ObjectNoiseKind(Enum):
    """How the object's unknown velocity grows the covariance over a step of ``dt`` seconds."""

    #: The object moves with an unknown velocity (std ``sigma_v`` [m/s], ``sigma_w`` [rad/s]) held
    #: over the step: displacement std ``sigma_v * dt`` (variance grows with ``dt^2``). A random walk
    #: perturbed at the velocity level, as the identification paper assumes. The default.
    VELOCITY = "velocity"
    #: Continuous white-noise velocity (Brownian motion) of spectral density ``sigma_v^2``
    #: [m^2/s]: displacement variance ``sigma_v^2 * dt``. ``sigma_v`` is then in m/sqrt(s).
    WIENER = "wiener"


@dataclass(frozen=True)
class ProcessNoise:
    """The process noise ``eta`` of Eq. (2): object motion, odometry error and a small floor.

    Attributes
    ----------
    kind : ObjectNoiseKind
        How the object's velocity uncertainty scales with ``dt`` (see :class:`ObjectNoiseKind`).
    sigma_v : float [m/s]
        Std of the object's linear velocity along each of its axes (VELOCITY), or the square root
        of the spectral density [m/sqrt(s)] (WIENER).
    sigma_w : float [rad/s]
        The same for its angular velocity [rad/s] (VELOCITY) or [rad/sqrt(s)] (WIENER).
    eta_m, eta_rad : float
        Per-step std added straight to the position [m] and the Euler angles [rad]: the search
        paper's static model Eq. (4), ``X_k = X_{k-1} + eta``, which keeps the filter able to move
        even with ``dt = 0``.
    odom_trans_per_m : float [m/m]
        Odometry translation error std (along and across the motion) per metre travelled.
    odom_rot_per_rad : float [rad/rad]
        Odometry heading error std per radian turned.
    odom_rot_per_m : float [rad/m]
        Odometry heading error std per metre travelled.
    """

    kind: ObjectNoiseKind = ObjectNoiseKind.VELOCITY
    sigma_v: float = 0.15
    sigma_w: float = 0.3
    eta_m: float = 1e-3
    eta_rad: float = 2e-3
    odom_trans_per_m: float = 0.05
    odom_rot_per_rad: float = 0.05
    odom_rot_per_m: float = 0.02

    def __post_init__(self):
        for name in (
            "sigma_v",
            "sigma_w",
            "eta_m",
            "eta_rad",
            "odom_trans_per_m",
            "odom_rot_per_rad",
            "odom_rot_per_m",
        ):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"ProcessNoise.{name} must be finite and >= 0, got {v!r}")
        if not isinstance(self.kind, ObjectNoiseKind):
            raise ValueError(f"ProcessNoise.kind must be an ObjectNoiseKind, got {self.kind!r}")


def odometry_covariance(G_odom, noise: ProcessNoise) -> np.ndarray:
    """Covariance (6, 6) of the odometry error twist ``delta_R`` (in R(k)) for one increment.

    A basic wheel-odometry model for a planar robot: translation error std ``odom_trans_per_m * s``
    along x and y, heading error std ``odom_rot_per_rad * |dtheta| + odom_rot_per_m * s`` about z,
    ``s`` the distance travelled; nothing in z, roll or pitch. No motion, no error.
    """
    G_odom = check_G(G_odom, "G_odom")
    s = float(np.hypot(G_odom[0, 3], G_odom[1, 3]))
    dtheta = float(np.arctan2(G_odom[1, 0], G_odom[0, 0]))
    sig_t = noise.odom_trans_per_m * s
    sig_r = noise.odom_rot_per_rad * abs(dtheta) + noise.odom_rot_per_m * s
    return np.diag([sig_t**2, sig_t**2, 0.0, 0.0, 0.0, sig_r**2])


def process_noise_covariance(
    X,
    G_RC,
    G_odom,
    dt: float,
    noise: ProcessNoise,
    Sigma_odom=None,
    chart: OrientationChart = OrientationChart.EULER,
) -> np.ndarray:
    r"""``Q``, shape (6, 6): covariance of ``eta`` in Eq. (2) at the predicted state ``X = X_k``.

    .. math::

        Q = L_O \,\mathrm{diag}(\sigma_v^2 I, \sigma_\omega^2 I)\, s(dt)\, L_O^T
          + L_R\, \Sigma_{odom}\, L_R^T + \mathrm{diag}(\eta_m^2 I, \eta_{rad}^2 I)

    with ``s(dt) = dt^2`` (VELOCITY) or ``dt`` (WIENER), and ``L_O``, ``L_R`` from
    :func:`motion_noise_jacobians`.

    Parameters
    ----------
    X : array_like, shape (6,)
        Predicted state ``X_k``.
    G_RC : ndarray, shape (4, 4)
        Camera in robot at step k.
    G_odom : ndarray, shape (4, 4)
        Odometry increment ``G_{R(k-1)R(k)}`` (for the default odometry covariance).
    dt : float [s]
    noise : ProcessNoise
    Sigma_odom : ndarray, shape (6, 6), optional
        Odometry error covariance (twist in R(k)); :func:`odometry_covariance` if omitted.
    chart : OrientationChart
        Coordinates of the result's orientation part (``eta_rad`` is added in those coordinates).
    """
    L_O, L_R = motion_noise_jacobians(X, G_RC, chart)
    scale = dt * dt if noise.kind is ObjectNoiseKind.VELOCITY else dt
    q_obj = np.array([noise.sigma_v**2] * 3 + [noise.sigma_w**2] * 3) * scale
    if Sigma_odom is None:
        Sigma_odom = odometry_covariance(G_odom, noise)
    else:
        Sigma_odom = np.asarray(Sigma_odom, dtype=float)
        if Sigma_odom.shape != (6, 6):
            raise ValueError(f"Sigma_odom must have shape (6, 6), got {Sigma_odom.shape}")
    Q = (L_O * q_obj) @ L_O.T  # object's velocity-level random walk, mapped into X_k
    Q += L_R @ Sigma_odom @ L_R.T  # odometry error, mapped into X_k
    Q[np.diag_indices(6)] += np.array([noise.eta_m**2] * 3 + [noise.eta_rad**2] * 3)  # Eq. (4)'s eta
    return 0.5 * (Q + Q.T)
