r"""The pose EKF's measurement and motion models, with their analytic Jacobians.

The state is the identification paper's ``X = [x_r, x_o] = [x, y, z, alpha, beta, gamma]``: the
object frame O in the left camera's optical frame C (``G_CO``), translation in metres and z-y-x Euler
angles in radians, ``R(x_o) = Rz(alpha) Ry(beta) Rx(gamma)`` (see ``docs/conventions.md``).

Everything here is a pure function of explicit inputs; :mod:`lab.estimation.ekf` wires them into a
filter. Two small matrices carry all the Euler-angle calculus:

* the **Euler rate matrix** ``E(alpha, beta)`` maps Euler-angle rates to the angular velocity
  written in C (the "spatial" angular velocity),

  .. math::

      [\omega]_\times = \dot R R^T, \qquad \omega = E(\alpha, \beta)
      \begin{bmatrix}\dot\alpha \\ \dot\beta \\ \dot\gamma\end{bmatrix}, \qquad
      E = \begin{bmatrix} e_z & R_z(\alpha) e_y & R_z(\alpha) R_y(\beta) e_x \end{bmatrix}
        = \begin{bmatrix} 0 & -s_\alpha & c_\alpha c_\beta \\
                          0 &  c_\alpha & s_\alpha c_\beta \\
                          1 & 0 & -s_\beta \end{bmatrix}

* and its inverse, which exists away from gimbal lock (``cos(beta) != 0``).

With them every derivative of a rotation with respect to its Euler angles is a cross product:
``dR/dtheta_i = [E_i]_x R`` (``E_i`` the i-th column of ``E``).

Gimbal lock: at ``beta = +-pi/2`` (the object's x axis along the optical axis) the papers' Euler
parametrisation is singular: ``E`` loses rank, ``alpha`` and ``gamma`` turn about the same axis and
``E^-1`` blows up. The functions stay finite there (``cos(beta)`` is clamped at ``1e-12``) but the
filter's covariance then explodes, which :class:`lab.estimation.PoseEKF` reports as divergence.
With a level camera this happens whenever a box's x face looks straight at it.

**Two charts for the covariance.** The state ``X`` is always the papers' Euler pose. Its uncertainty
can be kept over the Euler angles themselves (:attr:`OrientationChart.EULER`, the papers' filter) or
over a small rotation vector ``phi`` in C, ``R_true = Exp(phi) R(x_o)`` (:attr:`OrientationChart.
ROTATION_VECTOR`, an "error-state" or multiplicative EKF), which has no singularity. The two are
related by ``[dx_r, phi] = T(X) dX`` with ``T = diag(I, E(alpha, beta))`` (:func:`euler_to_rv_jacobian`).
The ``*_rv`` variants of the Jacobians below are for the second chart; in it every ``E`` drops out.
"""

from __future__ import annotations

import math
from enum import Enum

import numpy as np

from lab.geometry import G_to_pose6, R_to_euler_zyx, euler_zyx_to_R, se3, se3_inv

__all__ = [
    "OrientationChart",
    "euler_to_rv_jacobian",
    "rv_to_euler_jacobian",
    "rotvec_to_R",
    "retract_rv",
    "measurement_jacobian_rv",
    "euler_rate_matrix",
    "euler_rate_matrix_inv",
    "measurement_model",
    "measurement_jacobian",
    "measurement_covariance",
    "motion_model",
    "motion_jacobian",
    "skew",
    "state_residual",
    "canonical_state",
]

_COS_BETA_FLOOR = 1e-12  # keeps E^-1 finite at gimbal lock; the filter flags the blow-up


def skew(v) -> np.ndarray:
    """Cross-product matrix ``[v]_x`` with ``[v]_x w = v x w``; shape (3, 3) or (n, 3, 3) for (n, 3)."""
    v = np.asarray(v, dtype=float)
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def euler_rate_matrix(alpha: float, beta: float) -> np.ndarray:
    r"""``E(alpha, beta)``, shape (3, 3): z-y-x Euler rates [rad/s] -> angular velocity in C [rad/s].

    .. math:: \omega = E \dot{x}_o, \quad
        E = \begin{bmatrix} 0 & -s_\alpha & c_\alpha c_\beta \\ 0 & c_\alpha & s_\alpha c_\beta \\
        1 & 0 & -s_\beta \end{bmatrix}

    Its columns are the three rotation axes written in C: ``e_z``, ``Rz(alpha) e_y`` and
    ``Rz(alpha) Ry(beta) e_x``. It does not depend on ``gamma``.
    """
    ca, sa = np.cos(alpha), np.sin(alpha)
    cb, sb = np.cos(beta), np.sin(beta)
    return np.array([[0.0, -sa, ca * cb], [0.0, ca, sa * cb], [1.0, 0.0, -sb]])


