"""Real cameras: a stereo calibration file and the rectification that turns raw pairs into the rectified
pairs the rest of the package expects (rows are epipolar lines, one pinhole model for both images).

The calibration is an OpenCV FileStorage YAML file with ``image_width``, ``image_height``, ``K1``, ``D1``,
``K2``, ``D2``, ``R``, ``T`` (OpenCV's ``stereoCalibrate`` convention: ``X_right = R X_left + T``, metres)
and, when written by :meth:`StereoCalibration.save`, the rectification ``R1 R2 P1 P2 Q``. The rectified
left camera frame is the raw one turned by ``R1`` (``p_rect = R1 p_raw``).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from lab.errors import ConfigError
from lab.robot import StereoCamera

__all__ = ["StereoCalibration", "StereoRectifier", "load_calibration"]


@dataclass(frozen=True)
class StereoCalibration:
    """A calibrated stereo pair (OpenCV conventions; lengths in metres).

    Attributes
    ----------
    image_size : (width, height) [px] of one image
    K1, K2 : ndarray, shape (3, 3)
    D1, D2 : ndarray, shape (1, n)
        Distortion coefficients (plumb bob: k1 k2 p1 p2 k3).
    R, T : ndarray, shape (3, 3) and (3, 1)
        Left camera -> right camera: ``X_right = R @ X_left + T``; a right camera at +b along x has
        ``T = [-b, 0, 0]``.
    R1, R2, P1, P2, Q : ndarray
        ``cv2.stereoRectify`` output; the rectified intrinsics are ``P1[:, :3]``, the baseline
        ``-P2[0, 3] / P2[0, 0]``.
    rms : float or None [px]
        Reprojection error of the calibration that produced it.
    """

    image_size: tuple[int, int]
    K1: np.ndarray = field(repr=False)
    D1: np.ndarray = field(repr=False)
    K2: np.ndarray = field(repr=False)
    D2: np.ndarray = field(repr=False)
    R: np.ndarray = field(repr=False)
    T: np.ndarray = field(repr=False)
    R1: np.ndarray = field(repr=False)
    R2: np.ndarray = field(repr=False)
    P1: np.ndarray = field(repr=False)
    P2: np.ndarray = field(repr=False)
    Q: np.ndarray = field(repr=False)
    rms: float | None = None

    @classmethod
    def from_intrinsics(cls, K1, D1, K2, D2, R, T, image_size, rms: float | None = None, alpha: float = 0.0):
        """Compute the rectification (``CALIB_ZERO_DISPARITY``; ``alpha=0`` keeps only valid pixels)."""
        K1, D1, K2, D2, R, T = (np.asarray(a, dtype=np.float64) for a in (K1, D1, K2, D2, R, T))
        D1, D2, T = D1.reshape(1, -1), D2.reshape(1, -1), T.reshape(3, 1)
        size = (int(image_size[0]), int(image_size[1]))
        R1, R2, P1, P2, Q, _, _ = cv2.stereoRectify(
            K1, D1, K2, D2, size, R, T, flags=cv2.CALIB_ZERO_DISPARITY, alpha=alpha
        )
        return cls(size, K1, D1, K2, D2, R, T, R1, R2, P1, P2, Q, rms)

    @classmethod
    def ideal(cls, width: int, height: int, f: float, baseline: float) -> StereoCalibration:
        """A perfect pair: identical pinholes, no distortion, right camera at +baseline along x."""
        K = np.array([[f, 0.0, width / 2.0 - 0.5], [0.0, f, height / 2.0 - 0.5], [0.0, 0.0, 1.0]])
        return cls.from_intrinsics(
            K, np.zeros(5), K, np.zeros(5), np.eye(3), [-baseline, 0.0, 0.0], (width, height)
        )

    @property
    def baseline(self) -> float:
        """Distance between the rectified optical centres [m]."""
        return float(-self.P2[0, 3] / self.P2[0, 0])

    def camera_model(
        self,
        mount_R=(0.0, 0.0, 0.8),
        camera_offset_P=(0.05, 0.06, 0.0),
        depth_scale_std: float = 0.007,
        pointing_std_deg: float = 0.05,
        focal_std: float = 0.005,
    ) -> StereoCamera:
        """The :class:`lab.robot.StereoCamera` of the *rectified* images.

        ``depth_scale_std``, ``pointing_std_deg`` and ``focal_std``: how well a checkerboard calibration
        and a homed pan-tilt know the camera (0.5 % on the focal length and the baseline each, one PTU
        step); the pose filters use them (:attr:`lab.robot.StereoCamera.depth_scale_std`)."""
        w, h = self.image_size
        P = self.P1
        return StereoCamera(
            w,
            h,
            float(P[0, 0]),
            float(P[1, 1]),
            float(P[0, 2]),
            float(P[1, 2]),
            self.baseline,
            tuple(float(v) for v in mount_R),
            tuple(float(v) for v in camera_offset_P),
            float(depth_scale_std),
            float(pointing_std_deg),
            float(focal_std),
        )

    def save(self, path: str | Path) -> None:
        """Write an OpenCV FileStorage YAML file (``cv2.FileStorage`` reads it back), atomically."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.stem}.tmp{os.getpid()}{path.suffix or '.yml'}")
        fs = cv2.FileStorage(str(tmp), cv2.FILE_STORAGE_WRITE)
        try:
            fs.write("image_width", int(self.image_size[0]))
            fs.write("image_height", int(self.image_size[1]))
            for name in ("K1", "D1", "K2", "D2", "R", "T", "R1", "R2", "P1", "P2", "Q"):
                fs.write(name, getattr(self, name))
            if self.rms is not None:
                fs.write("rms", float(self.rms))
        finally:
            fs.release()
        os.replace(tmp, path)


