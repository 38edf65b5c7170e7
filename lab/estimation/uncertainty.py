r"""What the pose EKF knows of its own errors: the camera's calibration and the database's points.

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
over-confident by as much. With :class:`CalibrationUncertainty` the
model is ``d_j = g(h_j(X), c) + n_j``, linearised as ``d_j = h_j + U_j c + n_j`` with
``c = [s, delta, a_x, a_y]`` and ``U_j = [h_j, -[h_j]_x, (0, -Y_j, -Z_j), (0, Y_j, 0)]``
(:func:`calibration_jacobian`): ``c`` joins the state for the update with its prior ``Sigma_c``
(:func:`with_calibration`). The update of :mod:`lab.estimation.kernel` runs in ``6 + m`` dimensions
(``C_j <- [C_j, U_j]`` over the ``m`` parts of ``c`` with a non-zero std), which is the update with
``S = C Sigma_bar C^T + U Sigma_c U^T + C P_xc U^T + U P_xc^T C^T + Sigma_m``: the features' errors
correlated through ``c``. With ``Sigma_c = 0`` it is the paper's update, step for step.

The pan-tilt's zero offset is *not* such an error: it turns the camera on the robot, not the measured
points in the camera, and the filter's state is the object in C (:meth:`CalibrationUncertainty.of_camera`
leaves it out). Modelled as a shared ``delta`` it made the filter over-cautious.
How the calibration error's model was chosen: docs/tuning/ekf-calibration-error.md.

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
say (:attr:`lab.estimation.PoseEKF.estimate`, which predicts them: its gate, likelihood and NIS are the
papers'), and reports the object's as that pose with ``Sigma_m`` added
(:attr:`lab.estimation.PoseEKF.object_estimate`). How its size was chosen:
docs/tuning/database-point-std.md.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "CalibrationUncertainty",
    "ModelUncertainty",
    "calibration_columns",
    "calibration_jacobian",
    "model_offset_covariance",
    "with_calibration",
]


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
        left out: it places C on the robot and does not move the points measured in C. How this model
        was chosen: docs/tuning/ekf-calibration-error.md."""
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


@functools.lru_cache(maxsize=64)
def calibration_columns(calibration: CalibrationUncertainty) -> tuple[int, ...]:
    """The parts of ``c = [s, delta]`` with a non-zero std (only those join the update, so that its
    prior stays SPD); worked out once per (immutable) calibration."""
    return tuple(j for j, sd in enumerate(np.diag(calibration.covariance())) if sd > 0)


def with_calibration(Sigma_bar, P_xc, r, C, d, calibration: CalibrationUncertainty):
    """The update's prior and Jacobian with the calibration error ``c`` in the state (module
    docstring): ``[[Sigma_bar, P_xc], [P_xc^T, Sigma_c]]`` and ``[C_j, U_j]``, ``U_j`` at the
    predicted points ``h_j = d_j - r_j``, over the columns of :func:`calibration_columns`."""
    cols = calibration_columns(calibration)
    if not cols:
        return Sigma_bar, C
    k = Sigma_bar.shape[0]
    prior = np.zeros((k + len(cols), k + len(cols)))
    prior[:k, :k] = Sigma_bar
    prior[:k, k:] = P_xc
    prior[k:, :k] = P_xc.T
    prior[k:, k:] = calibration.covariance()[np.ix_(cols, cols)]
    return prior, np.concatenate([C, calibration_jacobian(d - r)[..., cols]], axis=2)


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
