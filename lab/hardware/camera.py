"""Stereo cameras: capture, rectification from a calibration file, replay, and a calibration tool.

* :class:`SideBySideCamera`: a USB stereo camera that delivers both images side by side in one frame
  (width = 2 x one image). The mode is read back after setting it (cameras silently fall back to a
  single-eye mode), the halves are split, and ``swap_lr`` says which half is the left camera (public
  code disagrees; cover one lens to check).
* :class:`TwoDeviceCamera`: two ordinary webcams (grabbed back to back, then decoded).
* :class:`ReplayStereoSource`: image pairs from a folder or from arrays (tests, the emulated robot).
* :class:`StereoCalibration`, :func:`load_calibration`, :class:`StereoRectifier` live in
  :mod:`lab.vision.rectify` (re-exported here): the calibration file and the rectification of raw pairs.
* :func:`make_camera_source` and :func:`load_camera_calibration`: the source and the calibration a
  config's ``[camera]`` section describes (the one place that reads those keys; the calibration is
  checked against the section's image size).
* :func:`calibrate_stereo`: chessboard pairs -> calibration (``calibrateCamera`` per camera, then
  ``stereoCalibrate`` with ``CALIB_FIX_INTRINSIC`` and ``stereoRectify``).

Every source returns **RGB** ``uint8`` images (OpenCV's BGR is converted at the capture boundary) with a
timestamp on the monotonic clock. After a pan-tilt move, ``read(after=t)`` discards the frames the driver
buffered and returns one taken after ``t`` (stale frames would show the old view).
"""

from __future__ import annotations

import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from lab.errors import ConfigError, ConnectionLost, DeviceTimeout
from lab.hardware.config import HardwareConfig
from lab.vision.rectify import StereoCalibration, StereoRectifier, load_calibration

__all__ = [
    "RawStereo",
    "ReplayStereoSource",
    "SideBySideCamera",
    "StereoCalibration",
    "StereoRectifier",
    "StereoSource",
    "TwoDeviceCamera",
    "calibrate_folder",
    "calibrate_stereo",
    "find_chessboard",
    "load_calibration",
    "load_camera_calibration",
    "make_camera_source",
    "render_chessboard_view",
    "wait_until_after",
]


# --- sources ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class RawStereo:
    """An unrectified RGB pair and its capture time [s, monotonic clock]."""

    t: float
    left: np.ndarray = field(repr=False)
    right: np.ndarray = field(repr=False)


class StereoSource(ABC):
    """Something that delivers RGB image pairs of ``image_size`` = (width, height) of one image."""

    image_size: tuple[int, int]

    @abstractmethod
    def read(self, after: float | None = None, timeout: float = 2.0) -> RawStereo:
        """The next pair; with ``after``, one captured after that time (stale frames discarded)."""

    def close(self) -> None:  # noqa: B027 - optional hook
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False


def wait_until_after(after: float | None, timeout: float, clock: Callable[[], float]) -> None:
    """Wait until ``clock()`` is past ``after`` (at once for None); DeviceTimeout after ``timeout`` [s]."""
    if after is None:
        return
    t_end = time.monotonic() + timeout
    while clock() <= after:
        if time.monotonic() >= t_end:
            raise DeviceTimeout(f"no camera frame newer than t={after:.3f} s within {timeout:.1f} s")
        time.sleep(min(0.005, max(0.0, after - clock()) + 1e-4))


