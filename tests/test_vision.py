"""Stereo 3D SIFT features and feature databases against the simulator's ground truth and OpenCV."""

import dataclasses
import math

import cv2
import numpy as np
import pytest

from lab.errors import AssetError, ConfigError
from lab.geometry import Pose2D, Ry, se3, se3_inv, transform_points, translation
from lab.robot import StereoCamera
from lab.sim import RenderSettings, SimWorld, load_box_models, viewpoint_G_WC
from lab.training.databases import TrainingParams, get_database, get_databases, train_database
from lab.vision.database import load_database, save_database
from lab.vision.matching import Matcher, _k_smallest, _k_smallest_by_partition
from lab.vision.rectify import StereoCalibration, StereoRectifier, load_calibration
from lab.vision.stereo import (
    StereoParams,
    _epipolar_matches,
    _epipolar_matches_dense,
    deblurred,
    sift,
    stereo_features,
    triangulate,
    upsampled_pair,
)

CAM = StereoCamera.from_fov(320, 240, 60.0, 0.12)
RING = [(math.cos(a), math.sin(a)) for a in np.linspace(0, 2 * np.pi, 8, endpoint=False)]


@pytest.fixture(scope="module")
def models():
    return load_box_models()


@pytest.fixture(scope="module")
def dbs():
    names = ("M0", "M1", "M2", "M3")
    return dict(zip(names, get_databases(names, progress=False), strict=True))


def _bilinear(img, uv):
    x0, y0 = np.floor(uv[:, 0]).astype(int), np.floor(uv[:, 1]).astype(int)
    ax, ay = uv[:, 0] - x0, uv[:, 1] - y0
    return (
        img[y0, x0] * (1 - ax) * (1 - ay)
        + img[y0, x0 + 1] * ax * (1 - ay)
        + img[y0 + 1, x0] * (1 - ax) * ay
        + img[y0 + 1, x0 + 1] * ax * ay
    )


