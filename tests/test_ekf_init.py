"""RANSAC initialisation from 3D-3D matches: closed-form fit against SciPy, outliers, bad input."""

import numpy as np
import pytest
from ekf_scenarios import CAMERA, cube, observe, random_pose_in_view
from scipy.spatial.transform import Rotation

from lab.estimation import RansacConfig, fit_rigid_transform, ransac_pose, state_residual
from lab.estimation.synthetic import stereo_covariance
from lab.geometry import pose6_to_G


def test_closed_form_fit_matches_scipy_align_vectors():
    """Kabsch without scale against SciPy's Wahba solver (an independent implementation)."""
    rng = np.random.default_rng(0)
    for _ in range(20):
        b = rng.uniform(-0.2, 0.2, (12, 3))
        R_true = Rotation.random(random_state=rng).as_matrix()
        d = b @ R_true.T + rng.normal(0, 1, 3) + rng.normal(0, 0.01, (12, 3))
        w = rng.uniform(0.5, 2.0, 12)
        R, t = fit_rigid_transform(b, d, w)
        # SciPy aligns centred vectors: the same weighted least-squares rotation
        bc = b - np.average(b, axis=0, weights=w)
        dc = d - np.average(d, axis=0, weights=w)
        R_sp, _ = Rotation.align_vectors(dc, bc, weights=w)
        np.testing.assert_allclose(R, R_sp.as_matrix(), atol=1e-10)
        np.testing.assert_allclose(t, np.average(d, axis=0, weights=w) - R @ np.average(b, axis=0, weights=w))
        assert np.linalg.det(R) == pytest.approx(1.0)


def test_closed_form_fit_is_exact_without_noise_and_never_reflects():
    rng = np.random.default_rng(1)
    b = rng.uniform(-0.2, 0.2, (5, 3))
    G = pose6_to_G([0.1, -0.2, 1.0, 2.5, -0.3, 1.0])
    R, t = fit_rigid_transform(b, b @ G[:3, :3].T + G[:3, 3])
    np.testing.assert_allclose(R, G[:3, :3], atol=1e-12)
    np.testing.assert_allclose(t, G[:3, 3], atol=1e-12)
    # mirrored data: the best proper rotation, not the reflection
    R, _ = fit_rigid_transform(b, b * [1, 1, -1])
    assert np.linalg.det(R) == pytest.approx(1.0)


@pytest.mark.parametrize("outlier_frac", [0.0, 0.2, 0.4])
def test_ransac_finds_the_pose_and_the_wrong_matches(outlier_frac):
    errs_t, errs_r, recall, precision = [], [], [], []
    for s in range(12):
        rng = np.random.default_rng(100 + s)
        b_O, nrm = cube(rng)
        X = random_pose_in_view(rng)
        f = observe(rng, X, b_O, nrm, outlier_frac=outlier_frac)
        res = ransac_pose(f.d_C, f.b_O, f.Sigma_d, rng)
        assert res.success, res.reason
        e = state_residual(res.mu, X)
        errs_t.append(np.linalg.norm(e[:3]))
        R_err = Rotation.from_matrix(pose6_to_G(res.mu)[:3, :3].T @ pose6_to_G(X)[:3, :3])
        errs_r.append(np.degrees(R_err.magnitude()))
        good = ~f.wrong
        recall.append(np.mean(res.inliers[good]))
        if f.wrong.any():
            precision.append(np.mean(~res.inliers[f.wrong]))
        # the initial covariance is SPD and covers the error (NEES well inside chi-square(6) 99.9%)
        L = np.linalg.cholesky(res.Sigma)
        assert np.sum(np.linalg.solve(L, e) ** 2) < 22.5
    print(
        f"outliers {outlier_frac:.0%}: max translation error {max(errs_t) * 100:.2f} cm, "
        f"max rotation error {max(errs_r):.2f} deg, good kept {np.mean(recall):.2f}, "
        f"wrong rejected {np.mean(precision) if precision else float('nan'):.2f}"
    )
    assert max(errs_t) < 0.02 and max(errs_r) < 3.0
    assert np.mean(recall) > 0.9
    if precision:
        assert np.mean(precision) > 0.6  # wrong matches landing near the true point cannot be told apart


def test_ransac_is_deterministic_for_a_seed():
    rng = np.random.default_rng(7)
    b_O, nrm = cube(rng)
    f = observe(rng, random_pose_in_view(rng), b_O, nrm, outlier_frac=0.3)
    a = ransac_pose(f.d_C, f.b_O, f.Sigma_d, np.random.default_rng(42))
    b = ransac_pose(f.d_C, f.b_O, f.Sigma_d, np.random.default_rng(42))
    assert a.mu.tobytes() == b.mu.tobytes() and a.Sigma.tobytes() == b.Sigma.tobytes()
    np.testing.assert_array_equal(a.inliers, b.inliers)


def _points(n, rng):
    X = np.array([0.0, 0.0, 1.0, 0.3, 0.2, 0.1])
    b = rng.uniform(-0.14, 0.14, (n, 3))
    d = b @ pose6_to_G(X)[:3, :3].T + X[:3]
    return d, b, stereo_covariance(d, CAMERA.fx, CAMERA.baseline)


def test_ransac_bad_input_fails_with_a_reason():
    rng = np.random.default_rng(3)
    d, b, S = _points(10, rng)
    r = ransac_pose(d[:3], b[:3], S[:3], rng)  # fewer than the configured minimum (4)
    assert not r.success and "too few" in r.reason and not r.inliers.any()
    assert ransac_pose(d[:3], b[:3], S[:3], rng, RansacConfig(min_matches=3)).success
    d_nan = d.copy()
    d_nan[:7] = np.nan
    r = ransac_pose(d_nan, b, S, rng)
    assert not r.success and "too few valid" in r.reason
    line = np.outer(np.linspace(-0.1, 0.1, 10), [1.0, 0.5, 0.2])  # collinear model points
    r = ransac_pose(line + [0, 0, 1], line, S, rng)
    assert not r.success and "degenerate" in r.reason
    r = ransac_pose(np.tile([0, 0, 1.0], (10, 1)), np.zeros((10, 3)), S, rng)  # coincident
    assert not r.success and "degenerate" in r.reason
    with pytest.raises(ValueError, match="Sigma_d"):
        ransac_pose(d, b, S[:, :2], rng)
    with pytest.raises(ValueError, match="b_O"):
        ransac_pose(d, b[:5], S, rng)
