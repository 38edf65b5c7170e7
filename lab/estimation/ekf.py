r"""The 6-DOF pose EKF of the identification paper (Sec. III-A) and the search paper (Sec. III-C).

One filter tracks one database model's pose ``X = [x, y, z, alpha, beta, gamma]`` of the object in
the left camera frame C. A step is::

    ekf.predict(G_RC_prev, G_RC, G_odom, dt)   # Eqs. (1)-(2): robot, pan-tilt and object motion
    result = ekf.update(d_C, b_O, Sigma_d)     # Eq. (3): matched 3D features, gated, Joseph form
    result.log_likelihood                      # Eq. (9): the data likelihood for the model's probability

**The update never forms the 3n x 3n innovation covariance.** ``Sigma_m`` is block-diagonal, so
with whitened residuals and Jacobian (``L_j L_j^T = Sigma_j``, ``y~_j = L_j^-1 y_j``,
``C~_j = L_j^-1 C_j``) everything reduces to 6x6 algebra. With ``Lambda = C^T Sigma_m^-1 C``,
``g = C^T Sigma_m^-1 y`` and ``Sigma_bar = L L^T``:

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
check that over a 25-step run.

**Calibration error is shared by every feature of a frame.** A camera's calibration is never exact.
A stereo pair triangulates ``Z = f_x B / d``, ``X = (u - c_x) Z / f_x``, ``Y = (v - c_y) Z / f_y``
(:mod:`lab.vision.stereo`) with its calibrated ``f_x``, ``f_y``, ``B``; when the true ones are
``f_x (1 + a_x)``, ``f_y (1 + a_y)`` and ``B / (1 + s)``, every triangulated point is off in the same way:

.. math::

    X_m = (1 + s) X, \qquad Y_m = (1 + s) \frac{1 + a_y}{1 + a_x} Y, \qquad Z_m = (1 + s) \frac{Z}{1 + a_x}

a common scale ``s`` (the baseline's) and a stretch of the rows and of the depth against the columns
(the focal lengths'), which tilts a face seen at an angle. A rotation ``delta`` between the measured
points and C (a rectification's rotation residual) turns them all by ``Exp(delta)``. Treated as
independent per-feature noise such errors average away over the features, and the filter grows
over-confident by as much (measured: NEES above its band on 28 % of the static-box frames under
``realistic``, tuning seeds 0-5; 9 % with a common scale). With :class:`CalibrationUncertainty` the
model is ``d_j = g(h_j(X), c) + n_j``, linearised as ``d_j = h_j + U_j c + n_j`` with
``c = [s, delta, a_x, a_y]`` and ``U_j = [h_j, -[h_j]_x, (0, -Y_j, -Z_j), (0, Y_j, 0)]``
(:func:`calibration_jacobian`): ``c`` joins the state for the update with its prior ``Sigma_c``. The
same 6x6 algebra runs in ``6 + m`` dimensions (``C_j <- [C_j, U_j]`` over the ``m`` parts of ``c`` with
a non-zero std), which is the update with
``S = C Sigma_bar C^T + U Sigma_c U^T + C P_xc U^T + U P_xc^T C^T + Sigma_m``: the features' errors
correlated through ``c``. With ``Sigma_c = 0`` it is the paper's update, step for step.

The pan-tilt's zero offset is *not* such an error: it turns the camera on the robot, not the measured
points in the camera, and the filter's state is the object in C (:meth:`CalibrationUncertainty.of_camera`
leaves it out). Modelled as a shared ``delta`` it made the filter over-cautious: NEES below its band on
7.3 % of the static-box frames (tuning seeds 0-7), a median of 4.5 against chi-square(6)'s 5.35.

**The calibration error is also shared by every frame.** It is the same error in the next frame, so
the update is a *consider* (Schmidt-Kalman) update: the filter keeps the cross-covariance ``P_xc``
(6, m) between its state and ``c``, propagates it with the state (``P_xc <- F P_xc``; ``c`` does not
change), updates it with the state (the ``(6 + m)``-dimensional update's ``x``-``c`` block), and never
updates ``c`` itself (its estimate stays 0, its covariance ``Sigma_c``). The part of ``c`` the
features cannot tell from the pose then sets a floor under the covariance, however many frames of a
still scene the filter sees.

**So is the database's own error** (:class:`ModelUncertainty`): its points were triangulated in
training with stereo errors of their own, the same in every frame. Their rigid part is a pose offset
``m`` that no measurement can tell from the object's pose, so the filter tracks the pose the features
say (:attr:`PoseEKF.estimate`, which predicts them: its gate, likelihood and NIS are the papers'), and
reports the object's as that pose with ``Sigma_m`` added (:attr:`PoseEKF.object_estimate`).

Measured (``benchmarks/bench_nees.py``, ``realistic``, static-box frames, NEES in its chi-square(6) 95 %
band), tuning seeds 0-7: 88.0 % with a common scale and the pan-tilt's zero as the calibration error,
91.5 % with the stereo pair's own (scale and focal lengths, no pointing); with the latter the database's
2 mm (chosen on these seeds with the former: 86.1 % without it) is still at the top (87.0 / 89.8 /
90.5 / 91.5 / 91.7 / 89.8 % at 0 / 1 / 1.5 / 2 / 2.5 / 3 mm). Report seeds 100000-100007: 88.9 % before,
92.8 % now (3.2 % above the band, 4.0 % below; median NEES 4.4 against chi-square(6)'s 5.35).

With ``EKFConfig(chart=ROTATION_VECTOR)`` the same equations run with ``C`` and ``Sigma`` over
``[x_r, phi]`` (``phi`` a small rotation in C) and the correction is applied as
``R <- Exp(phi) R``: the state is still the Euler ``X``, but the filter no longer breaks down at
gimbal lock (see :class:`OrientationChart`).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from enum import Enum

import numpy as np

from lab.estimation.estimate import PoseEstimate
from lab.estimation.fit import (
    RansacConfig,
    _check_matches,
    _valid_rows,
    chi2_quantile,
    point_spread,
    ransac_pose,
)
from lab.estimation.gate import GateConfig, _gate
from lab.estimation.models import (
    OrientationChart,
    ProcessNoise,
    _camera_motion,
    _predict,
    canonical_state,
    euler_to_rv_jacobian,
    measurement_jacobian,
    measurement_jacobian_rv,
    measurement_model,
    process_noise_covariance,
    retract_rv,
    rv_to_euler_jacobian,
)

__all__ = [
    "CalibrationUncertainty",
    "DivergenceConfig",
    "ModelUncertainty",
    "EKFConfig",
    "UpdateOutcome",
    "UpdateResult",
    "PoseEKF",
    "calibration_jacobian",
    "data_log_likelihood",
    "model_offset_covariance",
]

_LOG_2PI = math.log(2.0 * math.pi)


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


@dataclass(frozen=True)
class CalibrationUncertainty:
    """How well the camera's calibration is known: the errors every feature of a frame shares.

    Attributes
    ----------
    scale_std : float
        Standard deviation of a common relative scale ``s`` of the triangulated points: the baseline's
        relative error (``Z = f B / d``; 0.005 when it is known to 0.5 %, what a checkerboard calibration
        of a small stereo pair achieves), or all of the depth's when the focal lengths' share is not
        told apart (``focal_std = 0``).
    pointing_std_deg : float [deg]
        Standard deviation of each axis of a small rotation ``delta`` between the measured points and
        the camera frame C (a rectification's rotation residual). Not the pan-tilt's zero: that turns
        C on the robot, not the points in C (see the module docstring).
    focal_std : float
        Standard deviation of the relative error ``a_x``, ``a_y`` of each focal length (independent of
        each other; 0.005 for a checkerboard calibration): it stretches depth and rows against the
        columns (the module docstring's equation).

    The default is :meth:`none`, the papers' filter; the agents take the robot's camera's stated
    accuracy (:meth:`of_camera`, :attr:`lab.robot.StereoCamera.depth_scale_std`).
    """

    scale_std: float = 0.0
    pointing_std_deg: float = 0.0
    focal_std: float = 0.0

    def __post_init__(self):
        for name in ("scale_std", "pointing_std_deg", "focal_std"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v >= 0):
                raise ValueError(f"CalibrationUncertainty.{name} must be a finite number >= 0, got {v!r}")

    @classmethod
    def none(cls) -> CalibrationUncertainty:
        return cls(0.0, 0.0, 0.0)

    @classmethod
    def of_camera(cls, camera) -> CalibrationUncertainty:
        """The stated accuracy of a :class:`lab.robot.StereoCamera`'s calibration (zero: exact): its
        focal lengths' (``focal_std``) and the rest of its depth scale's, the baseline's,
        ``sqrt(depth_scale_std**2 - focal_std**2)``. Its ``pointing_std_deg`` (the pan-tilt's zero) is
        left out: it places C on the robot and does not move the points measured in C."""
        focal = float(camera.focal_std)
        return cls(math.sqrt(max(0.0, float(camera.depth_scale_std) ** 2 - focal**2)), 0.0, focal)

    @property
    def is_none(self) -> bool:
        return self.scale_std == 0 and self.pointing_std_deg == 0 and self.focal_std == 0

    def covariance(self) -> np.ndarray:
        """``Sigma_c`` (6, 6) of ``c = [s, delta_x, delta_y, delta_z, a_x, a_y]``."""
        delta = math.radians(self.pointing_std_deg) ** 2
        return np.diag([self.scale_std**2, delta, delta, delta, self.focal_std**2, self.focal_std**2])


def calibration_jacobian(h_C) -> np.ndarray:
    """``U_j = d d_j / d c`` (n, 3, 6) at ``c = 0``: the predicted points' change with the calibration
    error ``c = [s, delta, a_x, a_y]`` (the module docstring's equation, to first order:
    ``d ~ h + s h + delta x h + a_x (0, -Y, -Z) + a_y (0, Y, 0)``)."""
    h = np.asarray(h_C, float)
    U = np.zeros((h.shape[0], 3, 6))
    U[:, :, 0] = h  # s: the common scale
    x, y, z = h[:, 0], h[:, 1], h[:, 2]
    U[:, 0, 2], U[:, 0, 3] = z, -y  # delta: -[h]_x
    U[:, 1, 1], U[:, 1, 3] = -z, x
    U[:, 2, 1], U[:, 2, 2] = y, -x
    U[:, 1, 4], U[:, 2, 4] = -y, -z  # a_x: Y (1 + a_y) / (1 + a_x), Z / (1 + a_x)
    U[:, 1, 5] = y  # a_y
    return U


@dataclass(frozen=True)
class ModelUncertainty:
    """How well a feature database knows its object: each database point ``b_j`` is off the object's
    surface by a small error of its own (the training's stereo error), the same in every frame.

    Attributes
    ----------
    point_std_m : float [m]
        Standard deviation of each axis of a database point's error.

    Within one frame these errors are like measurement noise; across frames they are not: the same
    features carry the same errors, so no number of frames averages them away. Their rigid part is a
    pose the features cannot tell from the object's: the filter tracks the pose the features say
    (``PoseEKF.estimate``, which predicts them), and the object is that pose off by ``m``,
    ``Sigma_m = sigma_b^2 (sum_j W_j^T W_j)^-1`` with ``W_j = [I, -[b_j]_x]`` over the frame's matched
    points (:func:`model_offset_covariance`): ``PoseEKF.object_estimate``. The default is
    :meth:`none` (the papers' filter, which assumes an exact database).
    """

    point_std_m: float = 0.0

    def __post_init__(self):
        v = self.point_std_m
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v >= 0):
            raise ValueError(f"ModelUncertainty.point_std_m must be a finite number >= 0, got {v!r}")

    @classmethod
    def none(cls) -> ModelUncertainty:
        return cls(0.0)

    @property
    def is_none(self) -> bool:
        return self.point_std_m == 0


def model_offset_covariance(b_O, point_std_m: float) -> np.ndarray:
    """``Sigma_m`` (6, 6) over ``m = [tau, rho]`` (in O): the rigid part of independent errors of std
    ``point_std_m`` on the database points ``b_O`` (n, 3), ``sigma_b^2 (sum_j W_j^T W_j)^-1`` with
    ``W_j = [I, -[b_j]_x]`` (``Exp(rho) b_j + tau ~ b_j + W_j m``). Zeros for a zero std."""
    b = np.asarray(b_O, float)
    if point_std_m == 0:
        return np.zeros((6, 6))
    x, y, z = b[:, 0], b[:, 1], b[:, 2]
    W = np.zeros((b.shape[0], 3, 6))
    W[:, :, :3] = np.eye(3)
    W[:, 0, 4], W[:, 0, 5] = z, -y  # -[b_j]_x
    W[:, 1, 3], W[:, 1, 5] = -z, x
    W[:, 2, 3], W[:, 2, 4] = y, -x
    return point_std_m**2 * np.linalg.inv(np.einsum("nki,nkj->ij", W, W))


@dataclass(frozen=True)
class EKFConfig:
    """Everything a :class:`PoseEKF` can be tuned with.

    Attributes
    ----------
    process : ProcessNoise
        Object motion noise, odometry error, Eq. (4)'s floor.
    gate : GateConfig
        Geometric feasibility check before an update.
    ransac : RansacConfig
        (Re-)initialisation from matches.
    divergence : DivergenceConfig
        Divergence criteria.
    auto_initialize : bool
        ``update`` initialises (and re-initialises after divergence) from its matches by RANSAC.
    calibration : CalibrationUncertainty
        The calibration error all features of a frame share (see the module docstring);
        ``CalibrationUncertainty.none()`` is the papers' update.
    model : ModelUncertainty
        The database's offset from its object, shared by all features of all frames;
        ``ModelUncertainty.none()`` is the papers' update.
    chart : OrientationChart
        Coordinates of the covariance's orientation part. ``EULER`` (default) is the papers' EKF and
        matches filterpy step for step; ``ROTATION_VECTOR`` keeps the same state ``X`` but tracks the
        uncertainty as a small rotation in C, which stays well defined at Euler gimbal lock (a box's
        x face looking straight at a level camera). See :mod:`lab.estimation.models`.
    """

    process: ProcessNoise = field(default_factory=ProcessNoise)
    gate: GateConfig = field(default_factory=GateConfig)
    ransac: RansacConfig = field(default_factory=RansacConfig)
    divergence: DivergenceConfig = field(default_factory=DivergenceConfig)
    auto_initialize: bool = True
    chart: OrientationChart = OrientationChart.EULER
    calibration: CalibrationUncertainty = field(default_factory=CalibrationUncertainty)
    model: ModelUncertainty = field(default_factory=ModelUncertainty)


class UpdateOutcome(Enum):
    """What :meth:`PoseEKF.update` did with a frame's matches."""

    UPDATED = "updated"  # an EKF measurement update was applied
    INITIALIZED = "initialized"  # the filter was (first) initialised by RANSAC
    REINITIALIZED = "reinitialized"  # re-initialised by RANSAC after divergence
    SKIPPED = "skipped"  # nothing changed; see the reason


@dataclass(frozen=True)
class UpdateResult:
    """The record of one :meth:`PoseEKF.update` call.

    Attributes
    ----------
    applied : bool
        True when an EKF measurement update changed the state (``outcome is UPDATED``).
    outcome : UpdateOutcome
    reason : str
        Why, in words (skips, initialisations and divergence name their cause).
    n_matches : int
        Rows passed in.
    n_used : int
        Rows used (finite, gated in; the RANSAC inliers for an initialisation).
    inliers : ndarray, shape (n_matches,), bool
        Which rows were used.
    nis : float or None
        Normalised innovation squared ``y^T S^-1 y`` (chi-square with ``dof`` degrees of freedom
        when the filter is consistent).
    dof : int
        ``3 * n_used`` when applied, else 0.
    log_likelihood : float or None
        ``log N(D | H(mu_bar), C Sigma_bar C^T + Sigma_m)``: Eq. (9)'s data likelihood of the used
        matches (None when no update was applied).
    estimate : PoseEstimate or None
        The state after the call.
    """

    applied: bool
    outcome: UpdateOutcome
    reason: str
    n_matches: int = 0
    n_used: int = 0
    inliers: np.ndarray = field(default_factory=lambda: np.zeros(0, bool), repr=False)
    nis: float | None = None
    dof: int = 0
    log_likelihood: float | None = None
    estimate: PoseEstimate | None = field(default=None, repr=False)


def _whitened(r, C, S):
    """Whiten residuals (n,3) and Jacobian blocks (n,3,k) by L_j^-1 (L_j L_j^T = Sigma_j)."""
    L = np.linalg.cholesky(S)  # (n, 3, 3)
    sol = np.linalg.solve(L, np.concatenate([r[..., None], C], axis=2))  # (n, 3, 1 + k)
    logdet_m = 2.0 * float(np.sum(np.log(np.diagonal(L, axis1=1, axis2=2))))
    return sol[..., 0].reshape(-1), sol[..., 1:].reshape(-1, C.shape[2]), logdet_m


@functools.lru_cache(maxsize=64)
def _calibration_columns(calibration: CalibrationUncertainty) -> tuple[int, ...]:
    """The parts of ``c = [s, delta]`` with a non-zero std (only those join the update, so that its
    prior stays SPD); worked out once per (immutable) calibration."""
    return tuple(j for j, sd in enumerate(np.diag(calibration.covariance())) if sd > 0)


def _with_calibration(Sigma_bar, P_xc, r, C, d, calibration: CalibrationUncertainty):
    """The update's prior and Jacobian with the calibration error ``c`` in the state (module
    docstring): ``[[Sigma_bar, P_xc], [P_xc^T, Sigma_c]]`` and ``[C_j, U_j]``, ``U_j`` at the
    predicted points ``h_j = d_j - r_j``, over the columns of :func:`_calibration_columns`."""
    cols = _calibration_columns(calibration)
    if not cols:
        return Sigma_bar, C
    k = Sigma_bar.shape[0]
    prior = np.zeros((k + len(cols), k + len(cols)))
    prior[:k, :k] = Sigma_bar
    prior[:k, k:] = P_xc
    prior[k:, :k] = P_xc.T
    prior[k:, k:] = calibration.covariance()[np.ix_(cols, cols)]
    return prior, np.concatenate([C, calibration_jacobian(d - r)[..., cols]], axis=2)


def _information_update(Sigma_bar, y_w, C_w, logdet_m):
    """The Kalman update with whitened quantities (see the module docstring). Raises LinAlgError.

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
    loglik = -0.5 * (nis + logdet_S + y_w.size * _LOG_2PI)  # log N(y; 0, S), Eq. (9)
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
    d, b, S = _check_matches(d_C, b_O, Sigma_d)
    mu_bar = np.asarray(mu_bar, float)
    n = d.shape[0]
    r = d - measurement_model(mu_bar, b)
    jac = measurement_jacobian if chart is OrientationChart.EULER else measurement_jacobian_rv
    C = jac(mu_bar, b).reshape(n, 3, 6)
    y_w, C_w, logdet_m = _whitened(r, C, S)
    return _information_update(np.asarray(Sigma_bar, float), y_w, C_w, logdet_m)[3]


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
class _PendingUpdate:
    """An update between its checks and its linear algebra (:meth:`PoseEKF._begin_update`): the used
    rows' residuals ``r`` (m, 3), Jacobians ``C`` (m, 3, k), covariances ``S`` (m, 3, 3) and database
    points ``b`` (m, 3), and the prior (k, k), with the calibration error when it is modelled."""

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
class _Motion:
    """One step's checked motion inputs (:func:`_checked_motion`), shared by every filter of a bank."""

    mats: dict
    bad: list
    dt: float
    A: np.ndarray | None  # G_{C(k) C(k-1)}, Eq. (1) without the object (None when ``bad``)


def _checked_motion(G_RC_prev, G_RC, G_odom, dt, G_OO=None) -> _Motion:
    """:meth:`PoseEKF.predict`'s inputs, checked (ValueError for wrong shapes, a non-rigid transform or
    a bad ``dt``); transforms that are non-finite or absurd (> 1 km) are listed in ``bad``."""
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
    A = None if bad else _camera_motion(mats["G_RC_prev"], mats["G_RC"], mats["G_odom"])
    return _Motion(mats, bad, dt, A)


def _health_many(dc: DivergenceConfig, euler: bool, mu: np.ndarray, P: np.ndarray) -> list[str | None]:
    """Why each of k states ``mu`` (k, 6) with covariance ``P`` (k, 6, 6) is not a usable estimate, or
    None: the first of non-finite, not symmetric, not positive definite, a covariance blow-up (the
    largest position or angle standard deviation over ``dc``'s bound), gimbal lock (Euler chart). The
    checks run on all k at once (one Cholesky call: a bank checks its filters together)."""
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


class PoseEKF:
    """EKF on the object's 6-DOF pose in the camera frame for one database model.

    Parameters
    ----------
    config : EKFConfig, optional
    rng : numpy.random.Generator
        Seeded generator for the RANSAC (re-)initialisations.

    Attributes
    ----------
    mu : ndarray, shape (6,) or None
        Current state ``X`` [m, rad]; None before initialisation.
    P : ndarray, shape (6, 6) or None
        The covariance the filter propagates, in its chart (``config.chart``): over ``X`` (EULER) or
        over ``[x_r, phi]`` (ROTATION_VECTOR). :attr:`Sigma` and :attr:`Sigma_rv` give both views.
    t : float [s]
        Filter time (advanced by ``predict``'s ``dt``).
    divergence : str or None
        Why the filter is considered diverged; it is re-initialised from the next update's matches
        (when ``config.auto_initialize``) or by :meth:`initialize`.
    n_reinit : int
        How many times it was re-initialised.
    last_result : UpdateResult or None

    Notes
    -----
    Never raises for bad data (NaN measurements, too few or degenerate matches, a failed
    factorisation): the update is skipped, the state stays finite and the reason is recorded.
    Wrong shapes or types raise ``ValueError``.
    """

    def __init__(self, config: EKFConfig | None = None, *, rng: np.random.Generator):
        if not isinstance(rng, np.random.Generator):
            raise ValueError(f"rng must be a numpy.random.Generator (seeded), got {type(rng).__name__}")
        self.config = config or EKFConfig()
        self.rng = rng
        self.mu: np.ndarray | None = None
        self.P: np.ndarray | None = None
        self.P_xc = self._no_cross_covariance()
        self.Sigma_m = np.zeros((6, 6))  # the database offset's, over the last update's points
        self.t = 0.0
        self.divergence: str | None = None
        self.n_reinit = 0
        self.last_result: UpdateResult | None = None
        self._huge_nis_run = 0
        self._gated_out_run = 0

    # ------------------------------------------------------------------ state
    def _no_cross_covariance(self) -> np.ndarray:
        """``P_xc`` of a state that knows nothing of the calibration error: zeros (6, m)."""
        return np.zeros((6, len(_calibration_columns(self.config.calibration))))

    @property
    def _euler(self) -> bool:
        return self.config.chart is OrientationChart.EULER

    @property
    def initialized(self) -> bool:
        return self.mu is not None

    @property
    def Sigma(self) -> np.ndarray | None:
        """Covariance (6, 6) over the Euler state ``X`` (derived from :attr:`P` in the rotation-vector
        chart, where it blows up near gimbal lock)."""
        if self.P is None or self._euler:
            return self.P
        T_inv = rv_to_euler_jacobian(self.mu)
        Sigma = T_inv @ self.P @ T_inv.T
        return 0.5 * (Sigma + Sigma.T)

    @property
    def Sigma_rv(self) -> np.ndarray | None:
        """Covariance (6, 6) over ``[x_r, phi]``, ``phi`` a small rotation vector in C."""
        if self.P is None or not self._euler:
            return self.P
        T = euler_to_rv_jacobian(self.mu)
        Sigma_rv = T @ self.P @ T.T
        return 0.5 * (Sigma_rv + Sigma_rv.T)

    @property
    def estimate(self) -> PoseEstimate | None:
        """The current estimate (a read-only snapshot), or None before initialisation."""
        if self.mu is None:
            return None
        return PoseEstimate(self.mu, self.Sigma, self.t, self.Sigma_rv)

    @property
    def object_estimate(self) -> PoseEstimate | None:
        """Where the object is: :attr:`estimate` (the pose its features say) with the database's own
        error added, ``Sigma_rv + blockdiag(R_CO, R_CO) Sigma_m blockdiag(R_CO, R_CO)^T`` (see
        :class:`ModelUncertainty`). The same as :attr:`estimate` for an exact database."""
        est = self.estimate
        if est is None or not self.Sigma_m.any():
            return est
        J = np.zeros((6, 6))
        J[:3, :3] = J[3:, 3:] = est.G_CO[:3, :3]  # tau moves the origin by R_CO tau, rho turns it in C
        Sigma_rv = est.Sigma_rv + J @ self.Sigma_m @ J.T
        Sigma_rv = 0.5 * (Sigma_rv + Sigma_rv.T)
        T_inv = rv_to_euler_jacobian(self.mu)
        return PoseEstimate(self.mu, T_inv @ Sigma_rv @ T_inv.T, self.t, Sigma_rv)

    @property
    def log_likelihood(self) -> float | None:
        """Eq. (9)'s log data likelihood of the last update (None if it applied no update)."""
        return None if self.last_result is None else self.last_result.log_likelihood

    def initialize(self, mu, Sigma, t: float | None = None, *, Sigma_rv=None) -> None:
        """Set the state explicitly (a prior, or a pose from elsewhere); clears any divergence.

        ``Sigma`` is over the Euler state; alternatively pass ``Sigma=None`` and ``Sigma_rv`` over
        ``[x_r, phi]`` (what a rotation-vector filter propagates; converted for an Euler one).
        """
        mu = np.asarray(mu, dtype=float)
        given = Sigma if Sigma is not None else Sigma_rv
        if given is None or (Sigma is not None and Sigma_rv is not None):
            raise ValueError("initialize needs exactly one of Sigma and Sigma_rv")
        given = np.asarray(given, dtype=float)
        if mu.shape != (6,) or given.shape != (6, 6):
            raise ValueError(
                f"initialize needs mu (6,) and a (6, 6) covariance, got {mu.shape} and {given.shape}"
            )
        if not (np.all(np.isfinite(mu)) and np.all(np.isfinite(given))):
            raise ValueError("initialize needs a finite mu and covariance")
        try:
            np.linalg.cholesky(given)
        except np.linalg.LinAlgError:
            raise ValueError("initialize needs a symmetric positive definite covariance") from None
        given = 0.5 * (given + given.T)
        in_rv = Sigma is None
        if in_rv == self._euler:  # convert to the filter's chart
            T = rv_to_euler_jacobian(mu) if in_rv else euler_to_rv_jacobian(mu)
            given = T @ given @ T.T
        if self._euler:
            self.mu, self.P = canonical_state(mu, given)
        else:
            self.mu, self.P = retract_rv(mu, np.zeros(6)), given  # canonical Euler angles, same rotation
        self.P_xc = self._no_cross_covariance()
        self.Sigma_m = np.zeros((6, 6))
        if t is not None:
            self.t = float(t)
        self.divergence = None
        self._huge_nis_run = 0
        self._gated_out_run = 0

    def reset(self) -> None:
        """Forget the state (the next update initialises again)."""
        self.mu = self.P = None
        self.P_xc = self._no_cross_covariance()
        self.Sigma_m = np.zeros((6, 6))
        self.divergence = None
        self._huge_nis_run = 0
        self._gated_out_run = 0

    def _health(self, mu, P) -> str | None:
        """Why (mu, P) is not a usable estimate, or None."""
        return _health_many(self.config.divergence, self._euler, mu[None], P[None])[0]

    # ---------------------------------------------------------------- predict
    def predict(
        self, G_RC_prev, G_RC, G_odom, dt: float, *, G_OO=None, Sigma_odom=None
    ) -> PoseEstimate | None:
        r"""Prediction, Eqs. (1)-(2): ``mu_bar = F(mu, u)``, ``Sigma_bar = F Sigma F^T + Q``.

        Parameters
        ----------
        G_RC_prev, G_RC : ndarray, shape (4, 4)
            Camera in robot at the previous and the current step (``StereoCamera.G_RC(pan, tilt)``).
        G_odom : ndarray, shape (4, 4)
            Odometry increment ``G_{R(k-1) R(k)}`` (``lab.geometry.relative_pose2d(prev, now)``).
        dt : float [s]
            Time since the previous step (>= 0).
        G_OO : ndarray, shape (4, 4), optional
            The object's own expected motion ``G_{O(k-1) O(k)}``; identity if omitted.
        Sigma_odom : ndarray, shape (6, 6), optional
            Odometry error covariance (twist in R(k)); from ``config.process`` if omitted.

        Returns
        -------
        PoseEstimate or None
            ``(mu_bar, Sigma_bar)``, or None while the filter is not initialised.
        """
        return self._predict_motion(_checked_motion(G_RC_prev, G_RC, G_odom, dt, G_OO), Sigma_odom)

    def _predict_motion(self, motion: _Motion, Sigma_odom=None) -> PoseEstimate | None:
        """:meth:`predict` with its inputs checked (:func:`_checked_motion`; a bank checks them once)."""
        staged = self._predict_staged(motion, Sigma_odom)
        if staged is not None:
            self._predict_commit(*staged, self._health(staged[0], staged[2]))
        return self.estimate

    def _predict_staged(self, motion: _Motion, Sigma_odom=None):
        """The prediction before its health check: ``(mu_bar, F, P_bar)``, or None when there is none
        to make (not initialised, or the motion is unknown: then the filter is marked diverged)."""
        self.t += motion.dt
        if self.mu is None:
            return None
        if motion.bad:  # the robot's motion is unknown: we no longer know where the object is
            self.divergence = f"prediction impossible: non-finite or absurd (> 1 km) {', '.join(motion.bad)}"
            return None
        chart = self.config.chart
        mats = motion.mats
        G_RC, G_odom = mats["G_RC"], mats["G_odom"]
        mu_bar, F = _predict(
            self.mu, motion.A, mats.get("G_OO"), jacobian=True, chart=chart
        )  # mu_bar = F(mu, u)
        Q = process_noise_covariance(mu_bar, G_RC, G_odom, motion.dt, self.config.process, Sigma_odom, chart)
        P_bar = F @ self.P @ F.T + Q  # Sigma_bar = F Sigma F^T + Q
        P_bar = 0.5 * (P_bar + P_bar.T)
        return mu_bar, F, P_bar

    def _predict_commit(self, mu_bar, F, P_bar, problem: str | None) -> None:
        """Keep a staged prediction unless its health ``problem`` makes it unusable."""
        if problem is None or problem.startswith(("covariance blow-up", "gimbal")):
            self.mu, self.P = mu_bar, P_bar  # finite and SPD: keep it, even if it is lost
            self.P_xc = F @ self.P_xc  # the calibration error c stays what it was
        if problem is not None and self.divergence is None:
            self.divergence = problem

    # ----------------------------------------------------------------- update
    def _skip(self, reason, n, inliers=None) -> UpdateResult:
        res = UpdateResult(
            False,
            UpdateOutcome.SKIPPED,
            reason,
            n,
            0,
            np.zeros(n, bool) if inliers is None else inliers,
            estimate=self.estimate,
        )
        self.last_result = res
        return res

    def _try_initialize(self, d, b, S, n) -> UpdateResult:
        was = self.divergence
        init = ransac_pose(d, b, S, self.rng, self.config.ransac)
        if not init.success:
            why = f"not initialised: {init.reason}"
            if was is not None:
                why = f"diverged ({was}); re-initialisation failed: {init.reason}"
            return self._skip(why, n)
        self.initialize(init.mu, None, Sigma_rv=init.Sigma_rv)
        self.Sigma_m = model_offset_covariance(b[init.inliers], self.config.model.point_std_m)
        problem = self._health(self.mu, self.P)
        if problem is not None:  # e.g. an Euler filter initialised at gimbal lock
            self.divergence = problem
        if was is None:
            outcome, why = UpdateOutcome.INITIALIZED, init.reason
        else:
            self.n_reinit += 1
            outcome, why = (
                UpdateOutcome.REINITIALIZED,
                f"re-initialised after divergence ({was}): {init.reason}",
            )
        res = UpdateResult(
            False, outcome, why, n, init.n_inliers, init.inliers.copy(), estimate=self.estimate
        )
        self.last_result = res
        return res

    def update(self, d_C, b_O, Sigma_d) -> UpdateResult:
        r"""Measurement update with one frame's matched features, Eq. (3), after the feasibility check.

        Parameters
        ----------
        d_C : array_like, shape (n, 3) [m]
            Measured 3D features in the camera frame C (the ``d_j`` of Eq. (3)).
        b_O : array_like, shape (n, 3) [m]
            Their matched database features ``b_{J(j)}`` in the object frame O.
        Sigma_d : array_like, shape (n, 3, 3) [m^2]
            Covariance of each measured feature (the diagonal blocks of ``Sigma_m``).

        Returns
        -------
        UpdateResult
            Rows with non-finite values or a covariance that is not positive definite are dropped
            (``inliers`` False); fewer than ``gate.min_matches`` usable rows, degenerate geometry or a
            failed factorisation skip the update with the reason. While the filter is not initialised
            or has diverged, the matches initialise it by RANSAC instead (``auto_initialize``).
        """
        pending = self._begin_update(d_C, b_O, Sigma_d)
        if isinstance(pending, UpdateResult):
            return pending
        try:
            y_w, C_w, logdet_m = _whitened(pending.r, pending.C, pending.S)  # innovation y = D - H(mu_bar)
            out = _information_update(pending.prior, y_w, C_w, logdet_m)
        except np.linalg.LinAlgError:
            return self._update_failed(pending)
        return self._end_update(pending, *out)

    def _begin_update(self, d_C, b_O, Sigma_d, valid=None, gated=None) -> UpdateResult | _PendingUpdate:
        """:meth:`update` up to its linear algebra: the checks, the gate, and the prior and Jacobian
        with the calibration error; or the result, when the update is skipped or initialises.
        ``valid``: the rows' ``_valid_rows``, when already known (a bank whose filters share them);
        ``gated``: ``_gate``'s output on the valid rows, when already known (a bank gates its filters
        together)."""
        d, b, S = _check_matches(d_C, b_O, Sigma_d)
        n = d.shape[0]
        valid = _valid_rows(d, b, S) if valid is None else valid
        n_valid = int(np.count_nonzero(valid))
        dropped = n - n_valid
        note = f" ({dropped} non-finite or invalid rows dropped)" if dropped else ""

        if self.mu is None or self.divergence is not None:
            if not self.config.auto_initialize:
                why = "not initialised" if self.mu is None else f"diverged: {self.divergence}"
                return self._skip(why, n)
            return self._try_initialize(d, b, S, n)

        gc = self.config.gate
        if n_valid < gc.min_matches:
            return self._skip(f"too few matches: {n_valid} usable < {gc.min_matches}{note}", n)
        idx = np.flatnonzero(valid)
        d, b, S = d[idx], b[idx], S[idx]

        keep, r, C, inliers, why_not = self._feasible_matches(d, b, S, idx, n, n_valid, note, gated)
        if why_not is not None:
            return self._skip(why_not, n, inliers)
        cal = self.config.calibration
        prior, C_c = _with_calibration(self.P, self.P_xc, r[keep], C[keep], d[keep], cal)
        return _PendingUpdate(n, n_valid, note, keep, inliers, prior, r[keep], C_c, S[keep], b[keep])

    def _update_failed(self, pending: _PendingUpdate) -> UpdateResult:
        self.divergence = "covariance is not positive definite"
        return self._skip("update failed: a covariance factorisation failed", pending.n, pending.inliers)

    def _end_update(self, pending: _PendingUpdate, dx, P, nis: float, loglik: float) -> UpdateResult:
        """:meth:`update` after its linear algebra (``_information_update``'s outputs)."""
        mu, P, P_xc = self._corrected_state(dx, P)
        return self._end_update_checked(pending, mu, P, P_xc, nis, loglik, self._health(mu, P))

    def _corrected_state(self, dx, P):
        """``(mu, P, P_xc)`` after the update: the correction in the filter's chart, the state's
        covariance (6, 6) and its cross-covariance with the calibration error."""
        dx = dx[:6]  # consider update: the estimate of c stays 0 (module docstring)
        mu, P = self._corrected(self.mu, dx, P)  # P still (6 + m, 6 + m): the chart acts on its rows
        return mu, P[:6, :6], P[:6, 6:]  # and Sigma_c stays Sigma_c

    def _end_update_checked(
        self, pending: _PendingUpdate, mu, P, P_xc, nis: float, loglik: float, problem: str | None
    ) -> UpdateResult:
        """:meth:`_end_update` with the corrected state's health ``problem`` known."""
        n, inliers = pending.n, pending.inliers
        if problem is not None and not problem.startswith(("covariance blow-up", "gimbal")):
            self.divergence = problem
            return self._skip(f"update rejected: {problem}", n, inliers)
        self.mu, self.P, self.P_xc = mu, P, P_xc
        self.Sigma_m = model_offset_covariance(pending.b, self.config.model.point_std_m)
        n_used = int(np.count_nonzero(pending.keep))
        dof = 3 * n_used
        self._watch_divergence(nis, dof, problem)
        why = f"updated with {n_used} of {pending.n_valid} matches{pending.note}"
        res = UpdateResult(
            True, UpdateOutcome.UPDATED, why, n, n_used, inliers, nis, dof, loglik, self.estimate
        )
        self.last_result = res
        return res

    def _feasible_matches(self, d, b, S, idx, n: int, n_valid: int, note: str, gated=None):
        """The geometric feasibility check before an update: which usable matches pass the gate.

        Returns ``(keep, r, C, inliers, why_not)``: the gate's verdict, residuals and Jacobians on the
        usable rows (``_gate``), the verdict on all ``n`` input rows, and the reason to skip the update
        (None to go on): too few matches passed (``gating_patience`` such frames in a row mean the
        track is lost) or their model points are collinear.
        """
        gc = self.config.gate
        keep, r, C = _gate(self.mu, self.P, d, b, S, gc, self.config.chart) if gated is None else gated
        inliers = np.zeros(n, bool)
        inliers[idx[keep]] = True
        n_used = int(np.count_nonzero(keep))
        if n_used < gc.min_matches:
            self._gated_out_run += 1
            if self._gated_out_run >= self.config.divergence.gating_patience:
                self.divergence = (
                    f"track lost: the gate rejected the matches {self._gated_out_run} frames in a row"
                )
            return keep, r, C, inliers, f"gating kept {n_used} of {n_valid} matches < {gc.min_matches}{note}"
        self._gated_out_run = 0
        if point_spread(b[keep]) < gc.min_spread_m:
            why = f"degenerate geometry: the matched model points are collinear or coincident{note}"
            return keep, r, C, inliers, why
        return keep, r, C, inliers, None

    def _corrected(self, mu_bar, dx, P):
        """``mu = mu_bar + K y`` in the filter's chart, with its covariance ``P`` (6 + m, 6 + m): the
        state's rows and columns follow the chart, the calibration error's stay."""
        if self._euler:
            return canonical_state(mu_bar + dx, P)  # alpha, gamma wrapped, beta in range
        return retract_rv(mu_bar, dx), P  # x_r + dx_r, R <- Exp(phi) R (the reset's Jacobian ~ I is ignored)

    def _watch_divergence(self, nis: float, dof: int, problem: str | None) -> None:
        """After an update: a health problem the update was still applied with, or ``nis_patience``
        updates in a row whose NIS exceeds its chi-square(``dof``) ``nis_prob`` quantile, mark the filter
        diverged (the next frame re-initialises it)."""
        dcfg = self.config.divergence
        self._huge_nis_run = self._huge_nis_run + 1 if nis > chi2_quantile(dcfg.nis_prob, dof) else 0
        if problem is not None:
            self.divergence = problem
        elif self._huge_nis_run >= dcfg.nis_patience:
            self.divergence = (
                f"NIS above its chi-square({dof}) {dcfg.nis_prob} quantile "
                f"{self._huge_nis_run} updates in a row (last {nis:.1f})"
            )
