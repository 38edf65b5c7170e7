"""Recordings: an animated file whose frames read back in number and differ over time."""

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from lab.errors import ConfigError  # noqa: E402
from lab.viz.recorder import Recorder, read_animation  # noqa: E402


def test_gif_round_trip_frame_count_and_change(tmp_path):
    rec = Recorder(tmp_path / "run.gif", fps=4)
    fig, ax = plt.subplots(figsize=(3, 2), dpi=60)
    for k in range(7):
        ax.clear()
        ax.plot([0, 1], [0, k])
        rec.add(fig, t=0.5 * k)
    plt.close(fig)
    path = rec.close()
    frames = read_animation(path)
    assert len(frames) == 7 == len(rec)
    assert all(
        np.abs(a.astype(int) - b.astype(int)).sum() > 0 for a, b in zip(frames, frames[1:], strict=False)
    )
    assert not list(tmp_path.glob(".run.tmp*"))  # written atomically: no temporary left behind


def test_mp4_without_an_encoder_falls_back_to_gif(tmp_path, monkeypatch):
    monkeypatch.setattr("shutil.which", lambda name: None)
    rec = Recorder(tmp_path / "run.mp4")
    assert rec.path.suffix == ".gif"
    rec.add(np.zeros((20, 30, 3), np.uint8), 0.0)
    assert rec.close().is_file()


def test_bad_recordings_are_refused(tmp_path):
    with pytest.raises(ConfigError, match="must end in .gif or .mp4"):
        Recorder(tmp_path / "run.avi")
    rec = Recorder(tmp_path / "a.gif")
    with pytest.raises(ValueError, match="RGB uint8"):
        rec.add(np.zeros((10, 10)), 0.0)
    assert rec.close() is None  # nothing to write


def test_frames_are_kept_losslessly_and_in_rgb_order(tmp_path):
    rng = np.random.default_rng(0)
    imgs = [rng.integers(0, 256, (60, 80, 3), dtype=np.uint8) for _ in range(3)]
    imgs[0][:20, :, :] = (255, 0, 0)  # red stays red (no channel swap)
    rec = Recorder(tmp_path / "a.gif")
    for k, img in enumerate(imgs):
        rec.add(img, float(k))
    for kept, img in zip(rec.frames, imgs, strict=True):
        np.testing.assert_array_equal(kept[:30], img[:30])  # above the time stamp, exactly the input
    assert len(read_animation(rec.close())) == 3
