"""Dense stereo: semi-global matching to a disparity map and a point cloud (for the costmap)."""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["checked_disparity", "disparity_map", "dense_points"]


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


def checked_disparity(
    left_rgb: np.ndarray,
    right_rgb: np.ndarray,
    num_disparities: int = 64,
    block_size: int = 5,
    max_lr_diff: float = 1.0,
) -> np.ndarray:
    """Dense disparity [px] over the whole image width, kept where left and right agree; NaN elsewhere.

    Two changes to :func:`disparity_map`:

    * **Full width.** StereoSGBM leaves the ``num_disparities`` leftmost columns empty (their search
      range runs off the right image). Both images are padded on the left with ``num_disparities``
      black columns, so those columns are matched wherever the right camera saw the point.
    * **Left-right check.** The right image's disparity ``d_R`` is computed as well (the same matcher
      on the mirrored pair), and a left disparity ``d`` at column ``u`` is kept only when
      ``|d_R(u - d) - d| <= max_lr_diff``: a match must be found from both sides. This removes most
      mismatches at occlusions and in weak texture (SGM's smoothing drags a near surface's disparity
      into the far, faint wall beside it), which otherwise land as points far in front of the surface.

    Measured in the lab room (48 views, 320 x 240, depths up to 2 m, against the depth buffer): 13 %
    more valid pixels than :func:`disparity_map`, errors above 0.2 m down from 0.78 % to 0.43 % of them,
    at about 2.7x the time (two matchings on images 20 % wider).
    """
    n = int(num_disparities)

    def pad(img):
        return cv2.copyMakeBorder(img, 0, 0, n, 0, cv2.BORDER_CONSTANT, value=0)

    def mirror(img):
        return np.ascontiguousarray(img[:, ::-1])

    d_L = disparity_map(pad(left_rgb), pad(right_rgb), n, block_size)[:, n:]
    # the right image's disparity: in the mirrored pair, the right image is the left one
    d_R = disparity_map(pad(mirror(right_rgb)), pad(mirror(left_rgb)), n, block_size)[:, n:][:, ::-1]
    v, u = np.nonzero(np.isfinite(d_L))
    u_R = np.round(u - d_L[v, u]).astype(np.int64)
    ok = u_R >= 0
    v, u, u_R = v[ok], u[ok], u_R[ok]
    agree = np.abs(d_R[v, u_R] - d_L[v, u]) <= max_lr_diff  # NaN in d_R: no agreement
    out = np.full_like(d_L, np.nan)
    out[v[agree], u[agree]] = d_L[v[agree], u[agree]]
    return out


def dense_points(
    left_rgb: np.ndarray,
    right_rgb: np.ndarray,
    camera,
    step: int = 2,
    max_depth: float = 6.0,
    checked: bool = False,
) -> np.ndarray:
    """3D points (n, 3) [m] in the left camera frame C from dense disparity, every ``step`` pixels.

    ``checked=True`` uses :func:`checked_disparity` (full width, left-right consistent) instead of
    :func:`disparity_map`.
    """
    d = (checked_disparity if checked else disparity_map)(left_rgb, right_rgb)[::step, ::step]
    v, u = np.mgrid[0 : camera.height : step, 0 : camera.width : step]
    ok = np.isfinite(d)
    Z = camera.fx * camera.baseline / d[ok]
    keep = Z < max_depth
    Z = Z[keep]
    X = (u[ok][keep] - camera.cx) * Z / camera.fx
    Y = (v[ok][keep] - camera.cy) * Z / camera.fy
    return np.stack([X, Y, Z], axis=1)
