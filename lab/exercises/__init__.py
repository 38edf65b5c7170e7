r"""Checks that answer back: the notebooks' exercises, and the assignments' public tests.

Every check takes the student's answer, a function, runs it on inputs of its own and returns a
:class:`Feedback`: "correct", or a hint that names the mistake it recognises (a wrong sign, transposed
axes, degrees where radians are wanted, a missing normalisation, ...). A stub that still raises
``NotImplementedError`` (or returns ``None``/``...``) gets "not attempted yet", so a notebook with its
exercises untouched runs to the end.

The checks do not carry the answer. Each compares the student's output, within a tolerance, with a
value computed by an *independent* method on the same inputs: OpenCV's triangulation and projection,
SciPy's rotations, softmax and entropy, finite differences, the information form of the Kalman update,
networkx's shortest paths, a fine numerical integration, products of homogeneous matrices. A NaN fails
every tolerance (``not (err <= tol)``). The hints come from running the same independent reference with
the mistake made on purpose (``R.T`` for "transposed", ``np.radians`` of the input for "degrees") and
comparing again.

The functions' signatures are those of the assignments (``assignments/*/``), so a notebook exercise
prepares its assignment and the public tests can call the same check:

==========================  ===========  ======================================================
check                       notebook     the student's function
==========================  ===========  ======================================================
:func:`check_triangulate`   00, stereo   ``triangulate(uv, disparity, f, cx, cy, baseline)``
:func:`check_project`       00, stereo   ``project(points_C, f, cx, cy)``
:func:`check_depth_std`     00, stereo   ``depth_std(Z, f, baseline, sigma_disparity)``
:func:`check_rotation_zyx`  01, ekf      ``rotation_zyx(alpha, beta, gamma)``
:func:`check_measurement_jacobian`  01   ``measurement_jacobian(X, b_O)``
:func:`check_kalman_update` 01, ekf      ``kalman_update(mu_bar, Sigma_bar, y, C, Sigma_m)``
:func:`check_entropy`       02, planning ``entropy(P)``
:func:`check_model_probabilities`  02    ``model_probabilities(P_prior, log_likelihood)``
:func:`check_information_gain`     02    ``information_gain(P, likelihood)``
:func:`check_detection_likelihood` 03    ``detection_likelihood(shape, cell, detected, alpha, beta)``
:func:`check_map_update`    03, search   ``update_probability_map(P, cell, detected, alpha, beta)``
:func:`check_octile_heuristic`     03    ``octile_heuristic(cell, goal, min_cost)``
:func:`check_wheel_speeds`  04           ``wheel_speeds(v, omega, track)``
:func:`check_ramp_distance` 04           ``ramp_distance(v, accel, duration)``
:func:`check_odometry_step` 04           ``odometry_step(pose, d_left, d_right, track)``
:func:`check_motion_model`  05           ``motion_model(x, u)``
:func:`check_landmark_measurement` 05    ``landmark_measurement(x, l)``
:func:`check_joseph_covariance`    05    ``joseph_covariance(Sigma_bar, K, H, Q)``
==========================  ===========  ======================================================

Units are SI and angles radians throughout (``docs/conventions.md``). This package sits beside the
algorithm packages: it imports the ground floor, NumPy, SciPy and (inside the checks that need them)
OpenCV and networkx; never the simulator or matplotlib.
"""

from lab.exercises.base import check_odometry_step, check_ramp_distance, check_wheel_speeds
from lab.exercises.ekf import check_kalman_update, check_measurement_jacobian, check_rotation_zyx
from lab.exercises.feedback import Feedback, Status
from lab.exercises.localization import check_joseph_covariance, check_landmark_measurement, check_motion_model
from lab.exercises.planning import check_entropy, check_information_gain, check_model_probabilities
from lab.exercises.search import check_detection_likelihood, check_map_update, check_octile_heuristic
from lab.exercises.stereo import check_depth_std, check_project, check_triangulate

__all__ = [
    "Feedback",
    "Status",
    "check_depth_std",
    "check_detection_likelihood",
    "check_entropy",
    "check_information_gain",
    "check_joseph_covariance",
    "check_kalman_update",
    "check_landmark_measurement",
    "check_map_update",
    "check_measurement_jacobian",
    "check_model_probabilities",
    "check_motion_model",
    "check_octile_heuristic",
    "check_odometry_step",
    "check_project",
    "check_ramp_distance",
    "check_rotation_zyx",
    "check_triangulate",
    "check_wheel_speeds",
]