_REQUIRED = ("K1", "D1", "K2", "D2", "R", "T")


def load_calibration(path: str | Path, expected_size: tuple[int, int] | None = None) -> StereoCalibration:
    """Read a calibration file written by :meth:`StereoCalibration.save` (or by hand, K1 D1 K2 D2 R T).

    Raises
    ------
    ConfigError
        File missing or unreadable, a matrix missing or of the wrong shape, or ``expected_size``
        (width, height) different from the calibrated image size.
    """
    path = Path(path)
    if not path.is_file():
        raise ConfigError(
            f"calibration file {path} not found; set [camera] calibration or create one with "
            "lab.hardware.camera.calibrate_folder (hardware/README.md)"
        )
    try:
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
        ok = fs.isOpened()
    except (cv2.error, SystemError) as e:  # malformed YAML surfaces as SystemError from the binding
        raise ConfigError(
            f"calibration file {path} is not an OpenCV YAML file ({str(e).strip()[:80]})"
        ) from e
    if not ok:
        raise ConfigError(f"calibration file {path} could not be opened as OpenCV FileStorage YAML")
    try:
        w, h = fs.getNode("image_width"), fs.getNode("image_height")
        if w.empty() or h.empty():
            raise ConfigError(f"calibration file {path} lacks image_width/image_height")
        size = (int(w.real()), int(h.real()))
        mats = {}
        for name in (*_REQUIRED, "R1", "R2", "P1", "P2", "Q", "rms"):
            node = fs.getNode(name)
            if node.empty():
                if name in _REQUIRED:
                    raise ConfigError(f"calibration file {path} lacks {name} (needs {', '.join(_REQUIRED)})")
                continue
            mats[name] = node.real() if name == "rms" else node.mat()
    finally:
        fs.release()
    shapes = {"K1": (3, 3), "K2": (3, 3), "R": (3, 3)}
    for name, shape in shapes.items():
        if mats[name] is None or mats[name].shape != shape:
            raise ConfigError(f"calibration file {path}: {name} must be a 3x3 matrix")
    if mats["T"] is None or mats["T"].size != 3:
        raise ConfigError(f"calibration file {path}: T must have 3 elements")
    if expected_size is not None and tuple(expected_size) != size:
        raise ConfigError(
            f"calibration file {path} is for {size[0]}x{size[1]} images but the camera delivers "
            f"{expected_size[0]}x{expected_size[1]}; recalibrate or set [camera] width/height to match"
        )
    if all(k in mats for k in ("R1", "R2", "P1", "P2", "Q")):
        return StereoCalibration(
            size,
            *(np.asarray(mats[k], dtype=np.float64) for k in (*_REQUIRED, "R1", "R2", "P1", "P2", "Q")),
            rms=mats.get("rms"),
        )
    return StereoCalibration.from_intrinsics(*(mats[k] for k in _REQUIRED), size, rms=mats.get("rms"))


class StereoRectifier:
    """Remaps raw image pairs to the rectified pair of a :class:`StereoCalibration`."""

    def __init__(self, calib: StereoCalibration):
        self.calib = calib
        size = calib.image_size
        self._maps = [
            cv2.initUndistortRectifyMap(K, D, Rr, P, size, cv2.CV_32FC1)
            for K, D, Rr, P in (
                (calib.K1, calib.D1, calib.R1, calib.P1),
                (calib.K2, calib.D2, calib.R2, calib.P2),
            )
        ]

    def rectify(self, left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rectified (left, right); ConfigError for images of another size than the calibration's."""
        w, h = self.calib.image_size
        for name, img in (("left", left), ("right", right)):
            if img.shape[:2] != (h, w):
                raise ConfigError(
                    f"{name} image is {img.shape[1]}x{img.shape[0]} but the calibration is for {w}x{h}; "
                    "refusing to rectify (recalibrate or fix [camera] width/height)"
                )
        return tuple(
            cv2.remap(img, mx, my, cv2.INTER_LINEAR)
            for img, (mx, my) in zip((left, right), self._maps, strict=True)
        )
