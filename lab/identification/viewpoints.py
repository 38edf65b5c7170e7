"""Which training viewpoint a relative pose is nearest to.

A database remembers which ring viewpoints saw each feature (``FeatureDatabase.seen_from``), and the
lookup tables have one row per ring viewpoint (the paper's Table I, "the relative pose which best
matches the predicted state"). Both are indexed by the direction from the object's centre to the
camera, in the object frame O: azimuth about O's z axis and elevation above its xy plane.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "camera_direction_O",
    "direction_std",
    "nearest_viewpoint",
    "viewpoint_directions",
    "viewpoint_weights",
]


def camera_direction_O(G_CO) -> np.ndarray:
    """Unit vector from O's origin towards the camera, in O, for poses ``G_CO`` (..., 4, 4) -> (..., 3).

    The camera's centre in O is ``-R^T t`` for ``G_CO = [R t; 0 1]``.
    """
    G = np.asarray(G_CO, dtype=float)
    R, t = G[..., :3, :3], G[..., :3, 3]
    p = -np.einsum("...ji,...j->...i", R, t)
    return p / np.linalg.norm(p, axis=-1, keepdims=True)


def viewpoint_directions(viewpoints) -> np.ndarray:
    """Unit vectors (V, 3) of ring viewpoints given as (azimuth, elevation) [rad], shape (V, 2)."""
    v = np.asarray(viewpoints, dtype=float)
    az, el = v[:, 0], v[:, 1]
    return np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=1)


def nearest_viewpoint(G_CO, viewpoints) -> np.ndarray | int:
    """Index of the ring viewpoint nearest (in angle) to the camera's direction seen from the object.

    Parameters
    ----------
    G_CO : ndarray, shape (..., 4, 4)
        Object poses in camera frames.
    viewpoints : ndarray, shape (V, 2) [rad]
        Azimuth and elevation of the ring viewpoints (``FeatureDatabase.viewpoints``).

    Returns
    -------
    int or ndarray of int, shape (...)
    """
    u = camera_direction_O(G_CO)
    idx = np.argmax(u @ viewpoint_directions(viewpoints).T, axis=-1)
    return int(idx) if np.ndim(idx) == 0 else idx


def direction_std(G_CO, Sigma_rv) -> np.ndarray:
    """Standard deviation [rad] of the direction from which the object is seen, from a pose covariance.

    The object turning about the camera's x or y axis, or shifting across the image, changes the
    direction the camera sees it from; turning about the optical axis (z) does not:

    .. math:: \\sigma^2 = \\tfrac12 (\\Sigma_{\\phi,xx} + \\Sigma_{\\phi,yy})
        + \\tfrac12 (\\Sigma_{p,xx} + \\Sigma_{p,yy}) / |t|^2

    Parameters
    ----------
    G_CO : ndarray, shape (..., 4, 4)
    Sigma_rv : ndarray, shape (..., 6, 6)
        Over ``[x_r, phi]`` in the camera frame.
    """
    G = np.asarray(G_CO, dtype=float)
    S = np.asarray(Sigma_rv, dtype=float)
    d2 = np.sum(G[..., :3, 3] ** 2, axis=-1)
    var = 0.5 * (S[..., 3, 3] + S[..., 4, 4]) + 0.5 * (S[..., 0, 0] + S[..., 1, 1]) / d2
    return np.sqrt(np.maximum(var, 0.0))


def viewpoint_weights(G_CO, viewpoints, sigma, min_weight: float = 1e-3) -> np.ndarray:
    """How much each ring viewpoint stands for a relative pose whose viewing direction is uncertain.

    ``w_v ~ exp(-theta_v^2 / (2 sigma^2))`` over the angles ``theta_v`` between the camera's direction
    (seen from O) and the viewpoints, normalised; weights below ``min_weight`` times the largest are
    dropped. ``sigma`` -> 0 gives the nearest viewpoint alone.

    Parameters
    ----------
    G_CO : ndarray, shape (..., 4, 4)
    viewpoints : ndarray, shape (V, 2) [rad]
    sigma : float or ndarray, shape (...) [rad]

    Returns
    -------
    ndarray, shape (..., V)
        Rows sum to 1.
    """
    u = camera_direction_O(G_CO)
    cos = np.clip(u @ viewpoint_directions(viewpoints).T, -1.0, 1.0)
    theta = np.arccos(cos)  # (..., V)
    theta = theta - theta.min(axis=-1, keepdims=True)  # relative to the nearest: exact at sigma -> 0
    s = np.maximum(np.asarray(sigma, dtype=float), 1e-6)[..., None]
    w = np.exp(-0.5 * (theta / s) ** 2)
    w = np.where(w >= min_weight, w, 0.0)
    return w / w.sum(axis=-1, keepdims=True)
