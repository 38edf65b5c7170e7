"""Rigid-body geometry: SE(3) transforms, z-y-x Euler angles, frames and the pan-tilt kinematics.

Conventions (frames W, R, P, C, O; ``G_AB`` maps points in B into A; Euler order z-y-x as the papers
use it; units) are written down once in ``docs/conventions.md``.

Everything here is plain NumPy and works on single values. Functions whose names end in ``_batch``
take stacks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "Pose2D",
    "R_BODY_TO_OPTICAL",
    "Rx",
    "Ry",
    "Rz",
    "compose",
    "euler_zyx_to_R",
    "R_to_euler_zyx",
    "pose6_to_G",
    "G_to_pose6",
    "se3",
    "se3_inv",
    "transform_points",
    "translation",
    "wrap_angle",
    "quat_xyzw_to_R",
    "R_to_quat_xyzw",
    "pan_tilt_G_RP",
    "pan_tilt_G_RC",
    "planar_G",
    "relative_pose2d",
]


def wrap_angle(a):
    """Wrap an angle (or array of angles) [rad] to (-pi, pi]."""
    if isinstance(a, (float, int, np.floating, np.integer)):  # a scalar: Python's float modulo, as np.mod's
        w = (float(a) + math.pi) % (2.0 * math.pi) - math.pi
        return math.pi if w == -math.pi else w
    w = np.mod(np.asarray(a, dtype=float) + np.pi, 2.0 * np.pi) - np.pi
    w = np.where(w == -np.pi, np.pi, w)
    return float(w) if np.ndim(w) == 0 else w


def Rx(a: float) -> np.ndarray:
    """Rotation by ``a`` [rad] about the x axis, shape (3, 3)."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def Ry(a: float) -> np.ndarray:
    """Rotation by ``a`` [rad] about the y axis, shape (3, 3)."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def Rz(a: float) -> np.ndarray:
    """Rotation by ``a`` [rad] about the z axis, shape (3, 3)."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def euler_zyx_to_R(alpha: float, beta: float, gamma: float) -> np.ndarray:
    r"""Rotation matrix of z-y-x Euler angles, the papers' ``R(x_o)``.

    .. math:: R(\alpha, \beta, \gamma) = R_z(\alpha) R_y(\beta) R_x(\gamma)

    Parameters
    ----------
    alpha, beta, gamma : float [rad]
        Yaw about z, then pitch about the new y, then roll about the newest x.

    Returns
    -------
    R : ndarray, shape (3, 3)
    """
    ca, sa = np.cos(alpha), np.sin(alpha)
    cb, sb = np.cos(beta), np.sin(beta)
    cg, sg = np.cos(gamma), np.sin(gamma)
    return np.array(
        [
            [ca * cb, ca * sb * sg - sa * cg, ca * sb * cg + sa * sg],
            [sa * cb, sa * sb * sg + ca * cg, sa * sb * cg - ca * sg],
            [-sb, cb * sg, cb * cg],
        ]
    )


def R_to_euler_zyx(R: np.ndarray) -> np.ndarray:
    """z-y-x Euler angles ``[alpha, beta, gamma]`` [rad] of a rotation matrix.

    ``beta`` is in [-pi/2, pi/2]; ``alpha`` and ``gamma`` in (-pi, pi]. At gimbal lock
    (``|beta| = pi/2``) ``gamma`` is set to 0 and ``alpha`` carries the whole yaw.
    """
    R = np.asarray(R, dtype=float)
    sb = -R[2, 0]
    cb = np.hypot(R[0, 0], R[1, 0])
    beta = float(np.arctan2(sb, cb))  # atan2 keeps full precision near +-pi/2, where arcsin does not
    if cb > 1e-12:
        alpha = np.arctan2(R[1, 0], R[0, 0])
        gamma = np.arctan2(R[2, 1], R[2, 2])
    else:  # gimbal lock: R = Rz(alpha) Ry(+-pi/2) Rx(gamma) depends on alpha -+ gamma only
        gamma = 0.0
        alpha = np.arctan2(-R[0, 1], R[1, 1])
        beta = float(np.copysign(np.pi / 2, sb))
    return np.array([wrap_angle(alpha), beta, wrap_angle(gamma)])


def se3(R: np.ndarray | None = None, t=None) -> np.ndarray:
    """Homogeneous 4x4 transform from a rotation (3, 3) and a translation (3,) [m]."""
    G = np.eye(4)
    if R is not None:
        G[:3, :3] = R
    if t is not None:
        G[:3, 3] = np.asarray(t, dtype=float).reshape(3)
    return G


def translation(x: float = 0.0, y: float = 0.0, z: float = 0.0) -> np.ndarray:
    """A pure translation as a 4x4 transform."""
    return se3(None, (x, y, z))