class SideBySideCamera(StereoSource):
    """A USB stereo camera delivering one (H, 2W) frame with both images side by side.

    Parameters
    ----------
    device : int or str
        OpenCV device index, ``/dev/videoN``, or a video file (for tests).
    width, height : int [px]
        One image's size; the camera is asked for ``2 * width`` x ``height`` and the answer is checked.
    swap_lr : bool
        False: the left half of the frame is the left camera.
    fourcc : str
        Pixel format to request ("MJPG" saves USB bandwidth); "" leaves the default.
    flush_grabs : int
        Frames discarded by ``read(after=...)`` (the driver's buffer holds a few old ones).
    capture_factory : callable
        ``cv2.VideoCapture`` (replaceable in tests).
    """

    def __init__(
        self,
        device: int | str = 0,
        width: int = 1280,
        height: int = 720,
        *,
        swap_lr: bool = False,
        fourcc: str = "MJPG",
        flush_grabs: int = 4,
        capture_factory: Callable = cv2.VideoCapture,
    ):
        self.device = device
        self.image_size = (int(width), int(height))
        self.swap_lr = swap_lr
        self.flush_grabs = int(flush_grabs)
        self._cap = capture_factory(device)
        if not self._cap.isOpened():
            raise ConnectionLost(
                f"stereo camera {device!r} could not be opened; check the cable and [camera] device"
            )
        if fourcc:
            self._cap.set(cv2.CAP_PROP_FOURCC, cv2.VideoWriter_fourcc(*fourcc))
        self._cap.set(cv2.CAP_PROP_FRAME_WIDTH, 2 * width)
        self._cap.set(cv2.CAP_PROP_FRAME_HEIGHT, height)
        self._cap.set(cv2.CAP_PROP_BUFFERSIZE, 1)
        got = (int(self._cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(self._cap.get(cv2.CAP_PROP_FRAME_HEIGHT)))
        if got != (2 * width, height):
            self._cap.release()
            raise ConfigError(
                f"stereo camera {device!r} delivers {got[0]}x{got[1]}, not the side-by-side "
                f"{2 * width}x{height} (2 x {width}x{height}) asked for; set [camera] width/height to a mode "
                "it supports (v4l2-ctl --list-formats-ext)"
            )

    def read(self, after: float | None = None, timeout: float = 2.0) -> RawStereo:
        wait_until_after(after, timeout, time.monotonic)
        if after is not None:
            for _ in range(self.flush_grabs):
                self._cap.grab()
        ok, frame = self._cap.read()
        t = time.monotonic()
        if not ok or frame is None:
            raise ConnectionLost(f"stereo camera {self.device!r} returned no frame (unplugged?)")
        w, h = self.image_size
        if frame.shape[:2] != (h, 2 * w):
            raise ConfigError(
                f"stereo camera {self.device!r} sent a {frame.shape[1]}x{frame.shape[0]} frame, "
                f"expected {2 * w}x{h}"
            )
        a, b = frame[:, :w], frame[:, w:]
        if self.swap_lr:
            a, b = b, a
        return RawStereo(t, _to_rgb(a), _to_rgb(b))

    def close(self) -> None:
        self._cap.release()


class TwoDeviceCamera(StereoSource):
    """Two separate cameras; both are grabbed before either is decoded, to keep them close in time."""

    def __init__(
        self,
        left: int | str,
        right: int | str,
        width: int,
        height: int,
        *,
        flush_grabs: int = 4,
        capture_factory: Callable = cv2.VideoCapture,
    ):
        self.image_size = (int(width), int(height))
        self.flush_grabs = int(flush_grabs)
        self._caps = []
        for name, dev in (("left", left), ("right", right)):
            cap = capture_factory(dev)
            if not cap.isOpened():
                self.close()
                raise ConnectionLost(f"{name} camera {dev!r} could not be opened; check [camera] devices")
            cap.set(cv2.CAP_PROP_FRAME_WIDTH, width)
            cap.set(cv2.CAP_PROP_FRAME_HEIGHT, height)
            got = (int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT)))
            self._caps.append(cap)
            if got != (width, height):
                self.close()
                raise ConfigError(f"{name} camera {dev!r} delivers {got[0]}x{got[1]}, not {width}x{height}")

    def read(self, after: float | None = None, timeout: float = 2.0) -> RawStereo:
        wait_until_after(after, timeout, time.monotonic)
        n = 1 + (self.flush_grabs if after is not None else 0)
        for _ in range(n):
            ok = [c.grab() for c in self._caps]
        t = time.monotonic()
        imgs = [c.retrieve()[1] if g else None for c, g in zip(self._caps, ok, strict=True)]
        if any(i is None for i in imgs):
            raise ConnectionLost("a stereo camera returned no frame (unplugged?)")
        return RawStereo(t, _to_rgb(imgs[0]), _to_rgb(imgs[1]))

    def close(self) -> None:
        for c in self._caps:
            c.release()


