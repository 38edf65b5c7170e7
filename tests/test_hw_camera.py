"""Stereo capture, calibration files, rectification, replay and the calibration tool.

The calibration tool is checked against a known camera: chessboard views are rendered with that camera
(a homography of the board plane, anti-aliased), calibrated, and the recovered focal length, principal
point and baseline are compared with the truth; rectified rows are checked to line up.
"""

import time

import cv2
import numpy as np
import pytest

from lab.errors import ConfigError, ConnectionLost, DeviceTimeout
from lab.hardware.camera import (
    ReplayStereoSource,
    SideBySideCamera,
    StereoCalibration,
    StereoRectifier,
    calibrate_folder,
    calibrate_stereo,
    find_chessboard,
    load_calibration,
    render_chessboard_view,
)

W, H, F, B = 640, 480, 500.0, 0.1
K_TRUE = np.array([[F, 0, W / 2 - 0.5], [0, F, H / 2 - 0.5], [0, 0, 1.0]])
BOARD, SQUARE = (9, 6), 0.025


def _views(n, seed):
    rng = np.random.default_rng(seed)
    pairs, poses = [], []
    for _ in range(n):
        rvec = np.array([rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), rng.uniform(-0.3, 0.3)])
        tvec = np.array(
            [-0.1 + rng.uniform(-0.05, 0.05), -0.07 + rng.uniform(-0.03, 0.03), rng.uniform(0.45, 0.7)]
        )
        left = render_chessboard_view(K_TRUE, rvec, tvec, (W, H), BOARD, SQUARE)
        right = render_chessboard_view(K_TRUE, rvec, tvec - np.array([B, 0, 0]), (W, H), BOARD, SQUARE)
        pairs.append((left, right))
        poses.append((rvec, tvec))
    return pairs, poses


@pytest.fixture(scope="module")
def calib():
    pairs, _ = _views(10, seed=0)
    return calibrate_stereo(pairs, BOARD, SQUARE)


def test_rendered_corners_are_where_the_camera_projects_them():
    """The test images themselves: detected corners match cv2.projectPoints of the board (an OpenCV peer)."""
    _, poses = _views(1, seed=3)
    rvec, tvec = poses[0]
    img = render_chessboard_view(K_TRUE, rvec, tvec, (W, H), BOARD, SQUARE)
    obj = np.zeros((BOARD[0] * BOARD[1], 3))
    obj[:, :2] = np.mgrid[0 : BOARD[0], 0 : BOARD[1]].T.reshape(-1, 2) * SQUARE
    proj, _ = cv2.projectPoints(obj, rvec, tvec, K_TRUE, np.zeros(5))
    found = find_chessboard(img, BOARD)
    d = np.linalg.norm(found.reshape(-1, 2) - proj.reshape(-1, 2), axis=1)
    d_rev = np.linalg.norm(
        found.reshape(-1, 2)[::-1] - proj.reshape(-1, 2), axis=1
    )  # the finder may start at either end
    assert min(d.max(), d_rev.max()) < 0.15


def test_calibration_recovers_the_known_camera(calib):
    assert calib.rms < 0.3
    for K in (calib.K1, calib.K2):
        assert K[0, 0] == pytest.approx(F, rel=0.01) and K[1, 1] == pytest.approx(F, rel=0.01)
        assert K[0, 2] == pytest.approx(W / 2 - 0.5, abs=1.0) and K[1, 2] == pytest.approx(
            H / 2 - 0.5, abs=1.0
        )
    assert calib.baseline == pytest.approx(B, rel=0.01)
    assert np.allclose(calib.R, np.eye(3), atol=0.01)


