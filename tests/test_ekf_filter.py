"""The filter's algebra against independent peers: filterpy's ExtendedKalmanFilter, a dense textbook
update, SciPy's multivariate normal for Eq. (9); covariance properties with hypothesis; the bank."""

import math

import numpy as np
import pytest
from ekf_scenarios import CAMERA, cube, moving_run, observe
from filterpy.kalman import ExtendedKalmanFilter
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import chi2, multivariate_normal

from lab.errors import ConfigError
from lab.estimation import (
    CalibrationUncertainty,
    EKFBank,
    EKFConfig,
    GateConfig,
    ModelUncertainty,
    OrientationChart,
    PoseEKF,
    UpdateOutcome,
    data_log_likelihood,
    gate_matches,
    measurement_covariance,
    measurement_jacobian,
    measurement_model,
    model_offset_covariance,
    motion_jacobian,
    motion_model,
    process_noise_covariance,
    state_residual,
)
from lab.estimation.synthetic import stereo_covariance

NO_GATE = EKFConfig(gate=GateConfig(dist_max_m=np.inf, gate_prob=None))


class FilterpyEKFWithOurMotion(ExtendedKalmanFilter):
    """filterpy's EKF predicts x = F x; the documented way to use a nonlinear f is to override
    predict_x. u carries (G_RC_prev, G_RC, G_odom)."""

    def predict_x(self, u=0):
        self.x = motion_model(self.x[:, 0], *u)[:, None]


def test_matches_filterpy_extended_kalman_filter_over_25_steps():
    """Same F, Q, HJacobian, Hx, R: same state, covariance and log-likelihood to 1e-9 at every step.

    filterpy's EKF.update is Joseph form (P = (I-KH)P(I-KH)' + KRK', checked in its source), with a
    dense 3n x 3n S and an explicit inverse; ours never forms S. Angles are compared on the circle.
    """
    rng = np.random.default_rng(3)
    b_O, nrm = cube(rng)
    run = moving_run(rng, n_steps=26)
    ekf = PoseEKF(NO_GATE, rng=rng)
    mu0 = run.X_true[0] + np.array([0.01, -0.01, 0.02, 0.02, -0.02, 0.01])
    Sigma0 = np.diag([0.02] * 3 + [0.05] * 3) ** 2
    ekf.initialize(mu0, Sigma0)
    fp = FilterpyEKFWithOurMotion(dim_x=6, dim_z=3)
    fp.x, fp.P = mu0[:, None].copy(), Sigma0.copy()

    def HJacobian(x, b):
        return measurement_jacobian(x[:, 0], b)

    def Hx(x, b):
        return measurement_model(x[:, 0], b).reshape(-1, 1)

    for k in range(1, len(run.X_true)):
        u = (run.G_RC[k - 1], run.G_RC[k], run.G_odom[k - 1])
        fp.F = motion_jacobian(fp.x[:, 0], *u)
        fp.Q = process_noise_covariance(
            motion_model(fp.x[:, 0], *u), run.G_RC[k], u[2], run.dt, NO_GATE.process
        )
        fp.predict(u=u)
        ekf.predict(*u, run.dt)
        np.testing.assert_allclose(state_residual(ekf.mu, fp.x[:, 0]), 0.0, atol=1e-9)
        np.testing.assert_allclose(ekf.Sigma, fp.P, rtol=0, atol=1e-9 * np.abs(fp.P).max())

        f = observe(rng, run.X_true[k], b_O, nrm, n_max=6 + k % 10)  # 6..15 matches: small dense S
        res = ekf.update(f.d_C, f.b_O, f.Sigma_d)
        fp.update(
            f.d_C.reshape(-1, 1),
            HJacobian,
            Hx,
            R=measurement_covariance(f.Sigma_d),
            args=f.b_O,
            hx_args=f.b_O,
        )
        assert res.applied and res.n_used == len(f.d_C)
        np.testing.assert_allclose(state_residual(ekf.mu, fp.x[:, 0]), 0.0, atol=1e-9)
        np.testing.assert_allclose(ekf.Sigma, fp.P, rtol=0, atol=1e-9 * np.abs(fp.P).max())
        assert abs(res.log_likelihood - fp.log_likelihood) < 1e-9 * abs(fp.log_likelihood)
        assert abs(res.nis - fp.mahalanobis**2) < 1e-9 * res.nis


