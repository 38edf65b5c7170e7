"""Rendering against ground truth: intrinsics, camera pose, per-face textures, determinism."""

import math

import cv2
import numpy as np
import pytest

from lab.geometry import Pose2D, se3_inv, transform_points
from lab.robot import StereoCamera
from lab.sim import SimRobot, SimWorld, load_box_models, viewpoint_G_WC
from lab.sim.assets import FACE_PX, FACES

CAM = StereoCamera.from_fov(320, 240, 60.0, 0.12, mount_R=(0.0, 0.0, 0.7))


def _box_corners_O(size):
    sx, sy, sz = (0.5 * s for s in size)
    return np.array([[x, y, z] for x in (-sx, sx) for y in (-sy, sy) for z in (-sz, sz)])


def _silhouette_centroid(points_C, camera):
    """Area centroid [px] of the convex hull of projected points (the exact silhouette of a convex body)."""
    uv = camera.project(points_C).astype(np.float64)
    hull = cv2.convexHull(uv.astype(np.float32)).reshape(-1, 2).astype(np.float64)
    x, y = hull[:, 0], hull[:, 1]
    x1, y1 = np.roll(x, -1), np.roll(y, -1)
    cross = x * y1 - x1 * y
    A = cross.sum() / 2
    return np.array([((x + x1) * cross).sum() / (6 * A), ((y + y1) * cross).sum() / (6 * A)]), abs(A)


@pytest.fixture(scope="module")
def models():
    return load_box_models()


