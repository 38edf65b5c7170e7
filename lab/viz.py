"""Figures and pictures. Algorithms never plot; they return data that these functions draw."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from lab.sim.assets import write_png_atomic

__all__ = ["disparity_map", "disparity_picture", "save_rgb"]


def save_rgb(path: Path, img_rgb: np.ndarray) -> None:
    """Write an RGB image as PNG (atomically)."""
    write_png_atomic(Path(path), img_rgb)


def disparity_map(
    left_rgb: np.ndarray, right_rgb: np.ndarray, num_disparities: int = 64, block_size: int = 5
) -> np.ndarray:
    """Dense disparity [px] of a rectified pair by semi-global matching (NaN where invalid)."""
    gl = cv2.cvtColor(left_rgb, cv2.COLOR_RGB2GRAY)
    gr = cv2.cvtColor(right_rgb, cv2.COLOR_RGB2GRAY)
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


def disparity_picture(left_rgb: np.ndarray, right_rgb: np.ndarray) -> np.ndarray:
    """A colour picture of the dense disparity (near = warm, far = cool, invalid = black), RGB."""
    d = disparity_map(left_rgb, right_rgb)
    valid = np.isfinite(d)
    out = np.zeros((*d.shape, 3), np.uint8)
    if valid.any():
        lo, hi = np.nanpercentile(d, [2, 98])
        n = np.clip((d - lo) / max(hi - lo, 1e-6), 0, 1)
        col = cv2.applyColorMap((np.nan_to_num(n) * 255).astype(np.uint8), cv2.COLORMAP_TURBO)
        out[valid] = cv2.cvtColor(col, cv2.COLOR_BGR2RGB)[valid]
    return out
