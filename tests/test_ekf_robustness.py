"""Bad data never raises and never corrupts the state; programmer errors raise ValueError; divergence
is detected with a reason and the filter re-initialises from the next matches."""

import numpy as np
import pytest
from ekf_scenarios import CAMERA, cube, observe
from hypothesis import given, settings
from hypothesis import strategies as st

from lab.estimation import (
    DivergenceConfig,
    EKFBank,
    EKFConfig,
    GateConfig,
    OrientationChart,
    PoseEKF,
    UpdateOutcome,
    measurement_model,
    state_residual,
)
from lab.estimation.synthetic import stereo_covariance
from lab.geometry import pose6_to_G, se3

X_TRUE = np.array([0.05, -0.03, 1.1, 0.7, -0.3, 1.9])
I4 = np.eye(4)


def tracked(seed=0, config=None, frames=3):
    """A filter that has initialised and run a few frames on the cube at X_TRUE."""
    rng = np.random.default_rng(seed)
    b_O, nrm = cube(rng)
    ekf = PoseEKF(config, rng=rng)
    for k in range(frames):
        if k:
            ekf.predict(I4, I4, I4, 0.1)
        f = observe(rng, X_TRUE, b_O, nrm)
        ekf.update(f.d_C, f.b_O, f.Sigma_d)
    assert ekf.initialized and ekf.divergence is None
    return ekf, rng, b_O, nrm


def assert_unchanged(ekf, mu, Sigma):
    np.testing.assert_array_equal(ekf.mu, mu)
    np.testing.assert_array_equal(ekf.Sigma, Sigma)


def test_too_few_matches_skip_the_update():
    ekf, rng, b_O, nrm = tracked()
    f = observe(rng, X_TRUE, b_O, nrm)
    mu, Sigma = ekf.mu.copy(), ekf.Sigma.copy()
    for n in (0, 1, 2):
        res = ekf.update(f.d_C[:n], f.b_O[:n], f.Sigma_d[:n])
        assert not res.applied and res.outcome is UpdateOutcome.SKIPPED and "too few" in res.reason
        assert res.n_matches == n and res.inliers.shape == (n,) and res.log_likelihood is None
        assert_unchanged(ekf, mu, Sigma)
    assert ekf.update(f.d_C[:3], f.b_O[:3], f.Sigma_d[:3]).applied  # three (non-collinear) are enough


def test_non_finite_rows_are_dropped_and_all_bad_skips():
    ekf, rng, b_O, nrm = tracked()
    f = observe(rng, X_TRUE, b_O, nrm)
    mu, Sigma = ekf.mu.copy(), ekf.Sigma.copy()
    for bad in (np.nan, np.inf, -np.inf):
        d = f.d_C.copy()
        d[:] = bad
        res = ekf.update(d, f.b_O, f.Sigma_d)
        assert not res.applied and "too few" in res.reason and "non-finite" in res.reason
        assert_unchanged(ekf, mu, Sigma)
    d, b, S = f.d_C.copy(), f.b_O.copy(), f.Sigma_d.copy()
    d[0, 1], b[1, 2], S[2, 0, 0] = np.nan, np.inf, np.nan
    S[3] = -np.eye(3)  # not a covariance
    res = ekf.update(d, b, S)
    assert res.applied and "4 non-finite or invalid rows dropped" in res.reason
    assert not res.inliers[:4].any() and res.n_used <= len(d) - 4
    assert np.all(np.isfinite(ekf.mu)) and np.all(np.isfinite(ekf.Sigma))


def test_degenerate_geometry_skips_the_update():
    ekf, *_ = tracked()
    mu, Sigma = ekf.mu.copy(), ekf.Sigma.copy()
    line = np.outer(np.linspace(-0.12, 0.12, 12), [0.3, 1.0, -0.5])  # collinear database points
    d = measurement_model(ekf.mu, line)
    S = stereo_covariance(d, CAMERA.fx, CAMERA.baseline)
    res = ekf.update(d, line, S)
    assert not res.applied and "degenerate" in res.reason
    same = np.tile([0.1, 0.0, 0.14], (12, 1))  # coincident
    res = ekf.update(measurement_model(ekf.mu, same), same, S)
    assert not res.applied and "degenerate" in res.reason
    assert_unchanged(ekf, mu, Sigma)


