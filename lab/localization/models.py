r"""The planar motion and measurement models of the localizer, with their Jacobians.

The robot's pose is :math:`x = [x, y, \theta]^T` in the world W.

* **motion**: between two odometry readings the base moved by :math:`u = [\Delta x, \Delta y,
  \Delta\theta]^T`, written in the earlier odometry pose's frame (:func:`odometry_increment`); the
  motion model composes it onto the estimate (:func:`motion_model`, and :func:`calibrated_motion_model`
  on the state that also carries the odometry's turn scale and curvature bias);
* **measurement**: a landmark of known planar pose ``l`` in W, seen from the robot, is measured as its
  planar pose in the robot frame R, :math:`z` (:func:`observation_of`, from a stereo fit ``G_CL`` and
  the pan-tilt transform ``G_RC``); its model is :func:`measurement_model`, and
  :func:`pose_from_observation` solves it for the robot's pose.

The filter that uses them is :mod:`lab.localization.filter`.
"""

from __future__ import annotations

import math

import numpy as np

from lab.geometry import Pose2D, wrap_angle

__all__ = [
    "calibrated_motion_jacobians",
    "calibrated_motion_model",
    "measurement_jacobian",
    "measurement_model",
    "motion_jacobians",
    "motion_model",
    "observation_of",
    "odometry_increment",
    "pose_from_observation",
    "spin_fraction",
]


def odometry_increment(a: Pose2D, b: Pose2D) -> np.ndarray:
    r"""The motion ``u = [dx, dy, dtheta]`` from odometry pose ``a`` to ``b``, written in ``a``'s frame.

    .. math:: [\Delta x, \Delta y]^T = R(\theta_a)^T [x_b - x_a, y_b - y_a]^T, \quad
              \Delta\theta = \mathrm{wrap}(\theta_b - \theta_a)
    """
    c, s = math.cos(a.theta), math.sin(a.theta)
    dx, dy = b.x - a.x, b.y - a.y
    return np.array([c * dx + s * dy, -s * dx + c * dy, wrap_angle(b.theta - a.theta)])


def motion_model(x, u) -> np.ndarray:
    r"""``f(x, u)``: the pose ``x = [x, y, theta]`` moved by the increment ``u`` (in its own frame).

    .. math:: f(x, u) = [x + \Delta x \cos\theta - \Delta y \sin\theta,\;
                         y + \Delta x \sin\theta + \Delta y \cos\theta,\; \theta + \Delta\theta]^T
    """
    x = np.asarray(x, float)
    dx, dy, dth = np.asarray(u, float)
    c, s = math.cos(x[2]), math.sin(x[2])
    return np.array([x[0] + c * dx - s * dy, x[1] + s * dx + c * dy, wrap_angle(x[2] + dth)])


def motion_jacobians(x, u) -> tuple[np.ndarray, np.ndarray]:
    r"""``F = df/dx`` and ``V = df/du`` of :func:`motion_model`, both (3, 3).

    .. math:: F = \begin{bmatrix} 1 & 0 & -\Delta x \sin\theta - \Delta y \cos\theta \\
                                  0 & 1 & \Delta x \cos\theta - \Delta y \sin\theta \\
                                  0 & 0 & 1 \end{bmatrix}, \qquad
              V = \begin{bmatrix} R(\theta) & 0 \\ 0 & 1 \end{bmatrix}
    """
    dx, dy, _ = np.asarray(u, float)
    c, s = math.cos(float(x[2])), math.sin(float(x[2]))
    F = np.array([[1.0, 0.0, -s * dx - c * dy], [0.0, 1.0, c * dx - s * dy], [0.0, 0.0, 1.0]])
    V = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return F, V


def spin_fraction(u, half_track_m: float) -> float:
    r"""The share of an increment ``u``'s wheel travel that is a spin, in ``[0, 1]``: each wheel's travel
    from the turn over that plus the forward distance,

    .. math:: \phi(u) = \frac{h\, |\Delta\theta|}{|\Delta x| + h\, |\Delta\theta|}, \quad h = b / 2

    (1 for a turn in place, 0 for a straight drive; 0 for no motion). A base scrubs its wheels sideways
    in proportion to it, so the over-count of a turn grows with it (:func:`calibrated_motion_model`)."""
    dx, dth = float(u[0]), float(u[2])
    turn = half_track_m * abs(dth)
    return turn / (abs(dx) + turn) if turn > 0.0 else 0.0