def euler_rate_matrix_inv(alpha: float, beta: float) -> np.ndarray:
    r"""``E(alpha, beta)^-1``, shape (3, 3): angular velocity in C -> z-y-x Euler rates.

    .. math:: E^{-1} = \begin{bmatrix} t_\beta c_\alpha & t_\beta s_\alpha & 1 \\
        -s_\alpha & c_\alpha & 0 \\ c_\alpha / c_\beta & s_\alpha / c_\beta & 0 \end{bmatrix}

    Singular at gimbal lock (``cos(beta) = 0``); ``cos(beta)`` is clamped at 1e-12 there so the
    result stays finite (and huge).
    """
    ca, sa = np.cos(alpha), np.sin(alpha)
    cb, sb = np.cos(beta), np.sin(beta)
    if abs(cb) < _COS_BETA_FLOOR:
        cb = _COS_BETA_FLOOR if cb >= 0 else -_COS_BETA_FLOOR
    return np.array([[sb / cb * ca, sb / cb * sa, 1.0], [-sa, ca, 0.0], [ca / cb, sa / cb, 0.0]])


def check_state(X) -> np.ndarray:
    """The state ``X`` as a float array of shape (6,); ValueError for any other shape."""
    X = np.asarray(X, dtype=float)
    if X.shape != (6,):
        raise ValueError(f"state X must have shape (6,) = [x, y, z, alpha, beta, gamma], got {X.shape}")
    return X


def _check_points(b_O, name: str = "b_O") -> np.ndarray:
    b = np.asarray(b_O, dtype=float)
    if b.ndim != 2 or b.shape[1] != 3:
        raise ValueError(f"{name} must have shape (n, 3) [m], got {b.shape}")
    return b


def check_G(G, name: str) -> np.ndarray:
    """The homogeneous transform ``G`` (called ``name`` in the error) as a float (4, 4) array; ValueError
    for any other shape."""
    G = np.asarray(G, dtype=float)
    if G.shape != (4, 4):
        raise ValueError(f"{name} must be a 4x4 homogeneous transform, got shape {G.shape}")
    return G


def measurement_model(X, b_O) -> np.ndarray:
    r"""Predicted 3D feature positions in C: ``H(X, J)`` of Eq. (3) (identification paper), Eq. (5)
    (search paper).

    .. math:: \mathbf{d}_j = \mathbf{x}_r + R(\mathbf{x}_o)\, \mathbf{b}_{J(j)} \;(+\, \xi)

    Parameters
    ----------
    X : array_like, shape (6,) [m, rad]
        Object pose in C, ``[x, y, z, alpha, beta, gamma]``.
    b_O : array_like, shape (n, 3) [m]
        The matched database features ``b_{J(j)}``, in the object frame O (row j matches ``d_j``).

    Returns
    -------
    d_C : ndarray, shape (n, 3) [m]
    """
    X = check_state(X)
    b = _check_points(b_O)
    R = euler_zyx_to_R(X[3], X[4], X[5])
    return b @ R.T + X[:3]


