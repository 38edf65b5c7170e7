r"""Assignment 1: the pose EKF -- measurement model, Jacobian, update and data likelihood.

The state is the papers' 6-DOF pose of the object O in the left camera's frame C,

    X = [x_r, x_o] = [x, y, z, alpha, beta, gamma]      (metres, radians)

with z-y-x Euler angles, ``R(x_o) = Rz(alpha) Ry(beta) Rx(gamma)`` (docs/conventions.md). A frame's
measurement is ``n`` 3D SIFT features ``d_j`` in C (from stereo), each matched to a database feature
``b_{J(j)}`` in O. The measurement model (identification paper Eq. (3), search paper Eq. (5)) is

    d_j = x_r + R(x_o) b_{J(j)} + xi,      xi ~ N(0, Sigma_m)

stacked feature by feature into a vector of length 3n: ``D = [d_0; d_1; ...]``, so rows ``3j .. 3j+2``
of every stacked vector or matrix belong to feature ``j``.

Write the five functions below with NumPy (no ``lab`` imports). Run the public tests with
``python -m pytest test_ekf.py``; the graded tests check more (values against independent references,
the Jacobian against finite differences, the filter's consistency over many seeded runs).
"""

import numpy as np


def rotation_zyx(alpha: float, beta: float, gamma: float) -> np.ndarray:
    r"""The rotation matrix of z-y-x Euler angles, the papers' ``R(x_o)``.

    .. math:: R(\alpha, \beta, \gamma) = R_z(\alpha)\, R_y(\beta)\, R_x(\gamma)

    Parameters
    ----------
    alpha, beta, gamma : float [rad]
        Yaw about z, then pitch about the new y, then roll about the newest x.

    Returns
    -------
    R : ndarray, shape (3, 3)
        Maps a vector written in O into C: ``v_C = R @ v_O``.
    """
    ### BEGIN SOLUTION
    ca, sa = np.cos(alpha), np.sin(alpha)
    cb, sb = np.cos(beta), np.sin(beta)
    cg, sg = np.cos(gamma), np.sin(gamma)
    Rz = np.array([[ca, -sa, 0.0], [sa, ca, 0.0], [0.0, 0.0, 1.0]])
    Ry = np.array([[cb, 0.0, sb], [0.0, 1.0, 0.0], [-sb, 0.0, cb]])
    Rx = np.array([[1.0, 0.0, 0.0], [0.0, cg, -sg], [0.0, sg, cg]])
    return Rz @ Ry @ Rx
    ### END SOLUTION


def measurement_model(X, b_O) -> np.ndarray:
    r"""The predicted features ``H(X, J)`` of Eq. (3): every database feature moved into C.

    .. math:: \mathbf{d}_j = \mathbf{x}_r + R(\mathbf{x}_o)\, \mathbf{b}_{J(j)}

    Parameters
    ----------
    X : array_like, shape (6,) [m, rad]
        Pose ``[x, y, z, alpha, beta, gamma]`` of O in C.
    b_O : array_like, shape (n, 3) [m]
        The matched database features ``b_{J(j)}`` in O; row ``j`` is matched to ``d_j``.

    Returns
    -------
    d_C : ndarray, shape (n, 3) [m]
        Row ``j`` is the predicted ``d_j`` (also for ``n = 1``: shape (1, 3)).
    """
    ### BEGIN SOLUTION
    X = np.asarray(X, dtype=float)
    b = np.asarray(b_O, dtype=float).reshape(-1, 3)
    R = rotation_zyx(X[3], X[4], X[5])
    return b @ R.T + X[:3]
    ### END SOLUTION


