"""Pictures as files and bytes: PNG encoding, an RGB image saved atomically, the dense disparity as colour.

Only OpenCV and :mod:`lab.io`: importing it starts neither the simulator nor matplotlib.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from lab.io import write_bytes_atomic
from lab.vision.dense import disparity_map

__all__ = ["disparity_picture", "png_bytes", "save_rgb"]


def png_bytes(img_rgb: np.ndarray) -> bytes:
    """An RGB ``uint8`` image, shape (H, W, 3), encoded as PNG."""
    ok, buf = cv2.imencode(".png", cv2.cvtColor(img_rgb, cv2.COLOR_RGB2BGR))
    if not ok:  # pragma: no cover - OpenCV always encodes a uint8 image
        raise RuntimeError("PNG encoding failed")
    return buf.tobytes()


def save_rgb(path: Path, img_rgb: np.ndarray) -> None:
    """Write an RGB image as PNG (atomically: through a temporary file and a rename)."""
    write_bytes_atomic(Path(path), png_bytes(img_rgb))


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
