"""Dense stereo: semi-global matching to a disparity map and a point cloud (for the costmap)."""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["disparity_map", "dense_points"]


def disparity_map(
    left_rgb: np.ndarray, right_rgb: np.ndarray, num_disparities: int = 64, block_size: int = 5
) -> np.ndarray:
    """Dense disparity [px] of a rectified pair by semi-global matching (StereoSGBM); NaN where invalid."""
    gl = cv2.cvtColor(left_rgb, cv2.COLOR_RGB2GRAY) if left_rgb.ndim == 3 else left_rgb
    gr = cv2.cvtColor(right_rgb, cv2.COLOR_RGB2GRAY) if right_rgb.ndim == 3 else right_rgb
    sgbm = cv2.StereoSGBM_create(
        minDisparity=0,
        numDisparities=num_disparities,
        blockSize=block_size,
        P1=8 * block_size**2,
        P2=32 * block_size**2,
        uniquenessRatio=10,
        speckleWindowSize=50,
        speckleRange=2,
    )
    d = sgbm.compute(gl, gr).astype(np.float32) / 16.0
    d[d <= 0] = np.nan
    return d


def dense_points(
    left_rgb: np.ndarray, right_rgb: np.ndarray, camera, step: int = 2, max_depth: float = 6.0
) -> np.ndarray:
    """3D points (n, 3) [m] in the left camera frame C from dense disparity, every ``step`` pixels."""
    d = disparity_map(left_rgb, right_rgb)[::step, ::step]
    v, u = np.mgrid[0 : camera.height : step, 0 : camera.width : step]
    ok = np.isfinite(d)
    Z = camera.fx * camera.baseline / d[ok]
    keep = Z < max_depth
    Z = Z[keep]
    X = (u[ok][keep] - camera.cx) * Z / camera.fx
    Y = (v[ok][keep] - camera.cy) * Z / camera.fy
    return np.stack([X, Y, Z], axis=1)