def measurement_jacobian(X, b_O) -> np.ndarray:
    r"""``C = dH/dX`` of the measurement model Eq. (3), shape (3n, 6), analytic.

    Rows ``3j .. 3j+2`` belong to feature ``j`` (the same stacking as ``H``). With ``q_j = R b_j``
    (the feature rotated into C) and ``E`` the Euler rate matrix:

    .. math::

        \frac{\partial \mathbf{d}_j}{\partial \mathbf{x}_r} = I_3, \qquad
        \frac{\partial \mathbf{d}_j}{\partial \theta_i} = \frac{\partial R}{\partial \theta_i}
        \mathbf{b}_j = E_i \times \mathbf{q}_j
        \quad\Longrightarrow\quad
        C_j = \begin{bmatrix} I_3 & -[\mathbf{q}_j]_\times E(\alpha, \beta) \end{bmatrix}

    because ``dR/dalpha = [e_z]_x R``, ``dR/dbeta = Rz [e_y]_x Ry Rx = [Rz e_y]_x R`` and
    ``dR/dgamma = R [e_x]_x = [Rz Ry e_x]_x R``.

    Parameters
    ----------
    X : array_like, shape (6,) [m, rad]
    b_O : array_like, shape (n, 3) [m]

    Returns
    -------
    C : ndarray, shape (3n, 6)
        Translation columns dimensionless, angle columns in m/rad.
    """
    X = check_state(X)
    b = _check_points(b_O)
    n = b.shape[0]
    q = b @ euler_zyx_to_R(X[3], X[4], X[5]).T  # q_j = R b_j, shape (n, 3)
    E = euler_rate_matrix(X[3], X[4])
    C = np.zeros((n, 3, 6))
    C[:, 0, 0] = C[:, 1, 1] = C[:, 2, 2] = 1.0
    C[:, :, 3:] = -skew(q) @ E  # d d_j / d x_o = -[q_j]_x E
    return C.reshape(3 * n, 6)


class OrientationChart(Enum):
    """Coordinates of the orientation part of the filter's covariance (the state is Euler in both)."""

    #: Covariance over ``(alpha, beta, gamma)``: the papers' EKF. Singular at ``beta = +-pi/2``.
    EULER = "euler"
    #: Covariance over a small rotation vector ``phi`` in C with ``R_true = Exp(phi) R``: no singularity.
    ROTATION_VECTOR = "rotation_vector"


def euler_to_rv_jacobian(X) -> np.ndarray:
    """``T = diag(I, E(alpha, beta))``, shape (6, 6): Euler-state differentials -> ``[dx_r, phi]``.

    Covariances convert as ``Sigma_rv = T Sigma T^T`` and ``Sigma = T^-1 Sigma_rv T^-T``
    (``T^-1 = diag(I, E^-1)``, :func:`rv_to_euler_jacobian`).
    """
    X = check_state(X)
    T = np.eye(6)
    T[3:, 3:] = euler_rate_matrix(X[3], X[4])
    return T


def rv_to_euler_jacobian(X) -> np.ndarray:
    """``T^-1 = diag(I, E(alpha, beta)^-1)``, shape (6, 6): ``[dx_r, phi]`` -> Euler-state differentials."""
    X = check_state(X)
    T = np.eye(6)
    T[3:, 3:] = euler_rate_matrix_inv(X[3], X[4])
    return T


def rotvec_to_R(phi) -> np.ndarray:
    r"""``Exp(phi)``: the rotation by ``|phi|`` radians about ``phi`` (Rodrigues' formula), shape (3, 3).

    .. math:: \mathrm{Exp}(\phi) = I + \frac{\sin\theta}{\theta} [\phi]_\times
        + \frac{1 - \cos\theta}{\theta^2} [\phi]_\times^2, \qquad \theta = |\phi|
    """
    phi = np.asarray(phi, dtype=float)
    th2 = float(phi @ phi)
    K = skew(phi)
    if th2 < 1e-12:  # Taylor terms: exact to double precision here
        a, b = 1.0 - th2 / 6.0, 0.5 - th2 / 24.0
    else:
        th = math.sqrt(th2)
        a, b = math.sin(th) / th, (1.0 - math.cos(th)) / th2
    return np.eye(3) + a * K + b * (K @ K)


def retract_rv(X, delta) -> np.ndarray:
    """Apply a correction ``delta = [dx_r, phi]`` (rotation-vector chart): ``x_r + dx_r``,
    ``R <- Exp(phi) R``; returns the Euler state (canonical ranges)."""
    X = check_state(X)
    delta = np.asarray(delta, dtype=float)
    R = rotvec_to_R(delta[3:]) @ euler_zyx_to_R(X[3], X[4], X[5])
    return np.concatenate([X[:3] + delta[:3], R_to_euler_zyx(R)])