def test_projection_lands_where_the_renderer_draws(models):
    """A box at ~1 m: the projected silhouette's centroid matches the segmentation mask's within 0.5 px,
    and depth-buffer pixels back-projected with the intrinsics lie on the true box surface."""
    with SimWorld("box_database") as w:
        c = w.add_carrier(models[0], Pose2D(0.0, 0.0, 0.0), box_yaw=0.4)
        for eye in ((1.0, 0.1, 0.75), (0.7, -0.6, 0.6), (-0.5, 0.8, 0.9)):
            G_WC = viewpoint_G_WC(eye, (0.05, -0.03, 0.45))
            seg = w.truth.segmentation(G_WC, CAM)
            depth = w.truth.depth(G_WC, CAM)
            mask = seg == w.body_id("target")
            assert mask.sum() > 1500
            G_CO = se3_inv(G_WC) @ c.G_WO
            expect, area = _silhouette_centroid(transform_points(G_CO, _box_corners_O(models[0].size)), CAM)
            v, u = np.nonzero(mask)
            got = np.array([u.mean(), v.mean()])
            assert np.linalg.norm(got - expect) < 0.25, (eye, got, expect)
            assert abs(mask.sum() - area) / area < 0.03
            # back-project the box's depth pixels (interior only) and measure their distance to the surface
            inner = cv2.erode(mask.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
            v, u = np.nonzero(inner)
            z = depth[v, u]
            p_C = np.stack([(u - CAM.cx) * z / CAM.fx, (v - CAM.cy) * z / CAM.fy, z], axis=1)
            p_O = transform_points(se3_inv(G_CO), p_C)
            half = 0.5 * np.array(models[0].size)
            dist_to_surface = np.min(np.abs(np.abs(p_O) - half), axis=1)
            assert np.median(dist_to_surface) < 1.5e-3
            assert np.all(np.abs(p_O) < half + 5e-3)


def test_robot_camera_pose_matches_the_rendered_view(models):
    """The pan-tilt transform G_RC (and the odometry-free true base pose) is the pose the renderer uses."""
    with SimWorld("box_database") as w:
        c = w.add_carrier(models[2], Pose2D(0.0, 0.0, 0.3))
        r = SimRobot(w, CAM, start=Pose2D(-1.1, 0.15, 0.2))
        r.enable()
        for pan_deg, tilt_deg in ((-10, -12), (-28, -20), (-25, 0)):
            pan, tilt = math.radians(pan_deg), math.radians(tilt_deg)
            r.command_pan_tilt(pan, tilt)
            r.wait_pan_tilt()
            G_WC = Pose2D(-1.1, 0.15, 0.2).G() @ CAM.G_RC(pan, tilt)
            np.testing.assert_allclose(w.truth.G_WC(), G_WC, atol=1e-12)
            seg = w.truth.segmentation(G_WC, CAM)
            mask = seg == w.body_id("target")
            v, u = np.nonzero(mask)
            assert u.min() > 0 and v.min() > 0 and u.max() < CAM.width - 1 and v.max() < CAM.height - 1
            G_CO = se3_inv(G_WC) @ c.G_WO
            expect, _ = _silhouette_centroid(transform_points(G_CO, _box_corners_O(models[2].size)), CAM)
            assert np.linalg.norm([u.mean() - expect[0], v.mean() - expect[1]]) < 0.25
            # the robot's captured left image is the render from exactly that pose
            frame = r.capture_stereo()
            left, _, _ = w.render(G_WC, CAM)
            np.testing.assert_array_equal(frame.left, left)
            np.testing.assert_allclose(frame.G_RC, CAM.G_RC(pan, tilt), atol=1e-12)


def _face_textures(model):
    atlas = cv2.cvtColor(cv2.imread(str(model.atlas)), cv2.COLOR_BGR2GRAY)
    cells = {}
    for k, name in enumerate(FACES):
        r, c = divmod(k, 3)
        cells[name] = atlas[r * FACE_PX : (r + 1) * FACE_PX, c * FACE_PX : (c + 1) * FACE_PX]
    return cells


def _sift_matches(img_gray, tex_gray, sift, ratio=0.75):
    _, d1 = sift.detectAndCompute(img_gray, None)
    _, d2 = sift.detectAndCompute(tex_gray, None)
    if d1 is None or d2 is None:
        return 0
    pairs = cv2.BFMatcher(cv2.NORM_L2).knnMatch(d1, d2, k=2)
    return sum(1 for p in pairs if len(p) == 2 and p[0].distance < ratio * p[1].distance)


def test_unique_face_differs_and_shared_faces_are_identical(models):
    sift = cv2.SIFT_create()
    textures = [_face_textures(m) for m in models]
    # the shared faces use the same pixels in every model's atlas
    for t in textures[1:]:
        for f in ("-X", "+Y", "-Y"):
            np.testing.assert_array_equal(t[f], textures[0]["-X"])
    views = {}
    for k, m in enumerate(models):
        with SimWorld("box_database") as w:
            w.add_carrier(m, Pose2D(0.0, 0.0, 0.0))
            G_unique = viewpoint_G_WC((0.75, 0.0, 0.55), (0.0, 0.0, 0.49))  # looks at +X (unique)
            G_shared = viewpoint_G_WC((0.0, 0.75, 0.55), (0.0, 0.0, 0.49))  # looks at +Y (shared)
            views[k] = {
                s: cv2.cvtColor(w.render(G, CAM, supersample=2)[0], cv2.COLOR_RGB2GRAY)
                for s, G in (("unique", G_unique), ("shared", G_shared))
            }
    for k in range(len(models)):
        own = _sift_matches(views[k]["unique"], textures[k]["+X"], sift)
        others = [
            _sift_matches(views[k]["unique"], textures[j]["+X"], sift) for j in range(len(models)) if j != k
        ]
        assert own >= 10 and own >= 3 * max(others), (k, own, others)
        assert _sift_matches(views[k]["unique"], textures[k]["-X"], sift) * 3 <= own
        # the shared side renders the same for every model, and matches the shared page
        np.testing.assert_array_equal(views[k]["shared"], views[0]["shared"])
        assert _sift_matches(views[k]["shared"], textures[k]["-X"], sift) >= 10


def test_same_scene_renders_identically_twice():
    imgs = []
    for _ in range(2):
        with SimWorld("lab_room") as w:
            r = SimRobot(w, CAM, seed=3)
            r.enable()
            r.drive(0.4, 0.2)
            r.step(1.0)
            f = r.capture_stereo()
            imgs.append((f.left, f.right, f.odom))
    np.testing.assert_array_equal(imgs[0][0], imgs[1][0])
    np.testing.assert_array_equal(imgs[0][1], imgs[1][1])
    assert imgs[0][2] == imgs[1][2]


@pytest.mark.parametrize("ss", [1, 2, 3])
def test_supersampled_render_keeps_the_intrinsics(models, ss):
    """Rendering at ss x and downsampling (INTER_AREA) keeps cx = W/2 - 0.5, cy = H/2 - 0.5: the box's
    coverage (mask averaged the same way) is centred where the intrinsics project its silhouette."""
    with SimWorld("box_database") as w:
        c = w.add_carrier(models[1], Pose2D(0.0, 0.0, 0.0), box_yaw=0.3)
        for eye in ((1.0, 0.2, 0.7), (-0.6, -0.7, 0.9)):
            G_WC = viewpoint_G_WC(eye, (0.0, 0.0, 0.49))
            _, _, seg = w.render(G_WC, CAM, want_seg=True, supersample=ss)
            mask = (seg == w.body_id("target")).astype(np.float32)
            mask = cv2.resize(mask, (CAM.width, CAM.height), interpolation=cv2.INTER_AREA)
            v, u = np.mgrid[0 : CAM.height, 0 : CAM.width]
            got = np.array([(u * mask).sum(), (v * mask).sum()]) / mask.sum()
            G_CO = se3_inv(G_WC) @ c.G_WO
            expect, _ = _silhouette_centroid(transform_points(G_CO, _box_corners_O(models[1].size)), CAM)
            assert np.linalg.norm(got - expect) < 0.25, (ss, eye, got - expect)
            rgb = w.render(G_WC, CAM, supersample=ss)[0]
            assert rgb.shape == (CAM.height, CAM.width, 3)


def test_egl_renderer_matches_the_same_intrinsics(models):
    """Optional EGL path (Mesa): where it loads, its images obey the same intrinsics (pixel centres)."""
    from lab.errors import ConfigError
    from lab.sim import RenderSettings

    try:
        w = SimWorld("box_database", RenderSettings(renderer="egl"))
    except ConfigError as e:
        pytest.skip(f"EGL unavailable here: {e}")
    with w:
        c = w.add_carrier(models[0], Pose2D(0.0, 0.0, 0.0), box_yaw=0.4)
        for eye in ((1.0, 0.1, 0.75), (-0.5, 0.8, 0.9)):
            G_WC = viewpoint_G_WC(eye, (0.05, -0.03, 0.45))
            rgb, _, seg = w.render(G_WC, CAM, want_seg=True, supersample=1)
            v, u = np.nonzero(seg == w.body_id("target"))
            G_CO = se3_inv(G_WC) @ c.G_WO
            expect, _ = _silhouette_centroid(transform_points(G_CO, _box_corners_O(models[0].size)), CAM)
            assert np.linalg.norm([u.mean() - expect[0], v.mean() - expect[1]]) < 0.25
            assert rgb[v, u].std() > 20  # the atlas texture is there, not a flat colour


def test_a_view_that_did_not_change_is_not_rendered_again(models):
    """The same camera over the same scene gives the last render's images without rendering (they equal
    a fresh world's render); moving the camera or a body renders anew."""
    G_WC = viewpoint_G_WC((1.0, 0.2, 0.7), (0.0, 0.0, 0.49))
    with SimWorld("box_database") as fresh:
        fresh.add_carrier(models[2], Pose2D(0.0, 0.0, 0.0), box_yaw=0.3)
        truth = fresh.render_stereo(G_WC, CAM)
    with SimWorld("box_database") as w:
        c = w.add_carrier(models[2], Pose2D(0.0, 0.0, 0.0), box_yaw=0.3)
        first = w.render_stereo(G_WC, CAM)
        assert (w.n_renders, w.n_renders_reused) == (2, 0)
        first[0][:] = 0  # the caller's copy: what is kept is not touched
        again = w.render_stereo(G_WC, CAM)
        assert (w.n_renders, w.n_renders_reused) == (4, 2)
        for a, b in zip(again, truth, strict=True):
            np.testing.assert_array_equal(a, b)
        moved = w.render_stereo(viewpoint_G_WC((1.0, 0.25, 0.7), (0.0, 0.0, 0.49)), CAM)
        assert w.n_renders_reused == 2 and not np.array_equal(moved[0], truth[0])
        c.set_pose(Pose2D(0.1, 0.0, 0.0))  # the box moves under a still camera
        shifted = w.render_stereo(G_WC, CAM)
        assert w.n_renders_reused == 2 and not np.array_equal(shifted[0], truth[0])
