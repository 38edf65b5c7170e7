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
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lab.errors import ConfigError

__all__ = ["WorldPoseStd", "larger_axes_std", "world_pose_covariance", "world_pose_std"]


def _skew(v) -> np.ndarray:
    x, y, z = (float(a) for a in v)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def world_pose_covariance(G_WR, Sigma_R, G_RC, pointing_std_rad: float, G_CO, Sigma_CO_rv) -> np.ndarray:
    """``Sigma_WO`` (6, 6) over ``[dp, phi_W]`` [m, rad] in W (the module docstring's first-order model).

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
    S = J_R @ Sigma_R @ J_R.T + pointing_std_rad**2 * (J_d @ J_d.T) + J_o @ Sigma_o @ J_o.T
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
    pos, rot = larger_axes_std(S)
    cpos, crot = larger_axes_std(np.asarray(Sigma_CO_rv, float))
    return WorldPoseStd(pos, rot, cpos, crot, S)