def _to_rgb(bgr: np.ndarray) -> np.ndarray:
    if bgr.ndim == 2:
        return cv2.cvtColor(bgr, cv2.COLOR_GRAY2RGB)
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


class ReplayStereoSource(StereoSource):
    """Replays RGB image pairs (in a loop), stamping each with the clock when it is read.

    Parameters
    ----------
    pairs : sequence of (left, right)
        RGB ``uint8`` arrays, all of one shape (H, W, 3).
    loop : bool
        Start over after the last pair (otherwise DeviceTimeout, as a camera that stopped).
    clock : callable
        Time source for the stamps (the robot's ``now``).
    """

    def __init__(
        self,
        pairs: Sequence[tuple[np.ndarray, np.ndarray]],
        *,
        loop: bool = True,
        clock: Callable[[], float] = time.monotonic,
    ):
        if not pairs:
            raise ConfigError("ReplayStereoSource needs at least one image pair")
        shape = np.asarray(pairs[0][0]).shape
        for k, (l, r) in enumerate(pairs):
            for img in (l, r):
                img = np.asarray(img)
                if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 3 or img.shape != shape:
                    raise ConfigError(
                        f"replay pair {k}: images must be RGB uint8 of one shape {shape}, "
                        f"got {img.shape} {img.dtype}"
                    )
        self._pairs = [(np.asarray(l), np.asarray(r)) for l, r in pairs]
        self.image_size = (shape[1], shape[0])
        self.loop = loop
        self.clock = clock
        self._k = 0

    @classmethod
    def from_folder(cls, folder: str | Path, **kw) -> ReplayStereoSource:
        """Pairs ``left_<id>.<ext>`` + ``right_<id>.<ext>`` (png/jpg), in sorted order of ``<id>``."""
        folder = Path(folder)
        if not folder.is_dir():
            raise ConfigError(f"replay folder {folder} not found")
        lefts = sorted(
            p
            for p in folder.iterdir()
            if p.name.startswith("left_") and p.suffix.lower() in (".png", ".jpg", ".jpeg")
        )
        pairs = []
        for lp in lefts:
            rp = lp.with_name("right_" + lp.name[len("left_") :])
            if not rp.exists():
                raise ConfigError(f"replay folder {folder}: {lp.name} has no {rp.name}")
            imgs = [cv2.imread(str(p), cv2.IMREAD_COLOR) for p in (lp, rp)]
            if any(i is None for i in imgs):
                raise ConfigError(f"replay folder {folder}: cannot read {lp.name} or {rp.name}")
            pairs.append((_to_rgb(imgs[0]), _to_rgb(imgs[1])))
        if not pairs:
            raise ConfigError(f"replay folder {folder} has no left_<id>.png / right_<id>.png pairs")
        return cls(pairs, **kw)

    @classmethod
    def synthetic(
        cls, width: int = 320, height: int = 240, disparity_px: int = 8, n: int = 2, seed: int = 0, **kw
    ) -> ReplayStereoSource:
        """Random-dot pairs of a fronto-parallel plane: the right image is the left shifted by the disparity.

        A point at left column ``u`` is at ``u - disparity_px`` on the right (right camera at +baseline).
        """
        rng = np.random.default_rng(seed)
        pairs = []
        for _ in range(n):
            blocks = rng.integers(
                0, 256, size=(height // 4 + 1, (width + disparity_px) // 4 + 1, 3), dtype=np.uint8
            )
            tex = np.repeat(np.repeat(blocks, 4, axis=0), 4, axis=1)[:height]
            pairs.append(
                (
                    np.ascontiguousarray(tex[:, :width]),
                    np.ascontiguousarray(tex[:, disparity_px : disparity_px + width]),
                )
            )
        return cls(pairs, **kw)

    def read(self, after: float | None = None, timeout: float = 2.0) -> RawStereo:
        wait_until_after(after, timeout, self.clock)
        if self._k >= len(self._pairs):
            if not self.loop:
                raise DeviceTimeout("replay source has no more image pairs")
            self._k = 0
        l, r = self._pairs[self._k]
        self._k += 1
        return RawStereo(self.clock(), l.copy(), r.copy())


# --- from the config --------------------------------------------------------------------------------
def load_camera_calibration(cfg: HardwareConfig) -> StereoCalibration:
    """The calibration file ``[camera] calibration`` names, checked against the ``[camera]`` section.

    Both say the image size: ``[camera] width``/``height`` and the file's ``image_width``/``image_height``.

    Raises
    ------
    ConfigError
        The file is missing or unreadable; or the two sizes disagree: one line naming both sizes, the
        config file and its section, and the calibration file.
    """
    c = cfg.camera
    calib = load_calibration(c.calibration)
    w, h = (int(x) for x in calib.image_size)
    if (w, h) != (c.width, c.height):
        where = f"{cfg.path}: " if cfg.path is not None else ""
        raise ConfigError(
            f"{where}[camera] width/height say {c.width}x{c.height} but the calibration file "
            f"{c.calibration} (image_width/image_height) is for {w}x{h}; recalibrate at "
            f"{c.width}x{c.height} or set [camera] width = {w}, height = {h}"
        )
    return calib


def make_camera_source(cfg: HardwareConfig) -> StereoSource:
    """The stereo source a config describes (``[camera] source``)."""
    c = cfg.camera
    if c.source == "side_by_side":
        return SideBySideCamera(
            c.device, c.width, c.height, swap_lr=c.swap_lr, fourcc=c.fourcc, flush_grabs=c.flush_grabs
        )
    if c.source == "two_devices":
        return TwoDeviceCamera(c.devices[0], c.devices[1], c.width, c.height, flush_grabs=c.flush_grabs)
    if c.source == "replay":
        return ReplayStereoSource.from_folder(c.folder)
    if c.source == "sim":
        raise ConfigError(
            '[camera] source = "sim" renders the simulator from the emulators\' true state: run it through '
            "lab.runs.rehearsal.rehearsal() (lab identify --robot does), or choose another source"
        )
    return ReplayStereoSource.synthetic(c.width, c.height)


# --- calibration tool --------------------------------------------------------------------------------
def find_chessboard(image: np.ndarray, board_size: tuple[int, int]) -> np.ndarray | None:
    """Sub-pixel inner corners, shape (n, 1, 2) float32, of a chessboard with ``board_size`` inner corners."""
    gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    ok, corners = cv2.findChessboardCorners(
        gray, board_size, flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    )
    if not ok:
        return None
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-3)
    return cv2.cornerSubPix(gray, corners, (5, 5), (-1, -1), crit)