def measurement_jacobian_rv(X, b_O) -> np.ndarray:
    r"""``C`` in the rotation-vector chart, shape (3n, 6): ``C_j = [I_3, -[q_j]_x]``, ``q_j = R b_j``.

    .. math:: \frac{\partial}{\partial \phi} \left(\mathrm{Exp}(\phi) R\, b_j\right)\Big|_0
        = -[R b_j]_\times

    (:func:`measurement_jacobian` times ``T^-1``: the ``E`` drops out.)
    """
    X = check_state(X)
    b = _check_points(b_O)
    n = b.shape[0]
    q = b @ euler_zyx_to_R(X[3], X[4], X[5]).T
    C = np.zeros((n, 3, 6))
    C[:, 0, 0] = C[:, 1, 1] = C[:, 2, 2] = 1.0
    C[:, :, 3:] = -skew(q)
    return C.reshape(3 * n, 6)


def measurement_covariance(Sigma_d) -> np.ndarray:
    """``Sigma_m`` of Eq. (3): block-diagonal (3n, 3n) from per-feature covariances (n, 3, 3) [m^2].

    The filter never forms this matrix (it works with the blocks); it is here for teaching and tests.
    """
    S = np.asarray(Sigma_d, dtype=float)
    if S.ndim != 3 or S.shape[1:] != (3, 3):
        raise ValueError(f"Sigma_d must have shape (n, 3, 3) [m^2], got {S.shape}")
    n = S.shape[0]
    out = np.zeros((3 * n, 3 * n))
    idx = np.arange(n)[:, None, None] * 3
    rows = idx + np.arange(3)[None, :, None]
    cols = idx + np.arange(3)[None, None, :]
    out[rows, cols] = S
    return out


def camera_motion(G_RC_prev, G_RC, G_odom) -> np.ndarray:
    """``G_{C(k) C(k-1)} = G_RC(k)^-1 G_{R(k-1)R(k)}^-1 G_RC(k-1)``: the previous camera in the new one."""
    return se3_inv(G_RC) @ se3_inv(G_odom) @ G_RC_prev


def motion_model(X_prev, G_RC_prev, G_RC, G_odom, G_OO=None) -> np.ndarray:
    r"""Mean of the motion model, Eqs. (1)-(2) of the identification paper: ``X_k = F(X_{k-1}, u)``.

    .. math::

        G_{C_k O_k} = G_{R_k C_k}^{-1}\, G_{R_{k-1} R_k}^{-1}\, G_{R_{k-1} C_{k-1}}\,
        G_{C_{k-1} O_{k-1}}\, G_{O_{k-1} O_k}

    and ``X_k`` is read off ``G_{C_k O_k}`` (translation and z-y-x Euler angles, ``alpha``, ``gamma``
    wrapped to (-pi, pi], ``beta`` in [-pi/2, pi/2]). With identity increments this is the search
    paper's static model Eq. (4), ``X_k = X_{k-1}`` (+ noise).

    Parameters
    ----------
    X_prev : array_like, shape (6,) [m, rad]
        ``X_{k-1}``, the object in the camera frame at step k-1.
    G_RC_prev, G_RC : ndarray, shape (4, 4)
        Camera in the robot frame at k-1 and k (from the pan-tilt state, ``StereoCamera.G_RC``).
    G_odom : ndarray, shape (4, 4)
        ``G_{R(k-1) R(k)}``: the robot at k seen from the robot at k-1 (odometry increment,
        ``lab.geometry.relative_pose2d``).
    G_OO : ndarray, shape (4, 4), optional
        ``G_{O(k-1) O(k)}``, the object's own motion; identity (the random walk's mean) if omitted.

    Returns
    -------
    X : ndarray, shape (6,) [m, rad]
    """
    A, G_OO = _motion_inputs(G_RC_prev, G_RC, G_odom, G_OO)
    return motion_step(check_state(X_prev), A, G_OO, jacobian=False)[0]


