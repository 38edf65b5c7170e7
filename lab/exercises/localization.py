"""Notebook 05's checks: the planar motion and landmark measurement models and the Joseph-form covariance
for any gain.

See :mod:`lab.exercises` for what a check does and how it avoids carrying the answer.
"""

from __future__ import annotations

import math

import numpy as np

from lab.exercises.feedback import Feedback, Mistake, answer_array, call_answer, checked, close, verdict
from lab.geometry import planar_G

__all__ = ["check_motion_model", "check_landmark_measurement", "check_joseph_covariance"]


def _pose_of(G):
    return np.array([G[0, 3], G[1, 3], math.atan2(G[1, 0], G[0, 0])])


_MOTION_CASES = (
    ((1.0, 2.0, 0.5), (0.3, 0.05, 0.2)),
    ((-1.0, 0.5, 3.0), (0.2, -0.1, 0.4)),
    ((0.0, 0.0, -2.0), (0.1, 0.2, -0.3)),
)


@checked
def check_motion_model(motion_model) -> Feedback:
    """Check ``motion_model(x, u) -> x_new``, the pose ``x = (x, y, theta)`` moved by the increment ``u =
    (dx, dy, dtheta)`` written in its own frame, against the product of homogeneous 2D transforms
    ``G(x) G(u)``; the heading must be wrapped to (-pi, pi]."""
    name = "motion_model"
    got = np.stack(
        [
            answer_array(name, call_answer(name, motion_model, np.array(x), np.array(u)), (3,))
            for x, u in _MOTION_CASES
        ]
    )
    want = np.stack([_pose_of(planar_G(*x) @ planar_G(*u)) for x, u in _MOTION_CASES])

    def rotated(x, u, s):  # R(s theta) (dx, dy) added to (x, y)
        c, sn = math.cos(x[2]), s * math.sin(x[2])
        return np.add(x[:2], np.array([[c, -sn], [sn, c]]) @ u[:2])

    mistakes = [
        Mistake(
            "frame",
            "u is in the robot's own frame: rotate (dx, dy) by the heading before adding it",
            test=lambda g: close(g[:, :2], [np.add(x[:2], u[:2]) for x, u in _MOTION_CASES], 1e-9),
        ),
        Mistake(
            "transposed",
            "transposed rotation: that is R(theta)^T, it turns the increment the wrong way",
            test=lambda g: close(g[:, :2], [rotated(x, u, -1.0) for x, u in _MOTION_CASES], 1e-9),
        ),
        Mistake(
            "wrap",
            "the heading is not wrapped: keep theta in (-pi, pi]",
            test=lambda g: (
                close(g[:, :2], want[:, :2], 1e-9) and close(np.cos(g[:, 2]), np.cos(want[:, 2]), 1e-9)
            ),
        ),
    ]
    return verdict(name, got, want, 1e-9, mistakes, "not the increment composed onto the pose")


_LANDMARK_CASES = (
    ((1.0, 2.0, 0.5), (3.0, 1.0, 2.0)),
    ((-1.0, 0.5, 3.0), (-2.5, 2.0, -2.8)),
    ((0.2, -0.3, -1.0), (1.0, -2.0, 1.5)),
)


@checked
def check_landmark_measurement(landmark_measurement) -> Feedback:
    """Check ``landmark_measurement(x, l) -> z``, the planar pose of landmark ``l = (x_l, y_l, theta_l)``
    (in the world) as the robot at ``x`` sees it, in its own frame, against ``G(x)^-1 G(l)``; the angle
    wrapped to (-pi, pi]."""
    name = "landmark_measurement"
    got = np.stack(
        [
            answer_array(name, call_answer(name, landmark_measurement, np.array(x), np.array(l)), (3,))
            for x, l in _LANDMARK_CASES
        ]
    )
    want = np.stack([_pose_of(np.linalg.inv(planar_G(*x)) @ planar_G(*l)) for x, l in _LANDMARK_CASES])

    def rotate(x, v, s):
        c, sn = math.cos(x[2]), s * math.sin(x[2])
        return np.array([[c, -sn], [sn, c]]) @ v

    diff = [np.subtract(l[:2], x[:2]) for x, l in _LANDMARK_CASES]
    mistakes = [
        Mistake(
            "transposed",
            "transposed rotation: into the robot's frame is R(theta)^T (l - x), not R(theta) (l - x)",
            test=lambda g: close(
                g[:, :2], [rotate(x, d, 1.0) for (x, _), d in zip(_LANDMARK_CASES, diff, strict=True)], 1e-9
            ),
        ),
        Mistake(
            "sign",
            "a wrong sign: the landmark MINUS the robot, l - x",
            test=lambda g: close(g[:, :2], -want[:, :2], 1e-9),
        ),
        Mistake(
            "frame",
            "the difference is in the world frame: rotate it into the robot's frame",
            test=lambda g: close(g[:, :2], diff, 1e-9),
        ),
        Mistake(
            "wrap",
            "the angle is not wrapped: keep it in (-pi, pi]",
            test=lambda g: (
                close(g[:, :2], want[:, :2], 1e-9) and close(np.cos(g[:, 2]), np.cos(want[:, 2]), 1e-9)
            ),
        ),
    ]
    return verdict(name, got, want, 1e-9, mistakes, "not the landmark's pose in the robot frame")


def _joseph_inputs():
    rng = np.random.default_rng(11)
    A = rng.normal(size=(3, 3))
    Sigma_bar = A @ A.T / 3 + 0.05 * np.eye(3)
    H = rng.normal(size=(3, 3))
    Q = np.diag([0.02, 0.03, 0.01])
    K = 0.5 * Sigma_bar @ H.T @ np.linalg.inv(H @ Sigma_bar @ H.T + Q)  # half the optimal gain
    return Sigma_bar, K, H, Q


@checked
def check_joseph_covariance(joseph_covariance) -> Feedback:
    r"""Check ``joseph_covariance(Sigma_bar, K, H, Q) -> Sigma``, the covariance of :math:`\bar x + K\nu`
    for ANY gain ``K``: the check passes half the optimal gain. The reference is the covariance of the
    new error :math:`e' = [I - KH,\; -K]\,[e; v]` with
    :math:`[e; v] \sim N(0, \mathrm{diag}(\bar\Sigma, Q))`."""

    name = "joseph_covariance"
    Sb, K, H, Q = _joseph_inputs()
    got = answer_array(
        name, call_answer(name, joseph_covariance, Sb.copy(), K.copy(), H.copy(), Q.copy()), (3, 3)
    )
    from scipy.linalg import block_diag  # after the answer ran: a stub costs nothing

    A = np.hstack([np.eye(3) - K @ H, -K])
    want = A @ block_diag(Sb, Q) @ A.T
    IKH = np.eye(3) - K @ H
    mistakes = [
        Mistake(
            "short_form",
            "that is the short form (I - KH) Sigma_bar: it holds only for the optimal gain",
            IKH @ Sb,
        ),
        Mistake("missing_noise", "the measurement noise is missing: add K Q K^T", IKH @ Sb @ IKH.T),
        Mistake(
            "transposed",
            "a transpose is missing: (I - KH) Sigma_bar (I - KH)^T + K Q K^T",
            IKH @ Sb @ IKH + K @ Q @ K.T,
        ),
    ]
    return verdict(name, got, want, 1e-10, mistakes, "not the covariance of the updated error")
