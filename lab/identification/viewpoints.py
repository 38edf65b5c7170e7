"""Which training viewpoint a relative pose is nearest to.

A database remembers which ring viewpoints saw each feature (``FeatureDatabase.seen_from``), and the
lookup tables have one row per ring viewpoint (the paper's Table I, "the relative pose which best
matches the predicted state"). Both are indexed by the direction from the object's centre to the
camera, in the object frame O: azimuth about O's z axis and elevation above its xy plane.
"""

from __future__ import annotations

import numpy as np

__all__ = ["camera_direction_O", "nearest_viewpoint", "viewpoint_directions"]


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
