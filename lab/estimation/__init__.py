"""Pose estimation: the 6-DOF pose EKF of the two papers and the bank of per-model filters.

State ``X = [x, y, z, alpha, beta, gamma]``: the object frame O in the left camera frame C, z-y-x
Euler angles (``docs/conventions.md``).

* :mod:`~lab.estimation.models`: measurement model Eq. (3) and motion model Eqs. (1)-(2) with their
  analytic Jacobians; :mod:`~lab.estimation.noise`: the process noise of Eq. (2).
* :mod:`~lab.estimation.fit`: closed-form rigid fit and RANSAC initialisation.
* :mod:`~lab.estimation.ekf`: :class:`PoseEKF` (predict, gated Joseph-form update, Eq. (9) likelihood,
  divergence detection), with the geometric gate of :mod:`~lab.estimation.gate` and the
  :class:`PoseEstimate` of :mod:`~lab.estimation.estimate` (and its NEES).
  ``EKFConfig(chart=OrientationChart.ROTATION_VECTOR)`` keeps the covariance over a small rotation
  vector instead of the Euler angles: same state, no gimbal-lock breakdown.
* :mod:`~lab.estimation.kernel`: the update's algebra (whitening, the 6x6 information-form update,
  Eq. (9)'s :func:`data_log_likelihood`) and the checked inputs a filter's steps pass on.
* :mod:`~lab.estimation.uncertainty`: the errors the filter models besides each feature's own noise,
  :class:`CalibrationUncertainty` (the camera's calibration) and :class:`ModelUncertainty` (the
  database's points).
* :mod:`~lab.estimation.health`: :class:`DivergenceConfig` and the check of a filter's state.
* :mod:`~lab.estimation.bank`: :class:`EKFBank`, one filter per database model, driving its filters
  through :class:`PoseEKF`'s public steps with their shared work batched.
* :mod:`~lab.estimation.synthetic`: synthetic box features and stereo-like noise for tests and notebooks.
"""

from lab.estimation.bank import EKFBank
from lab.estimation.ekf import EKFConfig, PoseEKF, UpdateOutcome, UpdateResult
from lab.estimation.estimate import PoseEstimate, nees
from lab.estimation.fit import InitResult, RansacConfig, fit_rigid_transform, ransac_pose
from lab.estimation.gate import GateConfig, gate_matches
from lab.estimation.health import DivergenceConfig
from lab.estimation.kernel import data_log_likelihood
from lab.estimation.models import (
    OrientationChart,
    euler_rate_matrix,
    euler_rate_matrix_inv,
    euler_to_rv_jacobian,
    measurement_covariance,
    measurement_jacobian,
    measurement_jacobian_rv,
    measurement_model,
    motion_jacobian,
    motion_model,
    retract_rv,
    rotvec_to_R,
    rv_to_euler_jacobian,
    state_residual,
)
from lab.estimation.noise import (
    ObjectNoiseKind,
    ProcessNoise,
    motion_noise_jacobians,
    odometry_covariance,
    process_noise_covariance,
)
from lab.estimation.uncertainty import CalibrationUncertainty, ModelUncertainty, model_offset_covariance

__all__ = [
    "DivergenceConfig",
    "EKFBank",
    "EKFConfig",
    "GateConfig",
    "PoseEKF",
    "PoseEstimate",
    "UpdateOutcome",
    "UpdateResult",
    "CalibrationUncertainty",
    "ModelUncertainty",
    "data_log_likelihood",
    "model_offset_covariance",
    "gate_matches",
    "nees",
    "InitResult",
    "RansacConfig",
    "fit_rigid_transform",
    "ransac_pose",
    "retract_rv",
    "rotvec_to_R",
    "rv_to_euler_jacobian",
    "ObjectNoiseKind",
    "OrientationChart",
    "ProcessNoise",
    "euler_rate_matrix",
    "euler_rate_matrix_inv",
    "euler_to_rv_jacobian",
    "measurement_covariance",
    "measurement_jacobian",
    "measurement_jacobian_rv",
    "measurement_model",
    "motion_jacobian",
    "motion_model",
    "motion_noise_jacobians",
    "odometry_covariance",
    "process_noise_covariance",
    "state_residual",
]