def se3_inv(G: np.ndarray) -> np.ndarray:
    """Inverse of a rigid transform: ``G_BA`` from ``G_AB`` (uses R^T, never a general inverse)."""
    R = G[:3, :3]
    t = G[:3, 3]
    Gi = np.eye(4)
    Gi[:3, :3] = R.T
    Gi[:3, 3] = -R.T @ t
    return Gi


def compose(*Gs: np.ndarray) -> np.ndarray:
    """Product of transforms, left to right: ``compose(G_AB, G_BC) = G_AC``."""
    out = np.eye(4)
    for G in Gs:
        out = out @ G
    return out


def transform_points(G_AB: np.ndarray, p_B: np.ndarray) -> np.ndarray:
    """Points written in B, shape (n, 3) or (3,), expressed in A."""
    p_B = np.asarray(p_B, dtype=float)
    return p_B @ G_AB[:3, :3].T + G_AB[:3, 3]


def pose6_to_G(X) -> np.ndarray:
    """4x4 transform of a 6-DOF pose ``X = [x, y, z, alpha, beta, gamma]`` (z-y-x Euler, [m, rad])."""
    X = np.asarray(X, dtype=float)
    return se3(euler_zyx_to_R(X[3], X[4], X[5]), X[:3])


def G_to_pose6(G: np.ndarray) -> np.ndarray:
    """6-DOF pose ``[x, y, z, alpha, beta, gamma]`` of a 4x4 transform."""
    return np.concatenate([G[:3, 3], R_to_euler_zyx(G[:3, :3])])


def quat_xyzw_to_R(q) -> np.ndarray:
    """Rotation matrix of a unit quaternion in PyBullet's / SciPy's ``(x, y, z, w)`` order."""
    x, y, z, w = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def R_to_quat_xyzw(R: np.ndarray) -> np.ndarray:
    """Unit quaternion ``(x, y, z, w)`` with ``w >= 0`` of a rotation matrix (Shepperd's method)."""
    R = np.asarray(R, dtype=float)
    tr = np.trace(R)
    diag = np.diag(R)
    k = int(np.argmax([tr, *diag]))
    if k == 0:
        s = 2.0 * np.sqrt(1.0 + tr)
        q = [(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, 0.25 * s]
    elif k == 1:
        s = 2.0 * np.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q = [0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s, (R[2, 1] - R[1, 2]) / s]
    elif k == 2:
        s = 2.0 * np.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2])
        q = [(R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s, (R[0, 2] - R[2, 0]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1])
        q = [(R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s, (R[1, 0] - R[0, 1]) / s]
    q = np.array(q)
    q /= np.linalg.norm(q)
    return -q if q[3] < 0 else q


# Columns are the optical axes (x right, y down, z forward) written in the body axes (x fwd, y left, z up).
R_BODY_TO_OPTICAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def pan_tilt_G_RP(pan: float, tilt: float, mount_R) -> np.ndarray:
    """Pan-tilt frame P in the robot frame R.

    ``G_RP = T(mount_R) @ Rz(pan) @ Ry(-tilt)``: pan counter-clockwise seen from above, tilt up.

    Parameters
    ----------
    pan, tilt : float [rad]
    mount_R : array_like, shape (3,) [m]
        Where the pan axis meets the tilt axis, in R.
    """
    return se3(Rz(pan) @ Ry(-tilt), mount_R)


def pan_tilt_G_RC(pan: float, tilt: float, mount_R, camera_offset_P) -> np.ndarray:
    """Left camera's optical frame C in the robot frame R, for a pan-tilt state.

    ``G_RC = G_RP(pan, tilt) @ T(camera_offset_P) @ R_body_to_optical``

    Parameters
    ----------
    pan, tilt : float [rad]
    mount_R : array_like, shape (3,) [m]
        Pan/tilt axes intersection in R.
    camera_offset_P : array_like, shape (3,) [m]
        Left camera's optical centre in the pan-tilt frame P (x forward, y left, z up).
    """
    return pan_tilt_G_RP(pan, tilt, mount_R) @ se3(R_BODY_TO_OPTICAL, camera_offset_P)


@dataclass(frozen=True)
class Pose2D:
    """A planar pose on the floor: position ``x, y`` [m] and heading ``theta`` [rad] in the world W."""

    x: float
    y: float
    theta: float

    def G(self) -> np.ndarray:
        """The pose as a 4x4 transform ``G_WR`` (robot frame R in the world W)."""
        return planar_G(self.x, self.y, self.theta)

    def as_array(self) -> np.ndarray:
        return np.array([self.x, self.y, self.theta])


def planar_G(x: float, y: float, theta: float) -> np.ndarray:
    """4x4 transform of a planar pose: rotation ``theta`` about z, translation ``(x, y, 0)``."""
    return se3(Rz(theta), (x, y, 0.0))


def relative_pose2d(a: Pose2D, b: Pose2D) -> np.ndarray:
    """``G_{R_a R_b}``: pose ``b`` seen from pose ``a`` (the paper's ``G_{R(k-1) R(k)}``), 4x4."""
    return se3_inv(a.G()) @ b.G()