def measurement_jacobian(X, b_O) -> np.ndarray:
    r"""The Jacobian ``C = dH/dX`` of Eq. (3), analytic (the ``C_{k,i}`` of Eq. (9)).

    .. math::

        \frac{\partial \mathbf{d}_j}{\partial \mathbf{x}_r} = I_3, \qquad
        \frac{\partial \mathbf{d}_j}{\partial \alpha} = \frac{\partial R}{\partial \alpha}\mathbf{b}_j
        = R_z'(\alpha) R_y(\beta) R_x(\gamma)\, \mathbf{b}_j, \quad \text{and likewise for } \beta, \gamma

    Parameters
    ----------
    X : array_like, shape (6,) [m, rad]
    b_O : array_like, shape (n, 3) [m]

    Returns
    -------
    C : ndarray, shape (3n, 6)
        Rows ``3j .. 3j+2`` are ``d d_j / dX``; columns follow ``X``: three translation columns
        (dimensionless) then alpha, beta, gamma [m/rad].
    """
    ### BEGIN SOLUTION
    X = np.asarray(X, dtype=float)
    b = np.asarray(b_O, dtype=float).reshape(-1, 3)
    ca, sa = np.cos(X[3]), np.sin(X[3])
    cb, sb = np.cos(X[4]), np.sin(X[4])
    cg, sg = np.cos(X[5]), np.sin(X[5])
    Rz = np.array([[ca, -sa, 0.0], [sa, ca, 0.0], [0.0, 0.0, 1.0]])
    Ry = np.array([[cb, 0.0, sb], [0.0, 1.0, 0.0], [-sb, 0.0, cb]])
    Rx = np.array([[1.0, 0.0, 0.0], [0.0, cg, -sg], [0.0, sg, cg]])
    dRz = np.array([[-sa, -ca, 0.0], [ca, -sa, 0.0], [0.0, 0.0, 0.0]])  # d Rz / d alpha
    dRy = np.array([[-sb, 0.0, cb], [0.0, 0.0, 0.0], [-cb, 0.0, -sb]])  # d Ry / d beta
    dRx = np.array([[0.0, 0.0, 0.0], [0.0, -sg, -cg], [0.0, cg, -sg]])  # d Rx / d gamma
    dR = (dRz @ Ry @ Rx, Rz @ dRy @ Rx, Rz @ Ry @ dRx)
    n = b.shape[0]
    C = np.zeros((n, 3, 6))
    C[:, :, :3] = np.eye(3)  # d d_j / d x_r
    for k in range(3):
        C[:, :, 3 + k] = b @ dR[k].T  # d d_j / d theta_k = (dR/dtheta_k) b_j
    return C.reshape(3 * n, 6)
    ### END SOLUTION


def kalman_update(mu_bar, Sigma_bar, y, C, Sigma_m):
    r"""The (extended) Kalman filter's measurement update, covariance in Joseph form.

    .. math::

        S = C \bar\Sigma C^T + \Sigma_m, \qquad K = \bar\Sigma C^T S^{-1} \\
        \mu = \bar\mu + K y, \qquad
        \Sigma = (I - K C)\, \bar\Sigma\, (I - K C)^T + K \Sigma_m K^T \quad \text{(Joseph form)}

    The Joseph form equals ``(I - K C) Sigma_bar`` in exact arithmetic but stays symmetric and
    positive definite under round-off. Use ``np.linalg.solve`` rather than an explicit inverse.

    Parameters
    ----------
    mu_bar : array_like, shape (6,)
        Predicted state.
    Sigma_bar : array_like, shape (6, 6)
        Predicted covariance (symmetric positive definite).
    y : array_like, shape (m,)
        Innovation ``D - H(mu_bar)`` [m].
    C : array_like, shape (m, 6)
        Measurement Jacobian at ``mu_bar``.
    Sigma_m : array_like, shape (m, m) [m^2]
        Measurement noise covariance (symmetric positive definite).

    Returns
    -------
    mu : ndarray, shape (6,)
    Sigma : ndarray, shape (6, 6)
    """
    ### BEGIN SOLUTION
    mu_bar = np.asarray(mu_bar, dtype=float)
    Sigma_bar = np.asarray(Sigma_bar, dtype=float)
    y = np.asarray(y, dtype=float)
    C = np.asarray(C, dtype=float)
    Sigma_m = np.asarray(Sigma_m, dtype=float)
    S = C @ Sigma_bar @ C.T + Sigma_m  # innovation covariance
    K = np.linalg.solve(S, C @ Sigma_bar).T  # K = Sigma_bar C^T S^-1 (S and Sigma_bar symmetric)
    mu = mu_bar + K @ y
    I_KC = np.eye(mu_bar.size) - K @ C
    Sigma = I_KC @ Sigma_bar @ I_KC.T + K @ Sigma_m @ K.T  # Joseph form
    return mu, 0.5 * (Sigma + Sigma.T)
    ### END SOLUTION