def calibrated_motion_model(s, u, half_track_m: float = 0.0) -> np.ndarray:
    r"""``f(s, u)`` of the filter that calibrates its odometry: the state ``s = [x, y, theta, k, c]``
    adds the odometry's turn scale ``k`` and curvature bias ``c`` [rad/m] to the pose, constants of
    the base that the landmark updates estimate as they go (the augmented-state odometry calibration);
    ``s = [x, y, theta, k, c, sigma]`` adds the spin's slip ``sigma`` too.

    A real base measures its turns with a systematic error (the effective track is not the nominal one,
    the mean wheel radius is off: ``k``) and curves a straight drive (unequal wheels: ``c``); both add
    up turn after turn and metre after metre, which a noise that grows like a random walk cannot
    describe. The wheels also scrub sideways when the base spins, so they over-count a turn in place by
    more than a turn on a drive: ``sigma`` is that extra share, scaled by the increment's
    :func:`spin_fraction` ``phi`` on the nominal half-track ``half_track_m``. The pose is
    :func:`motion_model`'s with the heading change corrected:

    .. math:: f(s, u) = [x + \Delta x \cos\theta - \Delta y \sin\theta,\;
                         y + \Delta x \sin\theta + \Delta y \cos\theta,\;
                         \theta + (k - \sigma\, \phi(u))\, \Delta\theta + c\, \Delta x,\; k,\; c,\; \sigma]^T

    (``Delta x``, the increment's forward component, is the signed distance: a reversing base curves the
    other way). With one ``k`` alone, a spin teaches it the slip and a drive's turn is then corrected by
    it too.
    """
    s = np.asarray(s, float)
    _check_half_track(s, half_track_m)
    dx, dy, dth = np.asarray(u, float)
    turn = s[3] * dth + s[4] * dx
    if s.size == 6:
        turn -= s[5] * spin_fraction(u, half_track_m) * dth
    x = motion_model(s[:3], (dx, dy, turn))
    return np.concatenate([x, s[3:]])