def _random_spd(rng, dim, log10_range):
    Q, _ = np.linalg.qr(rng.normal(size=(dim, dim)))
    return (Q * 10.0 ** rng.uniform(*log10_range, dim)) @ Q.T


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(3, 30))
def test_update_keeps_covariance_spd_and_equals_the_dense_textbook_form(seed, n):
    """Random priors (eigenvalues 1e-8..1) and features (3x3 covariances 1e-7..1e-2): the update
    equals the dense textbook equations, the posterior is symmetric positive definite, and it never
    grows (Sigma_bar - Sigma is positive semidefinite)."""
    rng = np.random.default_rng(seed)
    mu_bar = np.r_[
        rng.normal(0, 0.2, 2), rng.uniform(0.5, 2), rng.uniform(-3, 3), rng.uniform(-1, 1), rng.uniform(-3, 3)
    ]
    Sigma_bar = _random_spd(rng, 6, (-8, 0))
    b = rng.uniform(-0.14, 0.14, (n, 3))
    Sd = np.stack([_random_spd(rng, 3, (-7, -2)) for _ in range(n)])
    d = measurement_model(mu_bar, b) + rng.normal(0, 0.01, (n, 3))
    ekf = PoseEKF(EKFConfig(gate=GateConfig(dist_max_m=np.inf, gate_prob=None, min_spread_m=1e-9)), rng=rng)
    ekf.initialize(mu_bar, Sigma_bar)
    res = ekf.update(d, b, Sd)
    assert res.applied, res.reason
    # textbook, dense (what a student writes first)
    C = measurement_jacobian(mu_bar, b)
    Sm = measurement_covariance(Sd)
    y = (d - measurement_model(mu_bar, b)).reshape(-1)
    S = C @ Sigma_bar @ C.T + Sm  # innovation covariance
    K = np.linalg.solve(S, C @ Sigma_bar).T  # K = Sigma_bar C^T S^-1
    I_KC = np.eye(6) - K @ C
    Sigma_ref = I_KC @ Sigma_bar @ I_KC.T + K @ Sm @ K.T
    scale = np.abs(Sigma_ref).max()
    np.testing.assert_allclose(
        state_residual(ekf.mu, mu_bar + K @ y), 0.0, atol=1e-8 * max(1.0, np.abs(K @ y).max())
    )
    np.testing.assert_allclose(ekf.Sigma, Sigma_ref, rtol=0, atol=1e-7 * scale)
    np.testing.assert_array_equal(ekf.Sigma, ekf.Sigma.T)
    assert np.linalg.eigvalsh(ekf.Sigma).min() > 0
    assert np.linalg.eigvalsh(Sigma_bar - ekf.Sigma).min() > -1e-9 * np.abs(Sigma_bar).max()


def test_log_likelihood_is_eq9_against_scipy():
    """log N(D; H(mu_bar), C Sigma_bar C^T + Sigma_m) computed densely by SciPy."""
    rng = np.random.default_rng(11)
    b_O, nrm = cube(rng)
    X = np.array([0.05, -0.02, 1.2, 0.4, 0.3, -2.0])
    f = observe(rng, X, b_O, nrm)
    mu_bar = X + rng.normal(0, [0.01, 0.01, 0.02, 0.02, 0.02, 0.02])
    Sigma_bar = np.diag([0.01, 0.01, 0.02, 0.03, 0.03, 0.03]) ** 2
    C = measurement_jacobian(mu_bar, f.b_O)
    cov = C @ Sigma_bar @ C.T + measurement_covariance(f.Sigma_d)
    expected = multivariate_normal.logpdf(
        f.d_C.reshape(-1), measurement_model(mu_bar, f.b_O).reshape(-1), cov
    )
    assert abs(data_log_likelihood(f.d_C, f.b_O, f.Sigma_d, mu_bar, Sigma_bar) - expected) < 1e-9 * abs(
        expected
    )
    ekf = PoseEKF(NO_GATE, rng=rng)
    ekf.initialize(mu_bar, Sigma_bar)
    res = ekf.update(f.d_C, f.b_O, f.Sigma_d)
    assert abs(res.log_likelihood - expected) < 1e-9 * abs(expected)
    assert ekf.log_likelihood == res.log_likelihood