def motion_jacobian(
    X_prev, G_RC_prev, G_RC, G_odom, G_OO=None, chart: OrientationChart = OrientationChart.EULER
) -> np.ndarray:
    r"""``F = dF/dX_{k-1}`` of the motion model Eq. (2), shape (6, 6), analytic.

    Write ``A = G_{C_k C_{k-1}} = (R_A, t_A)`` for the camera's own motion and ``G_OO = (R_o, p_o)``.
    Then ``t_k = R_A (t + R p_o) + t_A`` and ``R_k = R_A R R_o``. A change ``d x_o`` of the previous
    angles turns ``R`` by the angular velocity ``E(x_o) d x_o`` (in C_{k-1}), i.e. ``R_k`` by
    ``R_A E(x_o) d x_o`` in C_k, which the new angles absorb through ``E(x_o^k)^-1``:

    .. math::

        F = \begin{bmatrix} R_A & -R_A [R\, p_o]_\times E(x_o) \\
                             0   & E(x_o^{k})^{-1} R_A E(x_o) \end{bmatrix}

    Analytic rather than numerical: it is exact, cheap (a few 3x3 products), and the tests check it
    against central differences of :func:`motion_model`. Singular at gimbal lock of ``X_k``.

    In the rotation-vector chart (``chart=ROTATION_VECTOR``, errors ``[dx_r, phi]`` with
    ``R_true = Exp(phi) R``) the ``E`` matrices drop out:
    ``F = [[R_A, -R_A [R p_o]_x], [0, R_A]]``.
    """
    A, G_OO = _motion_inputs(G_RC_prev, G_RC, G_odom, G_OO)
    return motion_step(check_state(X_prev), A, G_OO, jacobian=True, chart=chart)[1]


def _motion_inputs(G_RC_prev, G_RC, G_odom, G_OO):
    A = camera_motion(check_G(G_RC_prev, "G_RC_prev"), check_G(G_RC, "G_RC"), check_G(G_odom, "G_odom"))
    return A, (None if G_OO is None else check_G(G_OO, "G_OO"))


def motion_step(X_prev, A, G_OO, jacobian: bool, chart: OrientationChart = OrientationChart.EULER):
    """``X_k`` (Eq. (1)) and, if asked, ``F`` for the camera motion ``A = G_{C_k C_{k-1}}``
    (:func:`camera_motion`): :func:`motion_model` and :func:`motion_jacobian` on checked inputs."""
    R = euler_zyx_to_R(X_prev[3], X_prev[4], X_prev[5])
    G = A @ se3(R, X_prev[:3])
    if G_OO is not None:
        G = G @ G_OO
    X = G_to_pose6(G)
    if not jacobian:
        return X, None
    R_A = A[:3, :3]
    euler = chart is OrientationChart.EULER
    E_prev = euler_rate_matrix(X_prev[3], X_prev[4]) if euler else np.eye(3)
    F = np.zeros((6, 6))
    F[:3, :3] = R_A
    if G_OO is not None:
        F[:3, 3:] = -R_A @ skew(R @ G_OO[:3, 3]) @ E_prev
    F[3:, 3:] = (euler_rate_matrix_inv(X[3], X[4]) @ R_A @ E_prev) if euler else R_A
    return X, F


def _wrap(a: float) -> float:
    """A scalar angle wrapped to (-pi, pi] (plain floats: this runs every step)."""
    w = (a + math.pi) % (2.0 * math.pi) - math.pi
    return math.pi if w == -math.pi else w


def canonical_state(X, Sigma=None):
    """Bring Euler angles to the canonical range: ``beta`` in [-pi/2, pi/2], ``alpha``, ``gamma``
    wrapped to (-pi, pi].

    ``(alpha, beta, gamma)`` and ``(alpha + pi, pi - beta, gamma + pi)`` are the same rotation; the
    map between them is linear (``beta`` changes sign), so the covariance follows exactly by flipping
    the sign of ``beta``'s row and column.

    Returns
    -------
    X : ndarray, shape (6,)
    Sigma : ndarray, shape (6, 6) or None
    """
    X = np.array(X, dtype=float)
    b = _wrap(float(X[4]))
    flip = abs(b) > math.pi / 2
    if flip:
        X[3] += math.pi
        X[5] += math.pi
        b = (math.pi - b) if b > 0 else (-math.pi - b)
    X[4] = b
    X[3] = _wrap(float(X[3]))
    X[5] = _wrap(float(X[5]))
    if Sigma is None:
        return X, None
    Sigma = np.array(Sigma, dtype=float)
    if flip:
        Sigma[4, :] *= -1.0
        Sigma[:, 4] *= -1.0
    return X, Sigma


def state_residual(X_a, X_b) -> np.ndarray:
    """``X_a - X_b`` with the angle components wrapped to (-pi, pi] (both brought to canonical form)."""
    a, _ = canonical_state(check_state(X_a))
    b, _ = canonical_state(check_state(X_b))
    r = a - b
    r[3:] = [_wrap(float(v)) for v in r[3:]]
    return r