def calibrated_motion_jacobians(s, u, half_track_m: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    r"""``F = df/ds`` (n, n) and ``V = df/du`` (n, 3) of :func:`calibrated_motion_model`, ``n`` 5 or 6.

    .. math:: F = \begin{bmatrix} 1 & 0 & -\Delta x \sin\theta - \Delta y \cos\theta & 0 & 0 & 0 \\
                                  0 & 1 & \Delta x \cos\theta - \Delta y \sin\theta & 0 & 0 & 0 \\
                                  0 & 0 & 1 & \Delta\theta & \Delta x & -\phi\, \Delta\theta \\
                                  0 & 0 & 0 & 1 & 0 & 0 \\ 0 & 0 & 0 & 0 & 1 & 0 \\
                                  0 & 0 & 0 & 0 & 0 & 1 \end{bmatrix}, \qquad
              V = \begin{bmatrix} \cos\theta & -\sin\theta & 0 \\ \sin\theta & \cos\theta & 0 \\
                                  c - \sigma\, \partial(\phi \Delta\theta) / \partial \Delta x & 0 &
                                  k - \sigma\, \partial(\phi \Delta\theta) / \partial \Delta\theta \\
                                  0 & 0 & 0 \\ 0 & 0 & 0 \\ 0 & 0 & 0 \end{bmatrix}

    with, for ``a = |dx|`` and ``q = h |dtheta|``, :math:`\partial(\phi\Delta\theta)/\partial\Delta x =
    -q\, \Delta\theta\, \mathrm{sign}(\Delta x) / (a + q)^2` and
    :math:`\partial(\phi\Delta\theta)/\partial\Delta\theta = q (2a + q) / (a + q)^2` (the sixth row
    and column only with ``sigma`` in the state).
    """
    s = np.asarray(s, float)
    _check_half_track(s, half_track_m)
    n = s.size
    dx, dy, dth = np.asarray(u, float)
    F3, V3 = motion_jacobians(s[:3], u)
    F = np.eye(n)
    F[:3, :3] = F3
    F[2, 3], F[2, 4] = dth, dx
    V = np.zeros((n, 3))
    V[:3] = V3
    V[2] = (s[4], 0.0, s[3])
    if n == 6:
        a, q = abs(dx), half_track_m * abs(dth)
        if q > 0.0:
            F[2, 5] = -spin_fraction(u, half_track_m) * dth
            V[2, 0] += s[5] * q * dth * math.copysign(1.0, dx) / (a + q) ** 2
            V[2, 2] -= s[5] * q * (2.0 * a + q) / (a + q) ** 2
    return F, V


def _check_half_track(s, half_track_m: float) -> None:
    """The spin's slip needs the track: with ``half_track_m`` 0 every increment's spin fraction is 0 and
    the slip would silently do nothing."""
    if s.size == 6 and not half_track_m > 0:
        raise ValueError(
            f"the six-state model (the spin's slip) needs half_track_m > 0 [m], got {half_track_m!r}"
        )


def measurement_model(x, l) -> np.ndarray:
    r"""``h(x; l)``: landmark ``l = [x_l, y_l, theta_l]`` (its planar pose in W) seen from pose ``x``.

    .. math:: h(x) = [R(\theta)^T ([x_l, y_l]^T - [x, y]^T),\; \mathrm{wrap}(\theta_l - \theta)]^T
    """
    x = np.asarray(x, float)
    l = np.asarray(l, float)
    c, s = math.cos(x[2]), math.sin(x[2])
    dX, dY = l[0] - x[0], l[1] - x[1]
    return np.array([c * dX + s * dY, -s * dX + c * dY, wrap_angle(l[2] - x[2])])


def measurement_jacobian(x, l) -> np.ndarray:
    r"""``H = dh/dx`` of :func:`measurement_model`, (3, 3); with ``h = [h_1, h_2, h_3]``:

    .. math:: H = \begin{bmatrix} -\cos\theta & -\sin\theta & h_2 \\
                                  \sin\theta & -\cos\theta & -h_1 \\ 0 & 0 & -1 \end{bmatrix}
    """
    h = measurement_model(x, l)
    c, s = math.cos(float(x[2])), math.sin(float(x[2]))
    return np.array([[-c, -s, h[1]], [s, -c, -h[0]], [0.0, 0.0, -1.0]])


def pose_from_observation(z, l) -> tuple[np.ndarray, np.ndarray]:
    r"""The robot pose ``x`` that one landmark observation ``z`` implies, and ``J = dx/dz`` (3, 3).

    A landmark is unique and its planar pose ``l`` in W is known, so one observation of it (its planar
    pose in R) determines the full planar pose of the robot: :func:`measurement_model` solved for ``x``,
    ``G_WR = G_WL G_RL^-1``:

    .. math:: \theta = \mathrm{wrap}(\theta_l - z_3), \qquad
              [x, y]^T = [x_l, y_l]^T - R(\theta) [z_1, z_2]^T

    .. math:: J = \begin{bmatrix} -\cos\theta & \sin\theta & -z_1 \sin\theta - z_2 \cos\theta \\
                                  -\sin\theta & -\cos\theta & z_1 \cos\theta - z_2 \sin\theta \\
                                  0 & 0 & -1 \end{bmatrix}

    (the third column: :math:`\partial\theta/\partial z_3 = -1` through :math:`-R'(\theta) [z_1, z_2]^T`).
    The pose's covariance is ``J Q J^T`` for an observation covariance ``Q``.
    """
    z = np.asarray(z, float)
    l = np.asarray(l, float)
    th = wrap_angle(l[2] - z[2])
    c, s = math.cos(th), math.sin(th)
    x = np.array([l[0] - (c * z[0] - s * z[1]), l[1] - (s * z[0] + c * z[1]), th])
    J = np.array(
        [
            [-c, s, -s * z[0] - c * z[1]],
            [-s, -c, c * z[0] - s * z[1]],
            [0.0, 0.0, -1.0],
        ]
    )
    return x, J


def observation_of(
    G_RC: np.ndarray, G_CL: np.ndarray, Sigma_rv_CL: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    r"""The measurement ``z`` (the landmark's planar pose in R) of a fitted ``G_CL``, and its covariance.

    ``G_RL = G_RC G_CL``; ``z = [t_RL,x, t_RL,y, atan2(R_RL[1,0], R_RL[0,0])]``. The fit's covariance
    ``Sigma_rv_CL`` (6, 6) is over ``[t_CL, phi]`` with ``R_CL <- Exp(phi) R_CL`` (rotation vector in C,
    :func:`lab.estimation.fit.ransac_pose`); it is carried to z by the Jacobian ``J`` (3, 6):

    .. math:: \partial t_{RL} / \partial t_{CL} = R_{RC}, \qquad
              \partial \psi / \partial \phi = \frac{r_{00}\, a_1 - r_{10}\, a_0}{r_{00}^2 + r_{10}^2} R_{RC},
              \quad a = -[r_0]_\times

    where ``r_0`` is R_RL's first column (a small rotation ``omega`` in R moves it by ``omega x r_0``).
    """
    G_RL = G_RC @ G_CL
    R_RL = G_RL[:3, :3]
    R_RC = G_RC[:3, :3]
    r0 = R_RL[:, 0]
    z = np.array([G_RL[0, 3], G_RL[1, 3], math.atan2(r0[1], r0[0])])
    a = -np.array([[0.0, -r0[2], r0[1]], [r0[2], 0.0, -r0[0]], [-r0[1], r0[0], 0.0]])
    J = np.zeros((3, 6))
    J[:2, :3] = R_RC[:2, :]
    J[2, 3:] = ((r0[0] * a[1] - r0[1] * a[0]) / (r0[0] ** 2 + r0[1] ** 2)) @ R_RC
    return z, J @ Sigma_rv_CL @ J.T