def _calibrated_points(h, c):
    """The points ``h`` (in C) as a stereo pair measures them whose true focal lengths are
    ``f (1 + a_x)``, ``f (1 + a_y)`` and true baseline ``B / (1 + s)`` while it triangulates with the
    calibrated ``f``, ``B`` (projected here, triangulated by ``lab.vision.stereo.triangulate``), turned
    by ``Exp(delta)`` with SciPy's rotation; ``c = [s, delta, a_x, a_y]``. Independent of
    ``calibration_jacobian``."""
    from scipy.spatial.transform import Rotation

    from lab.vision.stereo import triangulate

    s, delta, a_x, a_y = c[0], c[1:4], c[4], c[5]
    p = Rotation.from_rotvec(delta).apply(h)
    fx, fy, B = CAMERA.fx * (1.0 + a_x), CAMERA.fy * (1.0 + a_y), CAMERA.baseline / (1.0 + s)
    v = fy * p[:, 1] / p[:, 2] + CAMERA.cy
    uv_left = np.stack([fx * p[:, 0] / p[:, 2] + CAMERA.cx, v], axis=1)
    uv_right = np.stack([fx * (p[:, 0] - B) / p[:, 2] + CAMERA.cx, v], axis=1)
    return triangulate(uv_left, uv_right, CAMERA)


def test_calibration_update_is_the_dense_update_with_correlated_feature_errors():
    """With a calibration error shared by the frame's features, the update equals the dense textbook
    one with ``S = C Sigma_bar C^T + U Sigma_c U^T + Sigma_m`` (``U`` by central differences of the
    points a miscalibrated pair triangulates, :func:`_calibrated_points`), and its log likelihood is
    SciPy's on that ``S``."""
    rng = np.random.default_rng(5)
    b_O, nrm = cube(rng)
    X = np.array([0.05, -0.02, 1.2, 0.4, 0.3, -2.0])
    f = observe(rng, X, b_O, nrm)
    mu_bar = X + rng.normal(0, [0.01, 0.01, 0.02, 0.02, 0.02, 0.02])
    Sigma_bar = np.diag([0.01, 0.01, 0.02, 0.03, 0.03, 0.03]) ** 2
    cal = CalibrationUncertainty(scale_std=0.005, pointing_std_deg=0.05, focal_std=0.005)
    h = measurement_model(mu_bar, f.b_O)
    U = np.zeros((h.size, 6))
    for j in range(6):
        e = np.zeros(6)
        e[j] = 1e-6
        U[:, j] = (_calibrated_points(h, e) - _calibrated_points(h, -e)).reshape(-1) / 2e-6
    C = measurement_jacobian(mu_bar, f.b_O)
    Sm = measurement_covariance(f.Sigma_d)
    S = C @ Sigma_bar @ C.T + U @ cal.covariance() @ U.T + Sm
    y = (f.d_C - h).reshape(-1)
    K = np.linalg.solve(S, C @ Sigma_bar).T
    I_KC = np.eye(6) - K @ C
    Sigma_ref = I_KC @ Sigma_bar @ I_KC.T + K @ (S - C @ Sigma_bar @ C.T) @ K.T
    ekf = PoseEKF(EKFConfig(gate=NO_GATE.gate, calibration=cal), rng=rng)
    ekf.initialize(mu_bar, Sigma_bar)
    res = ekf.update(f.d_C, f.b_O, f.Sigma_d)
    assert res.applied, res.reason
    np.testing.assert_allclose(state_residual(ekf.mu, mu_bar + K @ y), 0.0, atol=1e-9)
    np.testing.assert_allclose(ekf.Sigma, Sigma_ref, rtol=0, atol=1e-7 * np.abs(Sigma_ref).max())
    expected = multivariate_normal.logpdf(f.d_C.reshape(-1), h.reshape(-1), S)
    assert abs(res.log_likelihood - expected) < 1e-9 * abs(expected)
    assert abs(res.nis - y @ np.linalg.solve(S, y)) < 1e-7 * res.nis
    # the shared error keeps the filter less sure than independent errors would
    plain = PoseEKF(NO_GATE, rng=rng)
    plain.initialize(mu_bar, Sigma_bar)
    plain.update(f.d_C, f.b_O, f.Sigma_d)
    assert np.linalg.eigvalsh(ekf.Sigma - plain.Sigma).min() > -1e-15
    assert np.trace(ekf.Sigma[:3, :3]) > 1.5 * np.trace(plain.Sigma[:3, :3])


