r"""How well the robot knows a found object's pose in the world: the stated deviation of ``G_WO``.

The local search's EKF says how well it knows the object in the camera frame C (``Sigma_rv`` of its
:class:`~lab.estimation.PoseEstimate`). The object's world pose rests on three more things the robot
knows only to a stated accuracy:

* the robot's planar pose ``(x, y, theta)``, the localizer's covariance ``Sigma_R`` (or dead
  reckoning's);
* the camera's orientation on the robot: the pan-tilt's zero and the mounts of the head on the mast and
  of the camera on its bracket, a small rotation ``delta`` of C (per axis ``pointing_std``, the camera's
  :attr:`~lab.robot.StereoCamera.pointing_std_deg`);
* the object in C, ``[t, phi]`` with ``R_CO,true = Exp(phi) R_CO``.

With ``G_WO = G_WR(x, y, theta) G_RC Exp(delta) G_CO``, to first order the world errors ``[dp, phi_W]``
(``R_WO,true = Exp(phi_W) R_WO``) are, with ``p`` the object's world position, ``t_R`` the robot's and
``t_C`` the camera's:

.. math::

    dp = [dx, dy, 0] + d\theta\, e_z \times (p - t_R) + (R_{WC}\delta) \times (p - t_C) + R_{WC}\, dt,
    \qquad \phi_W = d\theta\, e_z + R_{WC}\delta + R_{WC}\phi.

The three are independent (the robot does not know how its localizer's error and the mount's are
related), so ``Sigma_WO = J_R Sigma_R J_R^T + J_d Sigma_d J_d^T + J_o Sigma_rv J_o^T``. The stated
deviations are those of the larger axes, as the local search's "found" uses them
(:func:`lab.search.tracking.pose_stds`). What they say against the errors of tuning runs, and which of
the room's errors the found pose's error comes from: docs/tuning/search-found-pose.md.

**Resting on a face** (:func:`rest_on_face`). The searched objects are boxes standing on the floor, a
table or a shelf, which are level: one of the box's axes is vertical, exactly. An estimate is tilted by
its errors, and the tilt is information: the constraint ``E_xy Exp(phi_W) a = 0`` (``a`` the box's axis
nearest the vertical, ``E_xy`` its horizontal components) is a perfect measurement of ``phi_W``.
Conditioning the orientation on it removes the tilt and corrects the yaw by what the covariance says is
correlated with the tilt; the stated rotation deviation is then the yaw's. The position is left as
estimated: through ``Sigma_WO``'s cross terms the tilt would also move it, by the camera pointing's
share of the tilt, but on tuning runs the tilt was mostly the local search's own orientation error,
which its EKF understates, and the moves made the position worse as often as better. The local search
rejects a tilt above ``max_rest_tilt_deg`` before it calls a pose found (:mod:`lab.search.pose_check`):
a tilt that large says the pose is wrong, not slightly off. What it changed on tuning runs:
docs/tuning/search-rest-on-face.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from lab.errors import ConfigError

__all__ = [
    "WorldPoseStd",
    "larger_axes_std",
    "rest_on_face",
    "world_pose_covariance",
    "world_pose_std",
    "world_pose_std_of",
]


def _skew(v) -> np.ndarray:
    x, y, z = (float(a) for a in v)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def world_pose_covariance(
    G_WR, Sigma_R, G_RC, pointing_std_rad: float, G_CO, Sigma_CO_rv, yaw_in_pose: bool = False
) -> np.ndarray:
    """``Sigma_WO`` (6, 6) over ``[dp, phi_W]`` [m, rad] in W (the module docstring's first-order model).

    ``yaw_in_pose``: the camera's yaw on the robot (about the vertical) is in ``Sigma_R``'s heading, as
    when the localizer estimates it (``LocalizerConfig.camera_yaw_sigma_rad``: the heading is then the
    camera's, ``theta + beta``), so the pointing's part about the vertical is left out of ``Sigma_d``
    (``pointing_std^2 (I - u u^T)``, ``u`` the vertical in C) rather than counted twice.

    Parameters
    ----------
    G_WR : ndarray, shape (4, 4)
        The robot's planar pose (z up) when the object was seen.
    Sigma_R : array_like, shape (3, 3)
        Its covariance over ``(x, y, theta)`` [m^2, m rad, rad^2].
    G_RC : ndarray, shape (4, 4)
        The camera on the robot at the frame (pan, tilt).
    pointing_std_rad : float [rad]
        Standard deviation per axis of the camera's orientation on the robot (zero, mounts).
    G_CO : ndarray, shape (4, 4)
        The object in the camera frame.
    Sigma_CO_rv : array_like, shape (6, 6)
        Its covariance over ``[t, phi]`` (``phi`` in C), the EKF's ``Sigma_rv``.
    """
    Sigma_R = np.asarray(Sigma_R, float)
    Sigma_o = np.asarray(Sigma_CO_rv, float)
    if Sigma_R.shape != (3, 3) or Sigma_o.shape != (6, 6):
        raise ConfigError(
            f"world_pose_covariance needs Sigma_R (3, 3) and Sigma_CO_rv (6, 6), got {Sigma_R.shape}, "
            f"{Sigma_o.shape}"
        )
    if not (math.isfinite(pointing_std_rad) and pointing_std_rad >= 0):
        raise ConfigError(f"pointing_std_rad must be a finite number >= 0, got {pointing_std_rad!r}")
    G_WC = np.asarray(G_WR, float) @ np.asarray(G_RC, float)
    G_WO = G_WC @ np.asarray(G_CO, float)
    p, t_R, t_C, R_WC = G_WO[:3, 3], np.asarray(G_WR, float)[:3, 3], G_WC[:3, 3], G_WC[:3, :3]
    J_R = np.zeros((6, 3))
    J_R[0, 0] = J_R[1, 1] = 1.0
    J_R[:3, 2] = np.cross([0.0, 0.0, 1.0], p - t_R)
    J_R[5, 2] = 1.0
    J_d = np.vstack([-_skew(p - t_C) @ R_WC, R_WC])  # (R delta) x r = -[r]x R delta
    J_o = np.zeros((6, 6))
    J_o[:3, :3] = R_WC
    J_o[3:, 3:] = R_WC
    Sigma_d = np.eye(3)
    if yaw_in_pose:
        u = R_WC.T @ np.array([0.0, 0.0, 1.0])  # W's vertical in C
        Sigma_d -= np.outer(u, u)
    S = J_R @ Sigma_R @ J_R.T + pointing_std_rad**2 * (J_d @ Sigma_d @ J_d.T) + J_o @ Sigma_o @ J_o.T
    return 0.5 * (S + S.T)


@dataclass(frozen=True)
class WorldPoseStd:
    """The stated deviations of a found object's world pose and their parts.

    Attributes
    ----------
    position_m, rotation_deg : float
        The larger axis of ``Sigma_WO``'s position [m] and rotation [deg] blocks: all of it.
    camera_position_m, camera_rotation_deg : float
        The same of the object in the camera frame alone (the EKF's, what the local search judged).
    Sigma : ndarray, shape (6, 6)
        ``Sigma_WO`` (:func:`world_pose_covariance`).
    """

    position_m: float
    rotation_deg: float
    camera_position_m: float
    camera_rotation_deg: float
    Sigma: np.ndarray

    def as_dict(self) -> dict:
        """The JSON's ``pose_std``: all of it and the camera frame's part, rounded."""
        return {
            "position_m": round(self.position_m, 5),
            "orientation_deg": round(self.rotation_deg, 3),
            "camera_frame_position_m": round(self.camera_position_m, 5),
            "camera_frame_orientation_deg": round(self.camera_rotation_deg, 3),
        }


def larger_axes_std(S) -> tuple[float, float]:
    """The larger axes of a pose covariance (6, 6) over ``[t, phi]``: position [m], rotation [deg]."""
    S = np.asarray(S, float)
    pos = math.sqrt(max(0.0, float(np.linalg.eigvalsh(S[:3, :3])[-1])))
    rot = math.degrees(math.sqrt(max(0.0, float(np.linalg.eigvalsh(S[3:, 3:])[-1]))))
    return pos, rot


def world_pose_std(G_WR, Sigma_R, G_RC, pointing_std_rad: float, G_CO, Sigma_CO_rv) -> WorldPoseStd:
    """:func:`world_pose_covariance` and its larger axes, with the camera frame's own."""
    S = world_pose_covariance(G_WR, Sigma_R, G_RC, pointing_std_rad, G_CO, Sigma_CO_rv)
    return world_pose_std_of(S, Sigma_CO_rv)


def world_pose_std_of(Sigma_WO, Sigma_CO_rv) -> WorldPoseStd:
    """The :class:`WorldPoseStd` of a world covariance ``Sigma_WO`` (6, 6) and the camera frame's
    ``Sigma_CO_rv`` (6, 6) it rests on."""
    S = np.asarray(Sigma_WO, float)
    pos, rot = larger_axes_std(S)
    cpos, crot = larger_axes_std(np.asarray(Sigma_CO_rv, float))
    return WorldPoseStd(pos, rot, cpos, crot, S)


def _upright(R: np.ndarray) -> np.ndarray:
    """The box's axis nearest the vertical, in W, pointing up."""
    k = int(np.argmax(np.abs(R[2])))
    return R[:, k] * (1.0 if R[2, k] >= 0 else -1.0)


def rest_on_face(G_WO, Sigma_WO, iterations: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """The found pose and its covariance with the orientation conditioned on the box resting on a face of
    a level surface (the module docstring): ``(G_WO', Sigma_WO')``, one of the box's axes exactly vertical
    and the position as it was.

    The constraint ``c(phi) = E_xy Exp(phi) a = 0`` on the orientation error ``phi`` (``R' = Exp(phi) R``,
    ``phi ~ N(0, Sigma_phi)``, the rotation block of ``Sigma_WO``) is solved as a perfect measurement by
    Gauss-Newton: at ``phi_i``, with ``C_i = -E_xy [a_i]_x`` (``a_i = Exp(phi_i) a``),
    ``phi_{i+1} = K_i (C_i phi_i - c(phi_i))``, ``K_i = Sigma_phi C_i^T (C_i Sigma_phi C_i^T)^{-1}``: the
    most probable orientation on the linearised constraint. What is left of the tilt after ``iterations``
    steps (second order in it) is turned away by the smallest rotation about the box's centre. The
    covariance is that of this estimator, the position's gain being zero (Joseph's form,
    ``Sigma' = (I - K H) Sigma (I - K H)^T`` with ``K = [0; K]``, ``H = [0, C]``): rank 4, the position's
    three directions and the yaw.

    Parameters
    ----------
    G_WO : ndarray, shape (4, 4)
        The found pose in W (z up).
    Sigma_WO : ndarray, shape (6, 6)
        Its covariance over ``[dp, phi_W]`` (:func:`world_pose_covariance`).
    iterations : int
        Gauss-Newton steps (3: the tilts the local search lets through, under 10 degrees, are then
        corrected to a small fraction of a degree before the last turn).
    """
    G = np.asarray(G_WO, float)
    S = np.asarray(Sigma_WO, float)
    if G.shape != (4, 4) or S.shape != (6, 6):
        raise ConfigError(f"rest_on_face needs G_WO (4, 4) and Sigma_WO (6, 6), got {G.shape}, {S.shape}")
    if not (np.isfinite(G).all() and np.isfinite(S).all()):
        raise ConfigError(
            "rest_on_face needs a finite G_WO and Sigma_WO (a diverged estimate has no pose to correct)"
        )
    a0 = _upright(G[:3, :3])
    S_phi = S[3:, 3:]
    phi = np.zeros(3)
    K = np.zeros((3, 2))
    C = np.zeros((2, 3))
    for _ in range(max(1, int(iterations))):
        a = Rotation.from_rotvec(phi).apply(a0)
        C = -_skew(a)[:2]  # d(E_xy Exp(phi) a0) = E_xy (dphi x a) = -E_xy [a]_x dphi
        W = C @ S_phi @ C.T
        if np.linalg.cond(W) > 1e12:  # no stated tilt uncertainty: nothing to learn from the tilt
            phi, K = np.zeros(3), np.zeros((3, 2))
            break
        K = S_phi @ C.T @ np.linalg.inv(W)
        phi = K @ (C @ phi - a[:2])
    IKH = np.eye(6)
    IKH[3:, 3:] -= K @ C
    S = IKH @ S @ IKH.T
    R = Rotation.from_rotvec(phi).as_matrix() @ G[:3, :3]
    a = _upright(R)
    turn = np.cross(a, [0.0, 0.0, 1.0])  # the rest of the tilt: |turn| = sin(angle)
    if np.linalg.norm(turn) > 0:
        angle = math.atan2(float(np.linalg.norm(turn)), float(a[2]))
        R = Rotation.from_rotvec(turn / np.linalg.norm(turn) * angle).as_matrix() @ R
    out = G.copy()
    out[:3, :3] = R
    return out, 0.5 * (S + S.T)