def test_rectified_rows_line_up_and_depth_is_right(calib):
    """A view not used for calibration: corners share rows after rectification; Z = f B / d is right."""
    pairs, poses = _views(1, seed=42)
    left, right = StereoRectifier(calib).rectify(*pairs[0])
    cl, cr = find_chessboard(left, BOARD), find_chessboard(right, BOARD)
    assert cl is not None and cr is not None
    cl, cr = cl.reshape(-1, 2), cr.reshape(-1, 2)
    if np.linalg.norm(cl[0] - cr[0]) > np.linalg.norm(cl[0] - cr[-1]):
        cr = cr[::-1]
    assert np.abs(cl[:, 1] - cr[:, 1]).max() < 0.5  # epipolar error below half a pixel
    cam = calib.camera_model()
    Z = cam.fx * cam.baseline / (cl[:, 0] - cr[:, 0])
    rvec, tvec = poses[0]
    obj = np.zeros((BOARD[0] * BOARD[1], 3))
    obj[:, :2] = np.mgrid[0 : BOARD[0], 0 : BOARD[1]].T.reshape(-1, 2) * SQUARE
    Z_true = (obj @ cv2.Rodrigues(rvec)[0].T + tvec)[:, 2]
    assert np.median(np.abs(np.sort(Z) - np.sort(Z_true))) < 0.01 * Z_true.mean()


def test_too_few_boards_is_a_clear_error():
    blank = np.full((H, W, 3), 128, np.uint8)
    with pytest.raises(ConfigError, match="found in both images of only 0 of 2 pairs"):
        calibrate_stereo([(blank, blank)] * 2, BOARD, SQUARE)


def test_calibrate_folder_writes_a_loadable_file(tmp_path):
    pairs, _ = _views(6, seed=1)
    for k, (l, r) in enumerate(pairs):
        cv2.imwrite(str(tmp_path / f"left_{k:02d}.png"), cv2.cvtColor(l, cv2.COLOR_RGB2BGR))
        cv2.imwrite(str(tmp_path / f"right_{k:02d}.png"), cv2.cvtColor(r, cv2.COLOR_RGB2BGR))
    out = tmp_path / "stereo.yml"
    c = calibrate_folder(tmp_path, out, BOARD, SQUARE)
    back = load_calibration(out, expected_size=(W, H))
    assert back.baseline == pytest.approx(c.baseline, rel=1e-12) and back.rms == pytest.approx(c.rms)
    for name in ("K1", "D1", "K2", "D2", "R", "T", "P1", "P2", "Q"):
        np.testing.assert_allclose(getattr(back, name), getattr(c, name), rtol=1e-12)


def test_calibration_file_errors_are_one_clear_line(tmp_path):
    good = StereoCalibration.ideal(320, 240, 200.0, 0.12)
    path = tmp_path / "c.yml"
    good.save(path)
    with pytest.raises(ConfigError, match="is for 320x240 images but the camera delivers 640x480") as e:
        load_calibration(path, expected_size=(640, 480))
    assert "\n" not in str(e.value)
    with pytest.raises(ConfigError, match="not found"):
        load_calibration(tmp_path / "missing.yml")
    (tmp_path / "partial.yml").write_text("%YAML:1.0\n---\nimage_width: 320\nimage_height: 240\n")
    with pytest.raises(ConfigError, match="lacks K1"):
        load_calibration(tmp_path / "partial.yml")
    (tmp_path / "junk.yml").write_text("this: [is not\n")
    with pytest.raises(ConfigError, match="junk.yml"):
        load_calibration(tmp_path / "junk.yml")


def test_ideal_calibration_rectifies_to_the_same_image():
    c = StereoCalibration.ideal(320, 240, 207.8, 0.12)
    src = ReplayStereoSource.synthetic(320, 240, disparity_px=6)
    raw = src.read()
    l, r = StereoRectifier(c).rectify(raw.left, raw.right)
    assert np.abs(l.astype(int) - raw.left).max() <= 1 and np.abs(r.astype(int) - raw.right).max() <= 1
    with pytest.raises(ConfigError, match="refusing to rectify"):
        StereoRectifier(c).rectify(raw.left[:100], raw.right[:100])


def test_replay_source_stamps_after_and_end():
    t = [10.0]
    a = np.zeros((20, 30, 3), np.uint8)
    b = np.full((20, 30, 3), 255, np.uint8)
    src = ReplayStereoSource([(a, b), (b, a)], loop=False, clock=lambda: t[0])
    f1 = src.read()
    assert f1.t == 10.0 and (f1.left == a).all() and (f1.right == b).all() and src.image_size == (30, 20)
    f1.left[:] = 7  # a copy: the source is not changed
    t[0] = 10.5
    f2 = src.read(after=10.2)
    assert f2.t == 10.5 and (f2.left == b).all()
    with pytest.raises(DeviceTimeout, match="no more image pairs"):
        src.read()
    with pytest.raises(DeviceTimeout, match="no camera frame newer"):
        ReplayStereoSource([(a, b)], clock=lambda: 0.0).read(after=1.0, timeout=0.05)
    with pytest.raises(ConfigError, match="RGB uint8"):
        ReplayStereoSource([(a, b[:10])])