def calibrate_stereo(
    pairs: Sequence[tuple[np.ndarray, np.ndarray]],
    board_size: tuple[int, int] = (9, 6),
    square_size: float = 0.025,
    min_pairs: int = 5,
) -> StereoCalibration:
    """Calibrate a stereo pair from chessboard views.

    Each camera is calibrated alone (``cv2.calibrateCamera``), then the pair with its intrinsics fixed
    (``cv2.stereoCalibrate``, ``CALIB_FIX_INTRINSIC``), then rectified (``cv2.stereoRectify``).

    Parameters
    ----------
    pairs : sequence of (left, right) images (RGB or grey), one size
    board_size : (columns, rows) of *inner* corners
    square_size : float [m]
        Side of one square; it sets the unit of T and so of the baseline.
    min_pairs : int
        Fewer pairs where both images show the whole board raise ConfigError.
    """
    if not pairs:
        raise ConfigError("calibrate_stereo needs chessboard image pairs")
    h, w = pairs[0][0].shape[:2]
    obj = np.zeros((board_size[0] * board_size[1], 3), np.float32)
    obj[:, :2] = np.mgrid[0 : board_size[0], 0 : board_size[1]].T.reshape(-1, 2) * square_size
    objs, pts_l, pts_r = [], [], []
    for l, r in pairs:
        if l.shape[:2] != (h, w) or r.shape[:2] != (h, w):
            raise ConfigError(f"calibration images must all be {w}x{h}")
        cl, cr = find_chessboard(l, board_size), find_chessboard(r, board_size)
        if cl is not None and cr is not None:
            objs.append(obj)
            pts_l.append(cl)
            pts_r.append(cr)
    if len(objs) < min_pairs:
        raise ConfigError(
            f"the whole {board_size[0]}x{board_size[1]} chessboard was found in both images of only "
            f"{len(objs)} of {len(pairs)} pairs; at least {min_pairs} are needed"
        )
    size = (w, h)
    _, K1, D1, _, _ = cv2.calibrateCamera(objs, pts_l, size, None, None)
    _, K2, D2, _, _ = cv2.calibrateCamera(objs, pts_r, size, None, None)
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-6)
    rms, K1, D1, K2, D2, R, T, _, _ = cv2.stereoCalibrate(
        objs, pts_l, pts_r, K1, D1, K2, D2, size, flags=cv2.CALIB_FIX_INTRINSIC, criteria=crit
    )
    return StereoCalibration.from_intrinsics(K1, D1, K2, D2, R, T, size, rms=float(rms))