def _errors_against_depth(models, supersample):
    """3D errors [m] of triangulated box features against the depth buffer, and Mahalanobis distances."""
    errs, maha = [], []
    for k, m in enumerate(models):
        with SimWorld("box_database", RenderSettings(supersample=supersample)) as w:
            w.add_carrier(m, Pose2D(0, 0, 0), box_yaw=0.3 * k)
            for cx, cy in RING:
                G_WC = viewpoint_G_WC((cx, cy, 0.7), (0, 0, 0.49))
                f = stereo_features(*w.render_stereo(G_WC, CAM), CAM)
                depth = w.truth.depth(G_WC, CAM)
                box = w.truth.segmentation(G_WC, CAM) == w.body_id("target")
                inner = cv2.erode(box.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
                u = np.round(f.uv).astype(int)
                sel = inner[u[:, 1], u[:, 0]]
                z = _bilinear(depth, f.uv[sel])
                uv = f.uv[sel]
                p_true = np.stack([(uv[:, 0] - CAM.cx) * z / CAM.fx, (uv[:, 1] - CAM.cy) * z / CAM.fy, z], 1)
                e = f.points_C[sel] - p_true
                errs.append(np.linalg.norm(e, axis=1))
                maha.append(np.einsum("ni,nij,nj->n", e, np.linalg.inv(f.covariances[sel]), e))
    return np.concatenate(errs), np.concatenate(maha)


def test_triangulated_features_within_10mm_at_1m(models):
    e1, m1 = _errors_against_depth(models, 1)
    assert len(e1) > 300
    print(
        f"\n1x: n={len(e1)} median {np.median(e1) * 1e3:.1f} mm p90 {np.percentile(e1, 90) * 1e3:.1f} mm "
        f"inside 95% ellipsoid {np.mean(m1 < 7.815):.2f}"
    )
    assert np.median(e1) <= 0.010
    # the error model is consistent: most errors fall inside the 95% ellipsoid (outliers are mismatches)
    assert 0.85 <= np.mean(m1 < 7.815) <= 0.99
    e2, m2 = _errors_against_depth(models, 2)
    print(
        f"2x: n={len(e2)} median {np.median(e2) * 1e3:.1f} mm p90 {np.percentile(e2, 90) * 1e3:.1f} mm "
        f"inside 95% ellipsoid {np.mean(m2 < 7.815):.2f}"
    )
    assert np.median(e2) < np.median(e1)  # supersampling helps, as measured before the project


def test_right_image_in_a_second_thread_gives_the_same_features():
    with SimWorld("box_database") as w:
        w.add_carrier(load_box_models()[2], Pose2D(0, 0, 0), box_yaw=0.3)
        pair = w.render_stereo(viewpoint_G_WC((0.9, 0.3, 0.7), (0, 0, 0.49)), CAM)
    a = stereo_features(*pair, CAM, StereoParams(parallel=True))
    b = stereo_features(*pair, CAM, StereoParams(parallel=False))
    assert len(a) > 50
    for x, y in ((a.points_C, b.points_C), (a.descriptors, b.descriptors), (a.uv, b.uv)):
        np.testing.assert_array_equal(x, y)


def test_epipolar_matching_over_the_allowed_pairs_is_the_dense_matrix_s():
    """The sparse epipolar matcher (allowed pairs only) returns the dense distance matrix's matches,
    index for index: on rendered pairs, with the camera noise of the realistic profile, and on
    synthetic keypoints made of ties (rows shared by many keypoints, descriptors of 0..3)."""
    from lab.sim.sensing import corrupt_stereo, sensing_profile

    errors = sensing_profile("realistic").camera

    params, det = StereoParams(), sift()
    rng = np.random.default_rng(0)
    n_matches = 0
    with SimWorld("box_database") as w:
        w.add_carrier(load_box_models()[0], Pose2D(0, 0, 0), box_yaw=0.2)
        for cx, cy in RING[::2]:
            left, right = w.render_stereo(viewpoint_G_WC((cx, cy, 0.7), (0, 0, 0.49)), CAM)
            for noisy in (False, True):
                if noisy:
                    draw = errors.draw(rng, CAM, (0.3, 0.2, -1.0))
                    left, right = corrupt_stereo(left, right, errors, draw, rng)
                kl, dl = det.detectAndCompute(cv2.cvtColor(left, cv2.COLOR_RGB2GRAY), None)
                kr, dr = det.detectAndCompute(cv2.cvtColor(right, cv2.COLOR_RGB2GRAY), None)
                a = _epipolar_matches(kl, dl, kr, dr, params)
                b = _epipolar_matches_dense(kl, dl, kr, dr, params)
                np.testing.assert_array_equal(a[0], b[0])
                np.testing.assert_array_equal(a[1], b[1])
                n_matches += len(a[0])
    assert n_matches > 500
    n_synthetic = 0
    for _ in range(20):
        n_l, n_r = rng.integers(1, 60, 2)
        kl = [cv2.KeyPoint(float(rng.uniform(0, 320)), float(rng.integers(0, 6)), 3.0) for _ in range(n_l)]
        kr = [
            cv2.KeyPoint(
                float(rng.uniform(0, 320)), float(rng.integers(0, 6)) + rng.choice([0, 0.5, 1.5, 2]), 3.0
            )
            for _ in range(n_r)
        ]
        dl = rng.integers(0, 4, (n_l, 128)).astype(np.float32)
        dr = rng.integers(0, 4, (n_r, 128)).astype(np.float32)
        for p in (params, StereoParams(ratio=1.0)):
            a, b = _epipolar_matches(kl, dl, kr, dr, p), _epipolar_matches_dense(kl, dl, kr, dr, p)
            np.testing.assert_array_equal(a[0], b[0])
            np.testing.assert_array_equal(a[1], b[1])
            n_synthetic += len(a[0])
    assert n_synthetic > 20
    # descriptors that are not small integers take the dense path
    a = _epipolar_matches(kl, dl + 0.25, kr, dr, params)
    b = _epipolar_matches_dense(kl, dl + 0.25, kr, dr, params)
    np.testing.assert_array_equal(a[0], b[0])


def test_triangulation_agrees_with_opencv():
    rng = np.random.default_rng(0)
    uv_l = rng.uniform([20, 20], [300, 220], (50, 2))
    d = rng.uniform(5, 60, 50)
    uv_r = uv_l - np.c_[d, np.zeros(50)]
    P1 = CAM.K @ np.c_[np.eye(3), np.zeros(3)]
    P2 = CAM.K @ np.c_[np.eye(3), [-CAM.baseline, 0, 0]]
    X = cv2.triangulatePoints(P1, P2, uv_l.T, uv_r.T)
    np.testing.assert_allclose(triangulate(uv_l, uv_r, CAM), (X[:3] / X[3]).T, rtol=1e-9, atol=1e-9)


def test_unique_face_matches_its_model_5x_more_and_shared_faces_match_all(models, dbs):
    matchers = {k: Matcher(db) for k, db in dbs.items()}
    for k, m in enumerate(models):
        with SimWorld("box_database") as w:
            w.add_carrier(m, Pose2D(0, 0, 0), box_yaw=0.2)
            for dist, height in ((1.0, 0.7), (0.8, 0.65)):
                eye = (dist * math.cos(0.2), dist * math.sin(0.2), height)  # frontal to the unique face (+X)
                f = stereo_features(*w.render_stereo(viewpoint_G_WC(eye, (0, 0, 0.49)), CAM), CAM)
                n = {j: mt.match(f).n_matched for j, mt in matchers.items()}
                own = n[m.name]
                assert own >= 12 and own >= 5 * max(1, max(v for j, v in n.items() if j != m.name)), (
                    k,
                    dist,
                    n,
                )
            shared_eye = (-math.cos(0.2), -math.sin(0.2), 0.7)  # the -X face: shared
            f = stereo_features(*w.render_stereo(viewpoint_G_WC(shared_eye, (0, 0, 0.49)), CAM), CAM)
            n = [mt.match(f).n_matched for mt in matchers.values()]
            assert min(n) >= 5 and max(n) <= 2 * min(n), n


def test_matcher_flann_agrees_with_exact_search(dbs):
    db = dbs["M1"]
    with SimWorld("box_database") as w:
        w.add_carrier(load_box_models()[1], Pose2D(0, 0, 0))
        f = stereo_features(*w.render_stereo(viewpoint_G_WC((0.9, 0.3, 0.7), (0, 0, 0.49)), CAM), CAM)
    a, b = Matcher(db, method="flann").match(f), Matcher(db, method="brute").match(f)
    sa = set(zip(a.idx_meas, a.idx_db, strict=True))
    sb = set(zip(b.idx_meas, b.idx_db, strict=True))
    assert len(sa & sb) >= 0.9 * len(sb)  # approximate search finds nearly all exact matches
    # OpenCV's own brute-force matcher agrees with our nearest neighbours
    nn = cv2.BFMatcher(cv2.NORM_L2).match(f.descriptors, db.descriptors)
    idx, _ = Matcher(db, method="brute").neighbours(f.descriptors)
    agree = np.mean([m.trainIdx == idx[m.queryIdx, 0] for m in nn])
    assert agree > 0.99
    # and FLANN repeats itself exactly
    c = Matcher(db, method="flann").match(f)
    np.testing.assert_array_equal(a.idx_db, c.idx_db)
    # a search made elsewhere (the model probabilities') is reused as is: exact neighbours give the
    # exact matcher's matches, whatever the matcher's own method
    d = Matcher(db, method="flann").match(f, neighbours=Matcher(db, method="brute").neighbours(f.descriptors))
    for x, y in ((b.idx_meas, d.idx_meas), (b.idx_db, d.idx_db), (b.distance, d.distance)):
        np.testing.assert_array_equal(x, y)
    with pytest.raises(ConfigError, match="neighbours must be two"):
        Matcher(db).match(f, neighbours=(idx[:, :3], idx[:, :3].astype(float)))


def test_exact_search_is_the_argpartition_search_bit_for_bit(dbs):
    """The k nearest by repeated argmin (ties re-done by argpartition) equal the argpartition search,
    indices and distances, and the alias table the direct alias test, on real frames against every
    database (ties common: databases store some descriptors twice and squared distances of SIFT's
    integer descriptors are integers), and on a synthetic matrix made of ties; their values are the
    dense sort's."""
    with SimWorld("box_database") as w:
        w.add_carrier(load_box_models()[2], Pose2D(0, 0, 0), box_yaw=0.5)
        frames = [
            stereo_features(*w.render_stereo(viewpoint_G_WC((c, s, 0.7), (0, 0, 0.49)), CAM), CAM)
            for c, s in RING[::3]
        ]
    n_ties = 0
    for f in frames:
        q = f.descriptors.astype(np.float32)
        for db in dbs.values():
            m = Matcher(db, method="brute", k=8)
            d2 = np.einsum("ij,ij->i", q, q)[:, None] + m._D_sq[None, :] - 2.0 * q @ m._D.T
            a, b = _k_smallest(d2, 8), _k_smallest_by_partition(d2, k=8)
            np.testing.assert_array_equal(a[0], b[0])
            np.testing.assert_array_equal(a[1], b[1])
            np.testing.assert_array_equal(a[1], np.sort(d2, axis=1)[:, :8])  # a dense peer
            s = np.sort(d2, axis=1)[:, :9]
            n_ties += int(np.count_nonzero((s[:, 1:] == s[:, :-1]).any(axis=1)))
            # the alias table (one matrix product) is the direct descriptor distance, pair for pair
            direct = np.linalg.norm(m._D[a[0]] - m._D[a[0][:, :1]], axis=2) < m.alias_distance
            np.testing.assert_array_equal(m._aliases(a[0]), direct)
            chunked = Matcher(db, method="brute", k=8)
            chunked._D = chunked._D + np.float32(0.25)  # not integers: the table by the direct expression
            direct = np.linalg.norm(chunked._D[a[0]] - chunked._D[a[0][:, :1]], axis=2) < m.alias_distance
            np.testing.assert_array_equal(chunked._aliases(a[0]), direct)
    assert n_ties > 10  # the tie path was exercised
    rng = np.random.default_rng(0)
    d2 = rng.integers(0, 6, (200, 50)).astype(np.float32)  # nearly every row has ties
    for k in (1, 3, 8, 49):
        a, b = _k_smallest(d2, k), _k_smallest_by_partition(d2, k=k)
        np.testing.assert_array_equal(a[0], b[0])
        np.testing.assert_array_equal(a[1], b[1])
    d2 = rng.permutation(200 * 50).reshape(200, 50).astype(float)  # no ties: the argmin path alone
    a, b = _k_smallest(d2, 8), _k_smallest_by_partition(d2, k=8)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[0], np.argsort(d2, axis=1)[:, :8])