def test_programmer_errors_raise_value_error():
    ekf, rng, b_O, nrm = tracked()
    f = observe(rng, X_TRUE, b_O, nrm)
    with pytest.raises(ValueError, match="d_C"):
        ekf.update(f.d_C[:, :2], f.b_O, f.Sigma_d)
    with pytest.raises(ValueError, match="b_O"):
        ekf.update(f.d_C, f.b_O[:-1], f.Sigma_d)
    with pytest.raises(ValueError, match="Sigma_d"):
        ekf.update(f.d_C, f.b_O, f.Sigma_d[:, 0])
    with pytest.raises(ValueError, match="G_odom"):
        ekf.predict(I4, I4, np.eye(3), 0.1)
    with pytest.raises(ValueError, match="dt"):
        ekf.predict(I4, I4, I4, -0.1)
    with pytest.raises(ValueError, match="not a rigid transform"):
        ekf.predict(I4, I4, np.diag([2.0, 1, 1, 1]), 0.1)
    with pytest.raises(ValueError, match="positive definite"):
        ekf.initialize(np.zeros(6), -np.eye(6))
    with pytest.raises(ValueError, match="Generator"):
        PoseEKF(rng=0)
    with pytest.raises(ValueError, match="model index"):
        EKFBank(2, rng=np.random.default_rng(0)).update(2, f.d_C, f.b_O, f.Sigma_d)
    with pytest.raises(ValueError, match="min_matches"):
        GateConfig(min_matches=2)


@settings(max_examples=80, deadline=None)
@given(
    st.sampled_from(list(OrientationChart)),
    st.integers(0, 60),
    st.lists(st.sampled_from([np.nan, np.inf, -np.inf, 1e300, -1e300, 0.0, 1e-300]), min_size=1, max_size=20),
    st.integers(0, 2**32 - 1),
)
def test_garbage_never_raises_and_the_state_stays_finite_and_spd(chart, n, garbage, seed):
    """Random matches sprinkled with NaN, inf, huge and zero values (in points and covariances)."""
    ekf, *_ = tracked(seed=seed % 7, config=EKFConfig(chart=chart))
    rng = np.random.default_rng(seed)
    d = rng.normal(0, 0.3, (n, 3)) + [0, 0, 1.1]
    b = rng.uniform(-0.14, 0.14, (n, 3))
    S = np.tile(np.eye(3) * 1e-4, (n, 1, 1))
    for v in garbage:
        if n:
            arr = (d, b, S)[rng.integers(3)]
            arr.reshape(-1)[rng.integers(arr.size)] = v
    for _ in range(3):
        ekf.predict(I4, I4, I4, 0.1)
        res = ekf.update(d, b, S)
        assert res.inliers.shape == (n,)
        assert np.all(np.isfinite(ekf.mu)) and np.all(np.isfinite(ekf.Sigma))
        np.testing.assert_array_equal(ekf.P, ekf.P.T)  # the covariance the filter propagates
        assert np.linalg.eigvalsh(ekf.P).min() > 0


def test_non_finite_odometry_is_divergence_and_the_next_matches_reinitialise():
    ekf, rng, b_O, nrm = tracked()
    mu, Sigma = ekf.mu.copy(), ekf.Sigma.copy()
    G = I4.copy()
    G[0, 3] = np.nan
    est = ekf.predict(I4, I4, G, 0.1)
    assert "non-finite" in ekf.divergence and ekf.divergence.endswith("G_odom")
    np.testing.assert_array_equal(est.mu, mu)  # nothing moved
    assert_unchanged(ekf, mu, Sigma)
    f = observe(rng, X_TRUE, b_O, nrm)
    res = ekf.update(f.d_C, f.b_O, f.Sigma_d)
    assert res.outcome is UpdateOutcome.REINITIALIZED and not res.applied
    assert "G_odom" in res.reason and ekf.divergence is None and ekf.n_reinit == 1
    assert np.linalg.norm(state_residual(ekf.mu, X_TRUE)[:3]) < 0.02


def test_covariance_blow_up_without_measurements_is_divergence():
    ekf, rng, b_O, nrm = tracked()
    k = 0
    while ekf.divergence is None:
        ekf.predict(I4, I4, I4, 1.0)  # object unseen for seconds: the random walk grows Sigma
        k += 1
        assert k < 50
    assert ekf.divergence.startswith("covariance blow-up")
    assert np.all(np.isfinite(ekf.mu)) and np.all(np.isfinite(ekf.Sigma))
    f = observe(rng, X_TRUE, b_O, nrm)
    res = ekf.update(f.d_C, f.b_O, f.Sigma_d)
    assert res.outcome is UpdateOutcome.REINITIALIZED and "covariance blow-up" in res.reason
    assert np.sqrt(ekf.Sigma[2, 2]) < 0.05