def test_calibration_error_is_considered_not_learned_across_frames():
    """Two frames in a row against a dense Schmidt-Kalman (consider) reference: the joint covariance
    over ``[x, c]`` gets the textbook update with the gain's ``c`` rows set to zero, so ``P_xc`` is
    carried from frame to frame and ``Sigma_c`` never shrinks (``U`` by central differences through
    SciPy). On a still scene seen 40 times the filter's lateral uncertainty then stays above what the
    pan-tilt's pointing error allows, while dropping ``P_xc`` after each update (the frames' errors
    independent) lets it shrink with the number of frames."""
    rng = np.random.default_rng(11)
    b_O, nrm = cube(rng)
    X = np.array([0.05, -0.02, 1.2, 0.4, 0.3, -2.0])
    cal = CalibrationUncertainty(scale_std=0.005, pointing_std_deg=0.05, focal_std=0.005)
    mu = X + rng.normal(0, [0.01, 0.01, 0.02, 0.02, 0.02, 0.02])
    Pa = np.zeros((12, 12))
    Pa[:6, :6] = np.diag([0.01, 0.01, 0.02, 0.03, 0.03, 0.03]) ** 2
    Pa[6:, 6:] = cal.covariance()
    ekf = PoseEKF(EKFConfig(gate=NO_GATE.gate, calibration=cal), rng=rng)
    ekf.initialize(mu, Pa[:6, :6])
    for _ in range(2):
        f = observe(rng, X, b_O, nrm)
        h = measurement_model(mu, f.b_O)
        U = np.zeros((h.size, 6))
        for j in range(6):
            e = np.zeros(6)
            e[j] = 1e-6
            U[:, j] = (_calibrated_points(h, e) - _calibrated_points(h, -e)).reshape(-1) / 2e-6
        H = np.hstack([measurement_jacobian(mu, f.b_O), U])
        Sm = measurement_covariance(f.Sigma_d)
        S = H @ Pa @ H.T + Sm
        K = np.linalg.solve(S, H @ Pa).T
        K[6:] = 0.0  # consider: c is not updated
        mu = mu + K[:6] @ (f.d_C - h).reshape(-1)
        I_KH = np.eye(12) - K @ H
        Pa = I_KH @ Pa @ I_KH.T + K @ Sm @ K.T
        res = ekf.update(f.d_C, f.b_O, f.Sigma_d)
        assert res.applied, res.reason
        assert (
            abs(res.log_likelihood - multivariate_normal.logpdf(f.d_C.reshape(-1), h.reshape(-1), S)) < 1e-6
        )
        np.testing.assert_allclose(state_residual(ekf.mu, mu), 0.0, atol=1e-9)
        np.testing.assert_allclose(ekf.Sigma, Pa[:6, :6], rtol=0, atol=1e-7 * np.abs(Pa[:6, :6]).max())
        np.testing.assert_allclose(ekf.P_xc, Pa[:6, 6:], rtol=0, atol=1e-7 * np.abs(Pa[:6, 6:]).max())
        np.testing.assert_allclose(Pa[6:, 6:], cal.covariance())  # the reference's own check

    def still(config, forget=False):  # a still scene, fresh noise each frame (as the filter assumes)
        ekf = PoseEKF(config, rng=np.random.default_rng(0))
        ekf.initialize(X, np.diag([0.01] * 3 + [0.02] * 3) ** 2)
        for _ in range(40):
            f = observe(rng, X, b_O, nrm)
            assert ekf.update(f.d_C, f.b_O, f.Sigma_d).applied
            if forget:
                ekf.P_xc = np.zeros_like(ekf.P_xc)  # the frames' calibration errors independent
        return ekf

    lateral = (math.radians(0.05) * np.linalg.norm(X[:3])) ** 2  # the pointing error 1.2 m away
    considered = still(EKFConfig(gate=NO_GATE.gate, calibration=cal)).Sigma
    forgetful = still(EKFConfig(gate=NO_GATE.gate, calibration=cal), forget=True).Sigma
    assert considered[0, 0] > 0.8 * lateral and considered[1, 1] > 0.8 * lateral
    assert forgetful[0, 0] < 0.25 * considered[0, 0]


