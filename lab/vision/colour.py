"""Colour models: the object's chromaticity histogram and its back-projection over an image.

Search paper, Sec. III-B: a cumulative model histogram of the object in red-green space, back-projected
over each image to give, per pixel, how much its colour looks like the object. Red-green chromaticity
``r = R / (R + G + B)``, ``g = G / (R + G + B)`` discards brightness, so the model survives shading.
HSV (hue, saturation) is the alternative the paper suggests for future work.
"""

from __future__ import annotations

import cv2
import numpy as np

from lab.errors import ConfigError

__all__ = ["chromaticity", "colour_histogram", "back_project"]


def chromaticity(img_rgb: np.ndarray, space: str = "rg") -> np.ndarray:
    """Two float32 channels in [0, 1] per pixel: (r, g) chromaticity, or (hue, saturation) for ``"hsv"``."""
    if space == "rg":
        f = img_rgb.astype(np.float32)
        s = f.sum(axis=2) + 1e-6
        return np.stack([f[..., 0] / s, f[..., 1] / s], axis=2)
    if space == "hsv":
        hsv = cv2.cvtColor(img_rgb, cv2.COLOR_RGB2HSV_FULL).astype(np.float32) / 255.0
        return np.ascontiguousarray(hsv[..., :2])
    raise ConfigError(f"colour space must be 'rg' or 'hsv', got {space!r}")


def colour_histogram(
    img_rgb: np.ndarray, mask: np.ndarray | None = None, space: str = "rg", bins: int = 32
) -> np.ndarray:
    """2D histogram (bins, bins) of the masked pixels' chromaticity (counts, float32)."""
    ch = chromaticity(img_rgb, space)
    hist = cv2.calcHist([ch], [0, 1], mask, [bins, bins], [0.0, 1.0 + 1e-6, 0.0, 1.0 + 1e-6])
    return hist.astype(np.float32)


def back_project(
    img_rgb: np.ndarray, model_hist: np.ndarray, space: str = "rg", background_hist: np.ndarray | None = None
) -> np.ndarray:
    """Per-pixel likelihood (H, W) in [0, 1] that the pixel's colour belongs to the model histogram.

    With ``background_hist`` (the image's own histogram) the ratio model/background is used (Swain and
    Ballard's ratio histogram), which suppresses colours that are everywhere, like floor and walls.
    """
    bins = model_hist.shape[0]
    ch = chromaticity(img_rgb, space)
    m = model_hist / max(float(model_hist.max()), 1e-12)
    if background_hist is not None:
        b = background_hist / max(float(background_hist.sum()), 1e-12)
        mm = model_hist / max(float(model_hist.sum()), 1e-12)
        m = np.minimum(mm / np.maximum(b, 1e-12), 1.0).astype(np.float32)
    idx = np.minimum((ch * bins).astype(np.int32), bins - 1)
    return m[idx[..., 0], idx[..., 1]]