@pytest.mark.parametrize("chart", list(OrientationChart))
def test_lost_track_when_the_object_jumps_then_reinitialise_there(chart):
    ekf, rng, b_O, nrm = tracked(config=EKFConfig(chart=chart))
    X_new = X_TRUE + np.array([0.4, 0.0, 0.2, 1.0, 0.2, -0.5])  # the object was moved by hand
    patience = ekf.config.divergence.gating_patience
    for k in range(patience):
        ekf.predict(I4, I4, I4, 0.1)
        f = observe(rng, X_new, b_O, nrm)
        res = ekf.update(f.d_C, f.b_O, f.Sigma_d)
        assert not res.applied and "gating kept 0" in res.reason
        assert (ekf.divergence is None) == (k < patience - 1)
    assert ekf.divergence.startswith("track lost")
    f = observe(rng, X_new, b_O, nrm)
    res = ekf.update(f.d_C, f.b_O, f.Sigma_d)
    assert res.outcome is UpdateOutcome.REINITIALIZED and "track lost" in res.reason
    assert np.linalg.norm(state_residual(ekf.mu, X_new)[:3]) < 0.02


def test_consistently_huge_nis_is_divergence():
    """Stereo covariances under-reported 100x (gate off): every NIS is far above its chi-square
    quantile and after nis_patience updates the filter says so."""
    cfg = EKFConfig(
        gate=GateConfig(dist_max_m=np.inf, gate_prob=None), divergence=DivergenceConfig(nis_patience=4)
    )
    ekf, rng, b_O, nrm = tracked(config=cfg)
    for k in range(4):
        ekf.predict(I4, I4, I4, 0.1)
        f = observe(rng, X_TRUE, b_O, nrm)
        res = ekf.update(f.d_C, f.b_O, f.Sigma_d / 100.0)
        assert res.applied and res.nis > 10 * res.dof
        assert (ekf.divergence is None) == (k < 3)
    assert ekf.divergence.startswith("NIS above its chi-square")


def test_gimbal_lock_is_reported():
    ekf = PoseEKF(rng=np.random.default_rng(0))
    ekf.initialize(np.array([0.0, 0.0, 1.0, 0.3, np.pi / 2 - 1e-5, 0.2]), np.eye(6) * 1e-4)
    ekf.predict(I4, I4, I4, 0.1)
    assert ekf.divergence is not None and ("gimbal" in ekf.divergence or "blow-up" in ekf.divergence)
    assert np.all(np.isfinite(ekf.mu)) and np.all(np.isfinite(ekf.Sigma))


def test_without_auto_initialize_nothing_happens_until_initialize():
    rng = np.random.default_rng(1)
    b_O, nrm = cube(rng)
    ekf = PoseEKF(EKFConfig(auto_initialize=False), rng=rng)
    f = observe(rng, X_TRUE, b_O, nrm)
    assert ekf.predict(I4, I4, I4, 0.5) is None and ekf.t == 0.5
    res = ekf.update(f.d_C, f.b_O, f.Sigma_d)
    assert res.outcome is UpdateOutcome.SKIPPED and res.reason == "not initialised" and ekf.mu is None
    ekf.initialize(X_TRUE, np.eye(6) * 1e-4)
    assert ekf.update(f.d_C, f.b_O, f.Sigma_d).applied


def test_initialisation_needs_enough_matches_and_says_why():
    rng = np.random.default_rng(2)
    b_O, nrm = cube(rng)
    ekf = PoseEKF(rng=rng)
    f = observe(rng, X_TRUE, b_O, nrm)
    res = ekf.update(f.d_C[:3], f.b_O[:3], f.Sigma_d[:3])  # below RansacConfig.min_matches = 4
    assert res.outcome is UpdateOutcome.SKIPPED and "not initialised: too few" in res.reason
    assert not ekf.initialized
    res = ekf.update(f.d_C, f.b_O, f.Sigma_d)
    assert res.outcome is UpdateOutcome.INITIALIZED and res.n_used == res.inliers.sum() >= 40


def test_object_motion_G_OO_is_used_in_predict():
    """A known object motion moves the prediction exactly as the composition says."""
    ekf = PoseEKF(rng=np.random.default_rng(0))
    ekf.initialize(X_TRUE, np.eye(6) * 1e-4)
    G_OO = se3(np.eye(3), (0.1, 0.0, 0.0))
    est = ekf.predict(I4, I4, I4, 0.1, G_OO=G_OO)
    np.testing.assert_allclose(est.G_CO, pose6_to_G(X_TRUE) @ G_OO, atol=1e-12)