def calibrate_folder(folder: str | Path, out_path: str | Path, board_size=(9, 6), square_size: float = 0.025):
    """Calibrate from ``left_<id>.png`` / ``right_<id>.png`` pairs in ``folder`` and save to ``out_path``."""
    src = ReplayStereoSource.from_folder(folder)
    calib = calibrate_stereo(src._pairs, board_size, square_size)
    calib.save(out_path)
    return calib


def render_chessboard_view(
    K: np.ndarray,
    rvec,
    tvec,
    image_size: tuple[int, int],
    board_size: tuple[int, int] = (9, 6),
    square_size: float = 0.025,
    px_per_square: int = 40,
) -> np.ndarray:
    """Render a chessboard (board frame: corners at ``(i, j, 0) * square_size``) seen by a pinhole camera.

    The board texture is warped with the homography ``K [r1 r2 t]`` of the board plane (a distortion-free
    camera), on a grey background. Used to test the calibration tool with a known camera.
    Returns an RGB ``uint8`` image.
    """
    cols, rows = board_size[0] + 1, board_size[1] + 1  # squares
    s = px_per_square
    margin = s  # a white border helps the corner finder
    tex = np.full((rows * s + 2 * margin, cols * s + 2 * margin), 255, np.uint8)
    for j in range(rows):
        for i in range(cols):
            if (i + j) % 2 == 0:
                tex[margin + j * s : margin + (j + 1) * s, margin + i * s : margin + (i + 1) * s] = 0
    # texture pixel (u, v) -> board point (x, y) [m]. Pixel centres are integers, so the first inner corner
    # (between pixels margin + s - 1 and margin + s) is at texture coordinate margin + s - 0.5.
    c0 = margin + s - 0.5
    A = np.array(
        [[square_size / s, 0, -c0 * square_size / s], [0, square_size / s, -c0 * square_size / s], [0, 0, 1]]
    )
    Rm, _ = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64))
    H = (
        np.asarray(K)
        @ np.column_stack([Rm[:, 0], Rm[:, 1], np.asarray(tvec, dtype=np.float64).reshape(3)])
        @ A
    )
    # render 4x larger and average 4x4 blocks (anti-aliasing); pixel centres: u_super = 4 u + 1.5
    S = np.array([[4.0, 0.0, 1.5], [0.0, 4.0, 1.5], [0.0, 0.0, 1.0]])
    big = (image_size[0] * 4, image_size[1] * 4)
    img = cv2.warpPerspective(
        tex, S @ H, big, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=128
    )
    img = cv2.resize(img, image_size, interpolation=cv2.INTER_AREA)
    return cv2.cvtColor(img, cv2.COLOR_GRAY2RGB)