def test_replay_after_waits_for_a_newer_frame():
    src = ReplayStereoSource.synthetic(32, 24, n=1)
    t = time.monotonic() + 0.05
    f = src.read(after=t)
    assert f.t > t


def test_synthetic_pair_has_the_stated_disparity():
    src = ReplayStereoSource.synthetic(64, 48, disparity_px=5, seed=1)
    f = src.read()
    np.testing.assert_array_equal(f.right[:, :-5], f.left[:, 5:])  # right(u) = left(u + d)


def test_replay_from_folder(tmp_path):
    rng = np.random.default_rng(0)
    imgs = [rng.integers(0, 256, (12, 16, 3), dtype=np.uint8) for _ in range(4)]
    for k in range(2):
        cv2.imwrite(str(tmp_path / f"left_{k}.png"), cv2.cvtColor(imgs[2 * k], cv2.COLOR_RGB2BGR))
        cv2.imwrite(str(tmp_path / f"right_{k}.png"), cv2.cvtColor(imgs[2 * k + 1], cv2.COLOR_RGB2BGR))
    src = ReplayStereoSource.from_folder(tmp_path)
    for k in range(2):
        f = src.read()
        np.testing.assert_array_equal(f.left, imgs[2 * k])  # RGB in, RGB out
        np.testing.assert_array_equal(f.right, imgs[2 * k + 1])
    (tmp_path / "right_1.png").unlink()
    with pytest.raises(ConfigError, match="left_1.png has no right_1.png"):
        ReplayStereoSource.from_folder(tmp_path)
    with pytest.raises(ConfigError, match="not found"):
        ReplayStereoSource.from_folder(tmp_path / "nope")


def _sbs_video(path, w, h, n=5):
    vw = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10, (2 * w, h))
    assert vw.isOpened()
    for _ in range(n):
        f = np.zeros((h, 2 * w, 3), np.uint8)
        f[:, :w] = (0, 0, 255)  # BGR: left half red
        f[:, w:] = (255, 0, 0)  # right half blue
        vw.write(f)
    vw.release()


@pytest.mark.parametrize("swap", [False, True])
def test_side_by_side_capture_splits_the_halves(tmp_path, swap):
    """Through a real cv2.VideoCapture (a video file stands in for the USB device)."""
    _sbs_video(tmp_path / "sbs.avi", 160, 120)
    cam = SideBySideCamera(str(tmp_path / "sbs.avi"), 160, 120, swap_lr=swap, fourcc="", flush_grabs=2)
    f = cam.read()
    red, blue = (f.right, f.left) if swap else (f.left, f.right)
    assert f.left.shape == (120, 160, 3)
    assert red[..., 0].mean() > 240 and red[..., 2].mean() < 15  # RGB: red channel first
    assert blue[..., 2].mean() > 240 and blue[..., 0].mean() < 15
    f2 = cam.read(after=f.t)  # frames 2 and 3 are flushed, 4 is returned
    assert f2.t > f.t
    cam.read()  # frame 5, the last
    with pytest.raises(ConnectionLost, match="returned no frame"):
        cam.read()  # the file (the "camera") ran out
    cam.close()


def test_side_by_side_mode_not_accepted_is_a_clear_error(tmp_path):
    _sbs_video(tmp_path / "sbs.avi", 160, 120)
    with pytest.raises(ConfigError, match=r"delivers 320x120, not the side-by-side 640x120 \(2 x 320x120\)"):
        SideBySideCamera(str(tmp_path / "sbs.avi"), 320, 120, fourcc="")
    with pytest.raises(ConnectionLost, match="could not be opened"):
        SideBySideCamera(str(tmp_path / "missing.avi"), 160, 120)