def test_model_offset_covariance_is_the_rigid_part_of_independent_point_errors():
    """``Sigma_m`` against a Monte Carlo of SciPy's rigid fit (``Rotation.align_vectors``) to database
    points moved by independent errors; and a filter on a still scene: its :attr:`estimate` (the pose
    the features say) shrinks with the frames, its :attr:`object_estimate` keeps the database's share."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(4)
    b_O, nrm = cube(rng)
    b = b_O[:30]
    sd = 0.003
    Sigma_m = model_offset_covariance(b, sd)
    m = []
    c = b.mean(axis=0)
    for _ in range(3000):
        q = b + rng.normal(0.0, sd, b.shape)
        R, _ = Rotation.align_vectors(q - q.mean(axis=0), b - c)  # q_j ~ R b_j + tau
        m.append(np.concatenate([q.mean(axis=0) - R.apply(c), R.as_rotvec()]))
    np.testing.assert_allclose(np.cov(np.array(m).T), Sigma_m, rtol=0, atol=0.1 * np.abs(Sigma_m).max())
    np.testing.assert_allclose(np.diag(np.cov(np.array(m).T)), np.diag(Sigma_m), rtol=0.12)
    assert not model_offset_covariance(b, 0.0).any()

    X = np.array([0.05, -0.02, 1.2, 0.4, 0.3, -2.0])
    ekf = PoseEKF(EKFConfig(gate=NO_GATE.gate, model=ModelUncertainty(sd)), rng=rng)
    ekf.initialize(X, np.diag([0.01] * 3 + [0.02] * 3) ** 2)
    np.testing.assert_array_equal(ekf.object_estimate.Sigma_rv, ekf.estimate.Sigma_rv)  # nothing to add yet
    for _ in range(40):
        f = observe(rng, X, b_O, nrm)
        assert ekf.update(f.d_C, f.b_O, f.Sigma_d).applied
    floor = model_offset_covariance(f.b_O, sd)
    R = ekf.estimate.G_CO[:3, :3]
    J = np.kron(np.eye(2), R)
    np.testing.assert_allclose(
        ekf.object_estimate.Sigma_rv, ekf.estimate.Sigma_rv + J @ floor @ J.T, atol=1e-15
    )
    np.testing.assert_allclose(ekf.object_estimate.mu, ekf.estimate.mu)
    assert (
        np.linalg.eigvalsh(ekf.object_estimate.Sigma_rv[:3, :3]).min()
        > 0.9 * np.linalg.eigvalsh(floor[:3, :3]).min()
    )
    assert np.trace(ekf.estimate.Sigma_rv[:3, :3]) < 0.5 * np.trace(ekf.object_estimate.Sigma_rv[:3, :3])


def test_model_uncertainty_refuses_bad_values():
    for bad in (-0.01, float("nan"), True, "1"):
        with pytest.raises(ValueError, match="point_std_m must be a finite number >= 0"):
            ModelUncertainty(point_std_m=bad)
    assert ModelUncertainty().is_none and not ModelUncertainty(0.002).is_none


def test_calibration_uncertainty_refuses_bad_values_and_reads_the_camera():
    import dataclasses

    for bad in (-0.01, float("nan"), True):
        with pytest.raises(ValueError, match="scale_std must be a finite number >= 0"):
            CalibrationUncertainty(scale_std=bad)
    cam = dataclasses.replace(CAMERA, depth_scale_std=0.007, pointing_std_deg=0.05)
    assert CalibrationUncertainty.of_camera(cam) == CalibrationUncertainty(0.007, 0.0)  # all a common scale
    # the focal lengths' share apart, the rest the baseline's; the pan-tilt's zero turns C on the robot,
    # not the points measured in C: it is not a calibration error of the features
    cam = dataclasses.replace(cam, depth_scale_std=math.hypot(0.003, 0.004), focal_std=0.004)
    got = CalibrationUncertainty.of_camera(cam)
    assert (got.scale_std, got.pointing_std_deg, got.focal_std) == pytest.approx((0.003, 0.0, 0.004))
    with pytest.raises(ConfigError, match="focal_std .* must be <= depth_scale_std"):
        dataclasses.replace(cam, focal_std=0.01)
    assert CalibrationUncertainty.of_camera(CAMERA).is_none  # an exact camera: the papers' filter
    rng = np.random.default_rng(3)
    only_scale = PoseEKF(EKFConfig(gate=NO_GATE.gate, calibration=CalibrationUncertainty(0.01, 0.0)), rng=rng)
    b_O, nrm = cube(rng)
    X = np.array([0.0, 0.0, 1.0, 0.2, 0.1, 0.3])
    f = observe(rng, X, b_O, nrm)
    only_scale.initialize(X, np.diag([0.01] * 3 + [0.02] * 3) ** 2)
    assert only_scale.update(f.d_C, f.b_O, f.Sigma_d).applied


def test_gate_rejects_wrong_matches_and_keeps_good_ones():
    rng = np.random.default_rng(2)
    b_O, nrm = cube(rng)
    X = np.array([0.0, 0.05, 1.0, 0.5, -0.4, 2.2])
    f = observe(rng, X, b_O, nrm, outlier_frac=0.3)
    Sigma_bar = np.diag([0.005] * 3 + [0.01] * 3) ** 2
    keep = gate_matches(X, Sigma_bar, f.d_C, f.b_O, f.Sigma_d)
    assert keep[~f.wrong].mean() > 0.95 and not keep[f.wrong].any()
    # Mahalanobis per point with the predicted covariance, computed densely here
    C = measurement_jacobian(X, f.b_O).reshape(-1, 3, 6)
    r = f.d_C - measurement_model(X, f.b_O)
    m2 = np.array(
        [r[j] @ np.linalg.solve(C[j] @ Sigma_bar @ C[j].T + f.Sigma_d[j], r[j]) for j in range(len(r))]
    )
    dist = np.linalg.norm(r, axis=1)
    np.testing.assert_array_equal(keep, (m2 <= chi2.ppf(0.999, 3)) & (dist <= 0.15))
    # the Euclidean threshold alone: a far match with a huge covariance passes the chi-square gate only
    S_huge = f.Sigma_d.copy()
    S_huge[f.wrong] = np.eye(3)
    only_chi2 = gate_matches(X, Sigma_bar, f.d_C, f.b_O, S_huge, GateConfig(dist_max_m=np.inf))
    both = gate_matches(X, Sigma_bar, f.d_C, f.b_O, S_huge)
    assert only_chi2[f.wrong].all()
    np.testing.assert_array_equal(both, only_chi2 & (dist <= 0.15))
    assert not both[f.wrong & (dist > 0.15)].any()


def test_gating_keeps_the_filter_on_track_and_reports_the_inliers():
    rng = np.random.default_rng(4)
    b_O, nrm = cube(rng)
    X = np.array([0.1, 0.0, 1.3, -0.5, 0.6, 1.9])
    ekf = PoseEKF(rng=rng)
    I = np.eye(4)
    for k in range(10):
        if k:
            ekf.predict(I, I, I, 0.1)
        f = observe(rng, X, b_O, nrm, outlier_frac=0.2)
        res = ekf.update(f.d_C, f.b_O, f.Sigma_d)
        if k:
            assert res.applied and not res.inliers[f.wrong].any() and res.inliers[~f.wrong].mean() > 0.9
            assert res.n_used == res.inliers.sum() and res.dof == 3 * res.n_used
    assert np.linalg.norm(state_residual(ekf.mu, X)[:3]) < 0.01


def test_bank_applies_one_motion_to_all_and_updates_each_model_alone():
    rng = np.random.default_rng(9)
    b_O, nrm = cube(rng)
    run = moving_run(rng, n_steps=4)
    bank = EKFBank(3, rng=np.random.default_rng(1))
    assert len(bank) == 3 and bank.estimates == (None, None, None)
    assert bank.predict(run.G_RC[0], run.G_RC[1], run.G_odom[0], run.dt) == (None, None, None)
    f = observe(rng, run.X_true[1], b_O, nrm)
    assert bank.update(0, f.d_C, f.b_O, f.Sigma_d).outcome is UpdateOutcome.INITIALIZED
    bank[1].initialize(run.X_true[1], np.eye(6) * 1e-4)
    before = bank.estimates
    assert before[2] is None
    alone = PoseEKF(rng=np.random.default_rng(0))
    alone.initialize(before[1].mu, before[1].Sigma)
    out = bank.predict(run.G_RC[1], run.G_RC[2], run.G_odom[1], run.dt)
    ref = alone.predict(run.G_RC[1], run.G_RC[2], run.G_odom[1], run.dt)
    assert out[2] is None
    np.testing.assert_array_equal(out[1].mu, ref.mu)
    np.testing.assert_array_equal(out[1].Sigma, ref.Sigma)
    f = observe(rng, run.X_true[2], b_O, nrm)
    snapshot = bank.estimates
    res = bank.update(1, f.d_C, f.b_O, f.Sigma_d)
    assert res.applied
    after = bank.estimates
    np.testing.assert_array_equal(after[0].mu, snapshot[0].mu)  # model 0 untouched
    assert not np.array_equal(after[1].mu, snapshot[1].mu)
    assert bank.log_likelihoods[1] == res.log_likelihood and bank.log_likelihoods[0] is None


def test_batched_bank_equals_four_filterpy_filters_over_25_steps():
    """The bank's batched update (update_all) and its one-motion predict against 4 filterpy EKFs fed
    the same data, each model with its own start and its own matches: states, covariances and log
    likelihoods equal to 1e-9 at every step."""
    rng = np.random.default_rng(21)
    b_O, nrm = cube(rng)
    run = moving_run(rng, n_steps=26)
    Sigma0 = np.diag([0.02] * 3 + [0.05] * 3) ** 2
    starts = [run.X_true[0] + 0.01 * rng.standard_normal(6) for _ in range(4)]
    bank = EKFBank(4, NO_GATE, rng=np.random.default_rng(0))
    fps = []
    for f, mu0 in zip(bank.filters, starts, strict=True):
        f.initialize(mu0, Sigma0)
        fp = FilterpyEKFWithOurMotion(dim_x=6, dim_z=3)
        fp.x, fp.P = mu0[:, None].copy(), Sigma0.copy()
        fps.append(fp)
    for k in range(1, len(run.X_true)):
        u = (run.G_RC[k - 1], run.G_RC[k], run.G_odom[k - 1])
        bank.predict(*u, run.dt)
        frames = [observe(rng, run.X_true[k], b_O, nrm, n_max=5 + (k + i) % 12) for i in range(4)]
        results = bank.update_all([(f.d_C, f.b_O, f.Sigma_d) for f in frames])
        for ekf, fp, f, res in zip(bank.filters, fps, frames, results, strict=True):
            fp.F = motion_jacobian(fp.x[:, 0], *u)
            fp.Q = process_noise_covariance(
                motion_model(fp.x[:, 0], *u), run.G_RC[k], u[2], run.dt, NO_GATE.process
            )
            fp.predict(u=u)
            fp.update(
                f.d_C.reshape(-1, 1),
                lambda x, b: measurement_jacobian(x[:, 0], b),
                lambda x, b: measurement_model(x[:, 0], b).reshape(-1, 1),
                R=measurement_covariance(f.Sigma_d),
                args=f.b_O,
                hx_args=f.b_O,
            )
            assert res.applied and res.n_used == len(f.d_C)
            np.testing.assert_allclose(state_residual(ekf.mu, fp.x[:, 0]), 0.0, atol=1e-9)
            np.testing.assert_allclose(ekf.Sigma, fp.P, rtol=0, atol=1e-9 * np.abs(fp.P).max())
            assert abs(res.log_likelihood - fp.log_likelihood) < 1e-9 * abs(fp.log_likelihood)
            assert abs(res.nis - fp.mahalanobis**2) < 1e-9 * res.nis


def test_batched_bank_update_is_each_filter_s_own_update():
    """update_all against update(i, ...) filter by filter, in the identification's configuration
    (rotation-vector chart, calibration error, gate, RANSAC initialisation): the same outcomes, used
    rows and (to round-off) states, NIS and likelihoods, through initialisations, skipped frames (too
    few matches, a broken row) and gated-out wrong matches."""
    rng = np.random.default_rng(8)
    b_O, nrm = cube(rng)
    run = moving_run(rng, n_steps=20)
    cfg = EKFConfig(
        chart=OrientationChart.ROTATION_VECTOR,
        calibration=CalibrationUncertainty(scale_std=0.007, pointing_std_deg=0.05),
    )
    batched, alone = (
        EKFBank(4, cfg, rng=np.random.default_rng(3)),
        EKFBank(4, cfg, rng=np.random.default_rng(3)),
    )
    outcomes = set()
    for k in range(1, len(run.X_true)):
        u = (run.G_RC[k - 1], run.G_RC[k], run.G_odom[k - 1])
        pa, pb = batched.predict(*u, run.dt), alone.predict(*u, run.dt)
        for x, y in zip(pa, pb, strict=True):
            assert (x is None) == (y is None)
            if x is not None:  # the states differ by the updates' round-off
                np.testing.assert_allclose(x.mu, y.mu, rtol=0, atol=1e-12)
                np.testing.assert_allclose(
                    x.Sigma_rv, y.Sigma_rv, rtol=0, atol=1e-12 * np.abs(y.Sigma_rv).max()
                )
        matches = []
        for i in range(4):
            f = observe(rng, run.X_true[k], b_O, nrm, n_max=2 if (k + i) % 7 == 0 else 12)
            d = f.d_C.copy()
            if (k + i) % 5 == 0:
                d[0] += 0.3  # a wrong match: gated out
            if (k + i) % 6 == 0:
                d[1] = np.nan  # a broken row: dropped
            matches.append((d, f.b_O, f.Sigma_d))
        ra = batched.update_all(matches)
        rb = [alone.update(i, *m) for i, m in enumerate(matches)]
        for x, y, fa, fb in zip(ra, rb, batched.filters, alone.filters, strict=True):
            outcomes.add(x.outcome)
            assert (x.outcome, x.reason, x.n_used) == (y.outcome, y.reason, y.n_used)
            np.testing.assert_array_equal(x.inliers, y.inliers)
            if fa.mu is not None:
                np.testing.assert_allclose(fa.mu, fb.mu, rtol=0, atol=1e-12)
                np.testing.assert_allclose(fa.P, fb.P, rtol=0, atol=1e-12 * np.abs(fb.P).max())
            if x.applied:
                assert x.nis == pytest.approx(y.nis, rel=1e-10)
                assert x.log_likelihood == pytest.approx(y.log_likelihood, rel=1e-12)
    assert {UpdateOutcome.INITIALIZED, UpdateOutcome.UPDATED, UpdateOutcome.SKIPPED} <= outcomes
    with pytest.raises(ValueError, match="one match set per model"):
        batched.update_all(matches[:2])


def test_estimates_are_read_only_snapshots():
    ekf = PoseEKF(rng=np.random.default_rng(0))
    ekf.initialize(np.array([0, 0, 1.0, 0, 0, 0]), np.eye(6) * 1e-4)
    est = ekf.estimate
    assert not est.mu.flags.writeable and not est.Sigma.flags.writeable
    d = measurement_model(ekf.mu, np.eye(3) * 0.1)
    ekf.update(d + 0.001, np.eye(3) * 0.1, stereo_covariance(d, CAMERA.fx, CAMERA.baseline))
    assert est.mu[2] == 1.0  # the old snapshot did not move with the filter
    np.testing.assert_allclose(est.G_CO[:3, 3], [0, 0, 1.0])
