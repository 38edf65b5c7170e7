"""Synthetic matched features for the pose EKF: points on a box, stereo-like noise.

For tests, benchmarks and notebooks that exercise the filter without rendering images. The real
features and their covariances come from ``lab.vision``; these functions only imitate them.

Stereo-like noise: a point at depth ``Z`` triangulated from pixel ``(u, v)`` and disparity
``disp = f b / Z`` has ``X = (u - cx) Z / f``, ``Y = (v - cy) Z / f``, ``Z = f b / disp``. First-order
propagation of independent pixel noise ``sigma_px`` (on u and v) and disparity noise ``sigma_d_px``
gives ``Sigma = J diag(sigma_px^2, sigma_px^2, sigma_d_px^2) J^T`` with

    dX/du = Z/f,   dY/dv = Z/f,   d[X, Y, Z]/d disp = -[X, Y, Z] Z / (f b)

so ``sigma_Z = Z^2 sigma_d_px / (f b)`` and the lateral std is ``Z sigma_px / f`` on the optical
axis, the depth error stretched along the viewing ray off it.
"""

from __future__ import annotations

import numpy as np

from lab.geometry import transform_points

__all__ = [
    "box_surface_points",
    "stereo_covariance",
    "visible_points",
    "noisy_points",
    "rocking_robot_frames",
]


def box_surface_points(rng: np.random.Generator, n_per_face: int, size=0.28) -> tuple[np.ndarray, np.ndarray]:
    """Random points on the six faces of a box centred at O with edges along O's axes.

    Parameters
    ----------
    rng : numpy.random.Generator
    n_per_face : int
    size : float or array_like, shape (3,) [m]
        Edge lengths (a cube for a scalar).

    Returns
    -------
    b_O : ndarray, shape (6 * n_per_face, 3) [m]
        Points in O, face by face (+x, -x, +y, -y, +z, -z).
    normals_O : ndarray, shape (6 * n_per_face, 3)
        Outward unit normal of each point's face.
    """
    half = np.broadcast_to(np.asarray(size, dtype=float), (3,)) / 2.0
    pts, normals = [], []
    for axis in range(3):
        for sign in (1.0, -1.0):
            p = rng.uniform(-half, half, size=(n_per_face, 3))
            p[:, axis] = sign * half[axis]
            nrm = np.zeros((n_per_face, 3))
            nrm[:, axis] = sign
            pts.append(p)
            normals.append(nrm)
    return np.concatenate(pts), np.concatenate(normals)


def stereo_covariance(
    p_C, f_px: float, baseline_m: float, sigma_d_px: float = 0.3, sigma_px: float = 0.5
) -> np.ndarray:
    """Covariance (n, 3, 3) [m^2] of stereo-triangulated points ``p_C`` (n, 3) in the camera frame."""
    p = np.atleast_2d(np.asarray(p_C, dtype=float))
    Z = p[:, 2]
    J = np.zeros((p.shape[0], 3, 3))
    J[:, 0, 0] = Z / f_px  # dX/du
    J[:, 1, 1] = Z / f_px  # dY/dv
    J[:, :, 2] = -p * (Z / (f_px * baseline_m))[:, None]  # d[X, Y, Z]/d disparity
    D = np.array([sigma_px**2, sigma_px**2, sigma_d_px**2])
    return (J * D) @ np.swapaxes(J, 1, 2)


def visible_points(b_O, normals_O, G_CO, K=None, image_size=None, min_cos: float = 0.2) -> np.ndarray:
    """Mask (n,) of box points a camera at C sees: in front, on a face turned towards it (by more than
    ``min_cos``), and inside the image when intrinsics ``K`` (3, 3) and ``image_size`` (W, H) are given."""
    p = transform_points(G_CO, b_O)
    n_C = np.asarray(normals_O, dtype=float) @ G_CO[:3, :3].T
    view = -p / np.linalg.norm(p, axis=1, keepdims=True)
    ok = (p[:, 2] > 0.05) & (np.sum(n_C * view, axis=1) > min_cos)
    if K is not None and image_size is not None:
        uv = (p / p[:, 2:3]) @ np.asarray(K, dtype=float).T
        W, H = image_size
        ok &= (uv[:, 0] >= 0) & (uv[:, 0] <= W - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= H - 1)
    return ok


def noisy_points(rng: np.random.Generator, p_C, Sigma) -> np.ndarray:
    """Gaussian samples ``p_C + L z`` (n, 3) with ``L L^T = Sigma`` (n, 3, 3) and ``z ~ N(0, I)``."""
    L = np.linalg.cholesky(np.asarray(Sigma, dtype=float))
    z = rng.standard_normal((len(L), 3))
    return np.asarray(p_C, dtype=float) + np.einsum("nab,nb->na", L, z)


def rocking_robot_frames(n_steps: int, n_features: int, seed: int = 0):
    """Inputs of ``n_steps`` filter steps with a box 1.1 m ahead: the robot rocks back and forth and the
    head pans a little, so the box stays in view (the EKF benchmarks' data).

    Returns
    -------
    X_end : ndarray, shape (6,)
        The true state after the last step.
    frames : list of tuple
        Per step ``(G_RC_prev, G_RC, G_odom, d_C, b_O, Sigma_d)``: the camera in the robot before and
        after, the odometry increment, and ``n_features`` matched features (measured in C with
        stereo-like noise, their box points in O, their covariances).
    """
    from lab.estimation.models import motion_model
    from lab.geometry import Pose2D, pose6_to_G, relative_pose2d
    from lab.robot import StereoCamera

    rng = np.random.default_rng(seed)
    cam = StereoCamera.from_fov(320, 240, 60.0, baseline=0.12)
    b_all, _ = box_surface_points(rng, 40, 0.28)
    X = np.array([0.05, 0.02, 1.1, 0.6, -0.4, 1.8])
    frames = []
    pan_prev, robot_prev = 0.0, Pose2D(0.0, 0.0, 0.0)
    for k in range(n_steps):
        pan = 0.05 * np.sin(0.1 * k)
        robot = Pose2D(0.1 * np.sin(0.05 * k), 0.0, 0.05 * np.sin(0.03 * k))
        G_odom = relative_pose2d(robot_prev, robot)
        X_k = motion_model(X, cam.G_RC(pan_prev, -0.2), cam.G_RC(pan, -0.2), G_odom)
        idx = rng.choice(len(b_all), n_features, replace=False)
        G = pose6_to_G(X_k)
        p = b_all[idx] @ G[:3, :3].T + G[:3, 3]
        S = stereo_covariance(p, cam.fx, cam.baseline, 0.3, 0.5)
        frames.append(
            (cam.G_RC(pan_prev, -0.2), cam.G_RC(pan, -0.2), G_odom, noisy_points(rng, p, S), b_all[idx], S)
        )
        X, pan_prev, robot_prev = X_k, pan, robot
    return X, frames
