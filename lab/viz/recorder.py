"""Run recordings: frames (RGB images or matplotlib figures) stamped with sim time, written as an
animated GIF (always available, through Pillow) or an MP4 (when an ``ffmpeg`` binary is on the PATH).

A :class:`Recorder` holds its frames in memory, PNG-compressed (a live-view picture of 960 x 540 px takes
about 50-100 kB instead of 1.5 MB raw, so a run of a thousand steps fits), and writes the file once, at
:meth:`Recorder.close`, through a temporary file and a rename, so a crashed run never leaves a
half-written animation behind.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import cv2
import numpy as np

from lab.errors import ConfigError

__all__ = ["Recorder", "figure_to_rgb", "read_animation"]


def figure_to_rgb(fig) -> np.ndarray:
    """A matplotlib figure rendered to an RGB ``uint8`` array (H, W, 3)."""
    fig.canvas.draw()
    return np.ascontiguousarray(np.asarray(fig.canvas.buffer_rgba())[..., :3])


def _stamp(img: np.ndarray, text: str) -> np.ndarray:
    out = img.copy()
    h = out.shape[0]
    scale = max(0.4, h / 600)
    (tw, th), _ = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)
    cv2.rectangle(out, (4, h - th - 12), (12 + tw, h - 4), (255, 255, 255), -1)
    cv2.putText(out, text, (8, h - 8), cv2.FONT_HERSHEY_SIMPLEX, scale, (0, 0, 0), 1, cv2.LINE_AA)
    return out


class Recorder:
    """Collect frames of a run and write them as an animation.

    Parameters
    ----------
    path : str or Path
        ``.gif`` or ``.mp4``. MP4 needs ``ffmpeg`` on the PATH; without it a ``.gif`` is written next
        to the requested path instead (and :attr:`path` says so).
    fps : float
        Playback rate.
    """

    def __init__(self, path: str | Path, fps: float = 5.0):
        path = Path(path)
        if path.suffix.lower() not in (".gif", ".mp4"):
            raise ConfigError(f"recording {path}: the file must end in .gif or .mp4")
        if not 0.5 <= fps <= 60:
            raise ConfigError(f"recording fps must be within [0.5, 60], got {fps}")
        if path.suffix.lower() == ".mp4" and shutil.which("ffmpeg") is None:
            path = path.with_suffix(".gif")  # no encoder here: an animated GIF instead
        self.path = path
        self.fps = fps
        self._png: list[bytes] = []  # the stamped frames, PNG-encoded (RGB order kept)
        self._shape: tuple[int, ...] | None = None
        self.times: list[float] = []

    def __len__(self) -> int:
        return len(self._png)

    def _frames(self):
        """The stamped frames, decoded one at a time (RGB uint8)."""
        for b in self._png:
            yield cv2.imdecode(np.frombuffer(b, np.uint8), cv2.IMREAD_UNCHANGED)

    @property
    def frames(self) -> list[np.ndarray]:
        """All stamped frames, decoded (RGB uint8; memory: H * W * 3 bytes each)."""
        return list(self._frames())

    def add(self, frame, t: float) -> None:
        """Add one frame (RGB array or matplotlib figure), stamped with the sim time ``t`` [s]."""
        img = figure_to_rgb(frame) if hasattr(frame, "canvas") else np.asarray(frame)
        if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
            raise ValueError(f"a frame must be an RGB uint8 image (H, W, 3), got {img.shape} {img.dtype}")
        if self._shape is None:
            self._shape = img.shape
        elif img.shape != self._shape:
            img = cv2.resize(img, (self._shape[1], self._shape[0]), interpolation=cv2.INTER_AREA)
        ok, buf = cv2.imencode(".png", _stamp(img, f"t = {t:6.1f} s"), [cv2.IMWRITE_PNG_COMPRESSION, 1])
        if not ok:  # pragma: no cover - OpenCV always encodes a uint8 image
            raise RuntimeError("PNG encoding of a frame failed")
        self._png.append(buf.tobytes())
        self.times.append(float(t))

    def close(self) -> Path | None:
        """Write the animation (atomically); returns its path, or None when there were no frames."""
        if not self._png:
            return None
        self.path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.path.with_name(f".{self.path.stem}.tmp{os.getpid()}{self.path.suffix}")
        if self.path.suffix.lower() == ".gif":
            from PIL import Image

            imgs = (Image.fromarray(f) for f in self._frames())  # one frame decoded at a time
            next(imgs).save(
                tmp,
                save_all=True,
                append_images=imgs,
                duration=int(1000 / self.fps),
                loop=0,
                optimize=False,
            )
        else:
            self._write_mp4(tmp)
        os.replace(tmp, self.path)
        return self.path

    def _write_mp4(self, tmp: Path) -> None:
        h, w = self._shape[:2]
        with tempfile.TemporaryDirectory() as d:
            for i, f in enumerate(self._frames()):
                cv2.imwrite(os.path.join(d, f"{i:06d}.png"), cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
            cmd = [
                "ffmpeg",
                "-loglevel",
                "error",
                "-y",
                "-framerate",
                str(self.fps),
                "-i",
                os.path.join(d, "%06d.png"),
                "-vf",
                f"scale={w - w % 2}:{h - h % 2}",
                "-pix_fmt",
                "yuv420p",
                str(tmp),
            ]
            subprocess.run(cmd, check=True, timeout=600)


def read_animation(path: str | Path) -> list[np.ndarray]:
    """The frames of a written GIF (RGB arrays): for tests and for checking a recording."""
    from PIL import Image, ImageSequence

    with Image.open(path) as im:
        return [np.asarray(f.convert("RGB")) for f in ImageSequence.Iterator(im)]
