"""Figures and pictures. Algorithms never plot; they return data that these functions draw."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from lab.sim.assets import write_png_atomic
from lab.vision.dense import disparity_map

__all__ = ["disparity_map", "disparity_picture", "save_rgb"]


def save_rgb(path: Path, img_rgb: np.ndarray) -> None:
    """Write an RGB image as PNG (atomically)."""
    write_png_atomic(Path(path), img_rgb)


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