def test_training_is_deterministic_and_remembers_visibility(dbs):
    params = TrainingParams(step_deg=30.0)
    a, b = train_database("M2", params), train_database("M2", params)
    assert a.digest() == b.digest()
    assert a.seen_from.shape == (len(a), 12) and a.seen_from.any(axis=1).all()
    # a feature on the +X face is seen from azimuths near 0, never from behind (azimuth 180 deg)
    db = dbs["M2"]
    front = db.points_O[:, 0] > 0.13
    az = np.degrees(db.viewpoints[:, 0])
    behind = (az > 120) & (az < 240)
    assert front.sum() > 20 and not db.seen_from[np.ix_(front, behind)].any()


def test_cache_is_versioned_atomic_and_detects_corruption(tmp_path, dbs):
    db = dbs["M3"]
    p = tmp_path / "M3.npz"
    save_database(db, p)
    assert load_database(p).digest() == db.digest()
    raw = bytearray(p.read_bytes())
    raw[len(raw) // 2] ^= 0xFF
    p.write_bytes(bytes(raw))
    with pytest.raises(AssetError, match="corrupt"):
        load_database(p)
    with pytest.raises(AssetError, match="does not exist"):
        load_database(tmp_path / "none.npz")
    with pytest.raises(ConfigError, match="unknown object 'M9'; trainable objects: M0, M1, M2, M3"):
        get_database("M9")
    # a corrupt cache entry is rebuilt, and says so
    folder = tmp_path / "cache"
    from lab.training.databases import database_path

    q = database_path("M3", folder)
    q.parent.mkdir(parents=True)
    q.write_bytes(b"not a database")
    params = TrainingParams(step_deg=60.0)
    got = get_database("M3", folder, params, progress=False)
    assert load_database(q).digest() == got.digest()
    # a warm cache is read without a lock (no write access needed): no lock file beside it
    q.with_name(f"{q.name}.lock").unlink(missing_ok=True)  # left by the build (it holds nothing)
    assert get_database("M3", folder, params, progress=False).digest() == got.digest()
    assert get_databases(["M3"], folder, params, progress=False)[0].digest() == got.digest()
    assert sorted(p.name for p in q.parent.iterdir()) == ["M3.npz"]


def _distort(ideal, K_ideal, K_raw, D, size):
    """The raw image a distorting camera (K_raw, D) sees, resampled from an ideal pinhole render."""
    w, h = size
    u, v = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    pts = np.stack([u.ravel(), v.ravel()], 1).reshape(-1, 1, 2)
    n = cv2.undistortPoints(pts, K_raw, D).reshape(-1, 2)
    mx = (K_ideal[0, 0] * n[:, 0] + K_ideal[0, 2]).reshape(h, w).astype(np.float32)
    my = (K_ideal[1, 1] * n[:, 1] + K_ideal[1, 2]).reshape(h, w).astype(np.float32)
    return cv2.remap(ideal, mx, my, cv2.INTER_LINEAR)


def _surface_distance(p_O, size):
    half = 0.5 * np.asarray(size)
    return np.min(np.abs(np.abs(p_O) - half), axis=1)


def test_real_camera_style_input_gives_the_same_accuracy(models, tmp_path):
    """Render distorted raw images with a slightly rotated right camera, store a calibration file,
    rectify, and measure the distance of triangulated features to the true box surface."""
    K_raw = np.array([[215.0, 0, 161.3], [0, 213.0, 118.2], [0, 0, 1]])
    D = np.array([-0.18, 0.05, 0.0008, -0.0006, 0.0])
    R_LR = Ry(math.radians(0.8))  # right camera slightly toed in
    t_LR = np.array([0.12, 0.001, -0.0015])
    calib = StereoCalibration.from_intrinsics(K_raw, D, K_raw, D, R_LR.T, -R_LR.T @ t_LR, (320, 240))
    path = tmp_path / "stereo.yaml"
    calib.save(path)
    loaded = load_calibration(path, expected_size=(320, 240))
    rect, rect_cam = StereoRectifier(loaded), loaded.camera_model()
    wide = StereoCamera.from_fov(640, 480, 80.0, 0.12)  # the ideal render covers the raw field of view
    direct, via_raw = [], []
    m = models[0]
    with SimWorld("box_database", RenderSettings(supersample=1)) as w:
        c = w.add_carrier(m, Pose2D(0, 0, 0), box_yaw=0.5)
        for cx, cy in RING[:5]:
            G_WL = viewpoint_G_WC((cx, cy, 0.7), (0, 0, 0.49))
            G_WR = G_WL @ se3(R_LR, t_LR)
            raw_l = _distort(w.render(G_WL, wide)[0], wide.K, K_raw, D, (320, 240))
            raw_r = _distort(w.render(G_WR, wide)[0], wide.K, K_raw, D, (320, 240))
            left, right = rect.rectify(raw_l, raw_r)
            f = stereo_features(left, right, rect_cam)
            G_W_rect = G_WL @ se3(loaded.R1.T)  # the rectified left frame is the raw one turned by R1
            p_O = transform_points(se3_inv(c.G_WO) @ G_W_rect, f.points_C)
            via_raw.append(_surface_distance(p_O[np.all(np.abs(p_O) < 0.16, 1)], m.size))
            f0 = stereo_features(*w.render_stereo(G_WL, CAM), CAM)
            p_O = transform_points(se3_inv(c.G_WO) @ G_WL, f0.points_C)
            direct.append(_surface_distance(p_O[np.all(np.abs(p_O) < 0.16, 1)], m.size))
    d_direct, d_raw = np.median(np.concatenate(direct)), np.median(np.concatenate(via_raw))
    print(f"\nsurface distance median: rendered {d_direct * 1e3:.2f} mm, rectified raw {d_raw * 1e3:.2f} mm")
    assert abs(rect_cam.baseline - 0.12) < 0.003
    assert d_raw <= 1.2 * d_direct + 1e-4
    with pytest.raises(ConfigError, match="calibration is for 320x240"):
        rect.rectify(np.zeros((480, 640, 3), np.uint8), np.zeros((480, 640, 3), np.uint8))
    with pytest.raises(ConfigError, match="not found"):
        load_calibration(tmp_path / "missing.yaml")
    with pytest.raises(ConfigError, match="is for 320x240 images but the camera delivers 640x480"):
        load_calibration(path, expected_size=(640, 480))


def test_bad_inputs_are_refused_clearly():
    img = np.zeros((240, 320, 3), np.uint8)
    with pytest.raises(ConfigError, match="differ in shape"):
        stereo_features(img, img[:100], CAM)
    with pytest.raises(ConfigError, match="camera model is 320x240"):
        stereo_features(np.zeros((100, 100), np.uint8), np.zeros((100, 100), np.uint8), CAM)
    assert len(stereo_features(img, img, CAM)) == 0  # a blank pair has no features, not an error
    with pytest.raises(ConfigError, match="ratio"):
        StereoParams(ratio=1.5)
    with pytest.raises(ConfigError, match="step_deg must divide 360"):
        TrainingParams(step_deg=7.0)


_ = translation


def test_matcher_on_a_tiny_database_does_not_crash():
    """FLANN fails on indexes about as small as k; small databases fall back to exact search."""
    from dataclasses import replace

    from lab.vision.stereo import Features3D

    rng = np.random.default_rng(0)
    D = (rng.random((7, 128)) * 100).astype(np.float32)
    db = train_database("M0", TrainingParams(step_deg=90.0))
    tiny = replace(db, points_O=db.points_O[:7], descriptors=D, seen_from=db.seen_from[:7])
    q = np.vstack([D[:3] + 1.0, (rng.random((5, 128)) * 100).astype(np.float32)])
    f = Features3D(np.zeros((8, 3)), q, np.zeros((8, 2)), np.ones(8), np.tile(np.eye(3), (8, 1, 1)))
    m = Matcher(tiny)
    assert m.method == "brute"
    c = m.match(f)
    assert {(i, j) for i, j in zip(c.idx_meas, c.idx_db, strict=True) if i < 3} == {(0, 0), (1, 1), (2, 2)}


def test_spatial_aliases_keep_one_point_seen_from_two_views():
    """Two database features at one place in O (one physical point seen from two training rings,
    descriptors too far apart to merge) are aliases with ``alias_radius``: the ratio test compares the
    nearest with a feature elsewhere, and the point matches; without it the pair rejects itself.
    Exact search, so the check is against plain arithmetic."""
    from dataclasses import replace

    from lab.vision.stereo import Features3D

    rng = np.random.default_rng(1)
    n = 40
    D = (rng.random((n, 128)) * 100).astype(np.float32)
    P = rng.uniform(-0.1, 0.1, (n, 3))
    D[1] = D[0] + 15.0  # the same point from another ring: descriptor 150 away (> alias_distance)
    P[1] = P[0] + 0.004  # 4 mm apart in O
    db = train_database("M0", TrainingParams(step_deg=90.0))
    small = replace(db, points_O=P, descriptors=D, seen_from=db.seen_from[:n])
    q = D[:1] + 6.5  # the point seen from between the two views: D[0] nearest, D[1] at ratio 0.76
    f = Features3D(np.zeros((1, 3)), q, np.zeros((1, 2)), np.ones(1), np.eye(3)[None])
    assert np.linalg.norm(D[1] - D[0]) > 120.0
    assert Matcher(small, method="brute").match(f).n_matched == 0
    c = Matcher(small, method="brute", alias_radius=0.015).match(f)
    assert c.n_matched == 1 and set(c.idx_db.tolist()) == {0, 1}
    # a feature elsewhere with a close descriptor still makes the match ambiguous
    P2 = P.copy()
    P2[1] = P[0] + 0.05
    far = replace(small, points_O=P2)
    assert Matcher(far, method="brute", alias_radius=0.015).match(f).n_matched == 0
    with pytest.raises(ConfigError, match="alias_radius"):
        Matcher(small, alias_radius=-1.0)


def test_one_index_over_all_models_gives_each_models_own_exact_search_bit_for_bit(dbs):
    """The joint index stores the shared faces' descriptors once, knows which models hold each, and
    gives every model the neighbours (indices, distances, order among equal distances) of its own brute
    search, on real frames (full and region-restricted) and on descriptors that are not integers."""
    from lab.vision import JointIndex

    models = list(dbs.values())
    index = JointIndex(models, k=8)
    total = sum(len(db) for db in models)
    assert index.exact and len(index) < 0.7 * total  # the shared faces once
    np.testing.assert_array_equal(index.members.sum(axis=0), [len(np.unique(c)) for c in index.columns])
    for i, db in enumerate(models):
        np.testing.assert_array_equal(index.descriptors[index.columns[i]], db.descriptors)
    with SimWorld("box_database") as w:
        w.add_carrier(load_box_models()[1], Pose2D(0, 0, 0), box_yaw=0.3)
        frames = [
            stereo_features(*w.render_stereo(viewpoint_G_WC((c, s, 0.7), (0, 0, 0.49)), CAM), CAM)
            for c, s in RING[::2]
        ]
    queries = [f.descriptors for f in frames] + [frames[0].descriptors + np.float32(0.25)]
    for q in queries:
        joint = index.neighbours(q)
        assert index.neighbours(q) is joint  # kept for the other models
        for db, (idx, dist) in zip(models, joint, strict=True):
            own_idx, own_dist = Matcher(db, method="brute", k=8).neighbours(q)
            np.testing.assert_array_equal(idx, own_idx)
            np.testing.assert_array_equal(dist, own_dist)


# --- sharpening by the camera's blur ----------------------------------------------------------------
def test_deblurred_is_twice_the_image_minus_its_blur_as_scipy_computes_it():
    from scipy.ndimage import gaussian_filter

    img = cv2.resize(np.random.default_rng(0).integers(0, 256, (60, 80)).astype(np.uint8), (320, 240))
    for s in (0.5, 0.87, 1.5):
        peer = np.clip(np.rint(2.0 * img - gaussian_filter(img.astype(float), s, mode="mirror")), 0, 255)
        diff = np.abs(deblurred(img, s).astype(float) - peer)[8:-8, 8:-8]  # away from the border
        assert diff.max() <= 2 and diff.mean() < 0.3, (s, diff.max(), diff.mean())
    assert deblurred(img, 0.0) is img


def test_deblurred_takes_a_gaussian_blur_back_to_the_sharp_image():
    """On a band-limited texture (where the first order holds), blurred and rounded to grey levels: the
    unsharp mask of the blur's own size brings the image to within a third of the blur's error, nearer
    than one of half or twice the size."""
    n = cv2.GaussianBlur(np.random.default_rng(0).standard_normal((240, 320)).astype(np.float32), (0, 0), 2.0)
    sharp = np.clip(128.0 + 40.0 * n / n.std(), 0, 255)
    for s in (0.7, 1.0):
        blurred = np.rint(cv2.GaussianBlur(sharp, (0, 0), s)).astype(np.uint8)

        def rms(a):
            return float(np.sqrt(np.mean((a.astype(float) - sharp)[8:-8, 8:-8] ** 2)))

        e = rms(deblurred(blurred, s))
        assert e < rms(blurred) / 3 and e < min(
            rms(deblurred(blurred, s / 2)), rms(deblurred(blurred, 2 * s))
        )


def test_a_camera_stating_its_blur_matches_a_blurred_box_better_and_a_sharp_one_the_same(models, dbs):
    """Boxes 1.2 m away under scale 2's camera errors (1 px of blur, 4 grey levels of noise): stating
    the blur gives at least 1.3 x the right database matches (right: the matched model point, placed by
    the true pose, within 4 sd of the measured point), unless ``sharpen`` is off. Under scale 1's (0.5 px,
    what SIFT assumes) the stated blur changes no feature."""
    from lab.sim.sensing import corrupt_stereo, sensing_profile

    def right(f, mt, db, G_CO):
        c = mt.match(f)
        d_C, b_O, S = c.pairs(f, db)
        e = transform_points(G_CO, b_O) - d_C
        return len(set(c.idx_meas[np.einsum("ni,nij,nj->n", e, np.linalg.inv(S), e) < 16.0]))

    def f1_camera(errors):
        return dataclasses.replace(CAM, blur_sigma_px=errors.blur_sigma_px)

    for scale in (2, 1):
        errors = sensing_profile("realistic").scaled(scale).camera
        rng = np.random.default_rng(0)
        n = [0, 0]
        for m in models:
            mt = Matcher(dbs[m.name])
            with SimWorld("box_database") as w:
                w.add_carrier(m, Pose2D(0, 0, 0), box_yaw=0.2)
                G_WO = w.truth.G_W("target")
                for az in (0.2, 1.8):
                    G_WC = viewpoint_G_WC((1.2 * math.cos(az), 1.2 * math.sin(az), 0.9), (0, 0, 0.49))
                    draw = errors.draw(rng, CAM, (0.3, 0.2, 1.0))
                    pair = corrupt_stereo(*w.render_stereo(G_WC, CAM), errors, draw, rng)
                    f0 = stereo_features(*pair, CAM)
                    f1 = stereo_features(*pair, f1_camera(errors))
                    n[0] += right(f0, mt, dbs[m.name], se3_inv(G_WC) @ G_WO)
                    n[1] += right(f1, mt, dbs[m.name], se3_inv(G_WC) @ G_WO)
                    if scale == 1:
                        np.testing.assert_array_equal(f0.points_C, f1.points_C)
                    else:  # the identification's settings: the blur stated, nothing sharpened
                        no = stereo_features(*pair, f1_camera(errors), StereoParams(sharpen=False))
                        np.testing.assert_array_equal(f0.points_C, no.points_C)
        print(f"\nscale {scale}: right matches {n[0]} without the stated blur, {n[1]} with it")
        assert n[1] >= 1.3 * n[0] if scale == 2 else n[1] == n[0]


def test_an_enlarged_pair_keeps_the_original_images_sharpening():
    cam = dataclasses.replace(CAM, blur_sigma_px=1.0)
    img = np.zeros((CAM.height, CAM.width), np.uint8)
    _, _, cam2, par2 = upsampled_pair(img, img, cam, 2)
    assert (cam2.blur_sigma_px, par2.sift_blur_px) == (2.0, 1.0)  # the excess: 2 x sqrt(1 - 0.25) px
    with pytest.raises(ConfigError, match="sift_blur_px"):
        StereoParams(sift_blur_px=-0.1)