def data_log_likelihood(y, C, Sigma_bar, Sigma_m) -> float:
    r"""The log data likelihood of Eq. (9), the input of the model probabilities of Eq. (7).

    .. math::

        \log p(\mathbf{D}_k \mid \mathbf{D}_{1:k-1}, M_i) = \log \mathcal{N}(y;\ 0,\ S)
        = -\tfrac12 \left( y^T S^{-1} y + \log\lvert S\rvert + m \log 2\pi \right),
        \qquad S = C \bar\Sigma C^T + \Sigma_m

    (``y = D - H(mu_bar)``: the Gaussian of Eq. (9) written in the innovation). Compute it in log
    space (a Cholesky factor of ``S``, or ``np.linalg.slogdet``): with many features the density
    itself underflows to 0.

    Parameters
    ----------
    y : array_like, shape (m,) [m]
    C : array_like, shape (m, 6)
    Sigma_bar : array_like, shape (6, 6)
    Sigma_m : array_like, shape (m, m) [m^2]

    Returns
    -------
    float
        Natural log of the density [log(1/m^m)].
    """
    ### BEGIN SOLUTION
    y = np.asarray(y, dtype=float)
    C = np.asarray(C, dtype=float)
    S = C @ np.asarray(Sigma_bar, dtype=float) @ C.T + np.asarray(Sigma_m, dtype=float)
    L = np.linalg.cholesky(S)
    z = np.linalg.solve(L, y)  # z^T z = y^T S^-1 y
    log_det_S = 2.0 * np.sum(np.log(np.diag(L)))
    return float(-0.5 * (z @ z + log_det_S + y.size * np.log(2.0 * np.pi)))
    ### END SOLUTION


def ekf_update(mu_bar, Sigma_bar, d_C, b_O, Sigma_m):
    r"""One EKF measurement update with a frame of matched features: Eq. (3) linearised at ``mu_bar``.

    Put your functions together: the innovation ``y = D - H(mu_bar)`` (stacked feature by feature),
    the Jacobian ``C`` at ``mu_bar``, then :func:`kalman_update`. The graded tests keep the angles
    far from +-pi and from gimbal lock (``beta = +-pi/2``), so no angle wrapping is needed.

    Parameters
    ----------
    mu_bar : array_like, shape (6,) [m, rad]
    Sigma_bar : array_like, shape (6, 6)
    d_C : array_like, shape (n, 3) [m]
        Measured features in C; row ``j`` matches ``b_O[j]``.
    b_O : array_like, shape (n, 3) [m]
    Sigma_m : array_like, shape (3n, 3n) [m^2]
        Measurement covariance of the stacked ``D``.

    Returns
    -------
    mu : ndarray, shape (6,)
    Sigma : ndarray, shape (6, 6)
    """
    ### BEGIN SOLUTION
    mu_bar = np.asarray(mu_bar, dtype=float)
    y = (np.asarray(d_C, dtype=float) - measurement_model(mu_bar, b_O)).reshape(-1)  # D - H(mu_bar)
    C = measurement_jacobian(mu_bar, b_O)
    return kalman_update(mu_bar, Sigma_bar, y, C, Sigma_m)
    ### END SOLUTION
