"""Real cameras: a stereo calibration file and the rectification that turns raw pairs into the rectified
pairs the rest of the package expects (rows are epipolar lines, one pinhole model for both images).

The calibration is stored as an OpenCV FileStorage YAML file with ``image_width``, ``image_height``,
``K1``, ``D1``, ``K2``, ``D2``, ``R``, ``T`` (OpenCV's ``stereoCalibrate`` convention: a point in the left
camera frame maps into the right camera frame as ``p_R = R p_L + T``; ``T`` in metres).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field, replace
from pathlib import Path

import cv2
import numpy as np

from lab.errors import AssetError, ConfigError
from lab.robot import StereoCamera

__all__ = ["StereoCalibration", "Rectifier"]


@dataclass(frozen=True)
class StereoCalibration:
    """Intrinsics, distortion and the left-to-right transform of a stereo pair (OpenCV conventions)."""

    image_size: tuple[int, int]  # (width, height) [px]
    K1: np.ndarray = field(repr=False)
    D1: np.ndarray = field(repr=False)
    K2: np.ndarray = field(repr=False)
    D2: np.ndarray = field(repr=False)
    R: np.ndarray = field(repr=False)
    T: np.ndarray = field(repr=False)

    def __post_init__(self):
        for name, shape in (("K1", (3, 3)), ("K2", (3, 3)), ("R", (3, 3))):
            a = np.asarray(getattr(self, name), dtype=float)
            if a.shape != shape or not np.all(np.isfinite(a)):
                raise ConfigError(f"calibration {name} must be a finite {shape[0]}x{shape[1]} matrix")
        if np.asarray(self.T, dtype=float).size != 3:
            raise ConfigError("calibration T must have 3 values (metres)")
        if np.linalg.norm(self.T) <= 0:
            raise ConfigError("calibration T is zero: the baseline must be positive")

    @classmethod
    def load(cls, path: str | Path) -> StereoCalibration:
        """Read a FileStorage YAML calibration; a missing or incomplete file raises with what is missing."""
        path = Path(path)
        if not path.is_file():
            raise AssetError(f"calibration file {path} does not exist")
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
        if not fs.isOpened():
            raise AssetError(f"calibration file {path} could not be read as OpenCV FileStorage (YAML/XML)")
        try:
            vals = {}
            for k in ("K1", "D1", "K2", "D2", "R", "T"):
                m = fs.getNode(k).mat()
                if m is None:
                    raise ConfigError(
                        f"calibration file {path} lacks the matrix {k!r} (needs K1 D1 K2 D2 R T)"
                    )
                vals[k] = m.astype(float)
            w, h = int(fs.getNode("image_width").real()), int(fs.getNode("image_height").real())
            if w <= 0 or h <= 0:
                raise ConfigError(f"calibration file {path} lacks image_width / image_height")
        finally:
            fs.release()
        return cls(
            (w, h),
            vals["K1"],
            vals["D1"].ravel(),
            vals["K2"],
            vals["D2"].ravel(),
            vals["R"],
            vals["T"].ravel(),
        )

    def save(self, path: str | Path) -> None:
        """Write the calibration as FileStorage YAML, atomically."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.stem}.tmp{os.getpid()}{path.suffix or '.yaml'}")
        fs = cv2.FileStorage(str(tmp), cv2.FILE_STORAGE_WRITE)
        fs.write("image_width", int(self.image_size[0]))
        fs.write("image_height", int(self.image_size[1]))
        for k in ("K1", "D1", "K2", "D2", "R", "T"):
            fs.write(k, np.asarray(getattr(self, k), dtype=float))
        fs.release()
        os.replace(tmp, path)


class Rectifier:
    """Rectification maps of a calibrated pair, and the rectified camera model.

    Parameters
    ----------
    calibration : StereoCalibration
    alpha : float
        ``cv2.stereoRectify``'s free scaling: 0 keeps only valid pixels, 1 keeps all source pixels.
    mount_R, camera_offset_P :
        Where the rectified left camera sits on the pan-tilt (as in :class:`StereoCamera`).
    """

    def __init__(
        self,
        calibration: StereoCalibration,
        alpha: float = 0.0,
        mount_R=(0.0, 0.0, 0.7),
        camera_offset_P=(0.05, 0.06, 0.0),
    ):
        c = calibration
        self.calibration = c
        w, h = c.image_size
        K1, K2 = np.asarray(c.K1, float), np.asarray(c.K2, float)
        D1, D2 = np.asarray(c.D1, float).reshape(1, -1), np.asarray(c.D2, float).reshape(1, -1)
        R, T = np.asarray(c.R, float), np.asarray(c.T, float).reshape(3, 1)
        R1, R2, P1, P2, Q, _, _ = cv2.stereoRectify(
            K1, D1, K2, D2, (w, h), R, T, alpha=alpha, flags=cv2.CALIB_ZERO_DISPARITY
        )
        self.R1, self.R2, self.P1, self.P2, self.Q = R1, R2, P1, P2, Q
        self._maps = (
            cv2.initUndistortRectifyMap(K1, D1, R1, P1, (w, h), cv2.CV_32FC1),
            cv2.initUndistortRectifyMap(K2, D2, R2, P2, (w, h), cv2.CV_32FC1),
        )
        baseline = -P2[0, 3] / P2[0, 0]
        self.camera = StereoCamera(
            w,
            h,
            float(P1[0, 0]),
            float(P1[1, 1]),
            float(P1[0, 2]),
            float(P1[1, 2]),
            float(abs(baseline)),
            tuple(mount_R),
            tuple(camera_offset_P),
        )

    def rectify(self, left_raw: np.ndarray, right_raw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rectified (left, right) images of a raw pair; refuses a pair of another resolution."""
        w, h = self.calibration.image_size
        for name, img in (("left", left_raw), ("right", right_raw)):
            if img.shape[1] != w or img.shape[0] != h:
                raise ConfigError(
                    f"{name} image is {img.shape[1]}x{img.shape[0]} px but the calibration is for {w}x{h} px"
                )
        (m1x, m1y), (m2x, m2y) = self._maps
        return (
            cv2.remap(left_raw, m1x, m1y, cv2.INTER_LINEAR),
            cv2.remap(right_raw, m2x, m2y, cv2.INTER_LINEAR),
        )

    def with_mount(self, mount_R, camera_offset_P) -> StereoCamera:
        return replace(self.camera, mount_R=tuple(mount_R), camera_offset_P=tuple(camera_offset_P))
