"""The localizer that calibrates its odometry (``LocalizerConfig.odometry_calibration``): the augmented
motion model against finite differences, the filter against filterpy's EKF on the 5-state, and on
synthetic drives with a systematic turn scale and curvature bias it learns both and stays consistent."""

from __future__ import annotations

import math

import numpy as np
import pytest
from filterpy.kalman import ExtendedKalmanFilter
from localization_helpers import NO_FLOOR, num_jac
from scipy.stats import chi2

from lab.errors import ConfigError
from lab.geometry import wrap_angle
from lab.localization import (
    Landmark,
    Localizer,
    LocalizerConfig,
    calibrated_motion_jacobians,
    calibrated_motion_model,
    measurement_jacobian,
    measurement_model,
    motion_model,
)
from lab.training.landmarks import landmark_map_from_scene

RNG = np.random.default_rng(33)
#: the calibrating filter without the observation floor (filterpy's peer)
CALIBRATED = {**NO_FLOOR, "odometry_calibration": True}
LM = Landmark("p", (0.0, 3.94, 1.5), 0.0, (1.4, 0.02, 1.0), (0.0, -1.0))


@pytest.mark.parametrize("k", range(10))
def test_calibrated_motion_jacobians_match_finite_differences(k):
    s = RNG.uniform([-3, -4, -np.pi, 0.9, -0.05], [3, 4, np.pi, 1.1, 0.05])
    u = RNG.uniform([-0.3, -0.05, -0.5], [0.5, 0.05, 0.5])
    F, V = calibrated_motion_jacobians(s, u)
    np.testing.assert_allclose(F, num_jac(lambda a: calibrated_motion_model(a, u), s), atol=1e-7)
    np.testing.assert_allclose(V, num_jac(lambda a: calibrated_motion_model(s, a), u), atol=1e-7)


def test_nominal_calibration_is_the_pose_models_motion():
    """k = 1, c = 0: the pose moves as in :func:`motion_model`, the calibration stays."""
    for _ in range(20):
        x = RNG.uniform([-3, -4, -np.pi], [3, 4, np.pi])
        u = RNG.uniform([-0.3, -0.05, -0.5], [0.5, 0.05, 0.5])
        out = calibrated_motion_model(np.concatenate([x, [1.0, 0.0]]), u)
        np.testing.assert_allclose(out[:3], motion_model(x, u), atol=1e-12)
        np.testing.assert_allclose(out[3:], [1.0, 0.0])


def test_calibrated_filter_is_filterpys_ekf_on_the_five_state():
    """Two predictions and one plain EKF update (``update_iterations=1``), starting from a correlated
    prior, with a pose kept (cloned) on the way: filterpy's ExtendedKalmanFilter on ``[s, x_c]`` (8
    states) with ``H = [H_x, 0, 0]``, its prediction done by hand with the same F, V and M (and the turn
    scale's walk)."""
    cfg = LocalizerConfig(**CALIBRATED, gate_prob=0.999999, update_iterations=1)
    loc = Localizer([0.3, -1.0, 1.4], np.diag([0.09, 0.04, 0.01]), cfg)
    loc.s[3:] = (1.03, 0.01)
    loc.P[2, 3] = loc.P[3, 2] = 0.3 * math.sqrt(loc.P[2, 2] * loc.P[3, 3])
    loc.start_clone()
    ekf = ExtendedKalmanFilter(8, 3)
    ekf.x = np.concatenate([loc.s, loc.s[:3]])
    ekf.P = np.block([[loc.P, loc.P[:, :3]], [loc.P[:3, :], loc.P[:3, :3]]])
    for u in ([0.4, 0.05, 0.3], [0.6, -0.02, -0.1], [0.0, 0.0, 1.2]):
        u = np.asarray(u)
        loc.predict(u)
        F, V = calibrated_motion_jacobians(ekf.x[:5], u)
        Fj = np.eye(8)
        Fj[:5, :5] = F
        Gj = np.vstack([V, np.zeros((3, 3))])
        ekf.x = np.concatenate([calibrated_motion_model(ekf.x[:5], u), ekf.x[5:]])
        ekf.P = Fj @ ekf.P @ Fj.T + Gj @ cfg.motion_noise(u) @ Gj.T
        ekf.P[3, 3] += cfg.turn_scale_walk_per_sqrt_rad**2 * abs(u[2])
    z = measurement_model(ekf.x[:3] + np.array([0.05, -0.03, 0.02]), LM.planar)
    Q = np.diag([1e-4, 2e-4, 1e-4])
    assert loc.update(z, Q, LM).accepted
    ekf.R = Q
    ekf.update(
        z,
        lambda a: np.hstack([measurement_jacobian(a[:3], LM.planar), np.zeros((3, 5))]),
        lambda a: measurement_model(a[:3], LM.planar),
    )
    x_c, S_c = loc.cloned_estimate()
    np.testing.assert_allclose(loc.s, ekf.x[:5], atol=1e-12)
    np.testing.assert_allclose(loc.P, ekf.P[:5, :5], atol=1e-12)
    np.testing.assert_allclose(x_c, ekf.x[5:], atol=1e-12)
    np.testing.assert_allclose(S_c, ekf.P[5:, 5:], atol=1e-12)
    np.testing.assert_allclose(loc.x, loc.s[:3])
    np.testing.assert_allclose(loc.Sigma, loc.P[:3, :3])


def _drive(loc, lms, rng, k_true, c_true, n_steps, fix_every, noise):
    """A synthetic drive: legs of 0.1 m steps alternating with turns in place; the odometry reports the
    turns divided by ``k_true`` and leaves out the curvature ``c_true`` (so the true heading change is
    ``k dtheta_odo + c dx``), with a random error drawn from ``noise.motion_noise`` (the calibrating
    filter's own). A landmark fix every ``fix_every`` steps.
    Returns the pose NEES after each fix and the largest position error between fixes."""
    x_true = np.array([0.0, -3.0, math.pi / 2])
    nees, worst = [], 0.0
    for i in range(n_steps):
        if i % 20 < 4:  # a turn in place, 4 steps of 0.4 rad, alternating sides
            u_true = np.array([0.0, 0.0, 0.4 * (1 if (i // 20) % 2 else -1)])
        else:
            u_true = np.array([0.1, 0.0, 0.02 * math.sin(i / 7.0)])
        x_true = motion_model(x_true, u_true)
        u_odo = u_true.copy()
        u_odo[2] = (u_true[2] - c_true * u_true[0]) / k_true
        loc.predict(rng.multivariate_normal(u_odo, noise.motion_noise(u_odo)))
        worst = max(worst, math.hypot(*(loc.x[:2] - x_true[:2])))
        if i % fix_every == fix_every - 1:
            lm = lms.landmarks[(i // fix_every) % len(lms)]
            Q = np.diag([2e-4, 2e-4, math.radians(0.5) ** 2])
            z = measurement_model(x_true, lm.planar) + rng.multivariate_normal(np.zeros(3), Q)
            if loc.update(z, Q, lm).accepted:
                e = loc.x - x_true
                e[2] = wrap_angle(e[2])
                nees.append(e @ np.linalg.solve(loc.Sigma, e))
    return np.array(nees), worst


def test_calibration_learns_a_systematic_turn_scale_and_curvature_and_stays_consistent():
    """Odometry that over-counts turns by 4 % and misses a 0.015 rad/m curvature (a realistic Create 2):
    over 30 seeded drives of 400 steps with a landmark fix every 25, the calibrating filter's turn scale
    and curvature end within 3 sigma of the truth with sigma under a third of the prior's, its pose NEES
    is chi-square(3) (mean 2.5-3.5, >= 85 % in the 95 % band), and the worst position error between fixes
    is smaller than the pose-only filter's on the same drives."""
    lms = landmark_map_from_scene("lab_room")
    k_true, c_true = 1.0 / 1.04, 0.015
    cal = LocalizerConfig(
        **CALIBRATED,
        gate_prob=0.99999,
        calibrated_heading_rad_per_sqrt_rad=0.01,
        calibrated_heading_rad_per_sqrt_m=0.01,
    )
    pose_only = LocalizerConfig(**NO_FLOOR, gate_prob=0.99999)
    nees, worst_cal, worst_pose = [], [], []
    for run in range(30):
        P0 = np.diag([1e-4, 1e-4, 7.6e-5])
        x0 = np.array([0.0, -3.0, math.pi / 2]) + np.random.default_rng([run, 1]).multivariate_normal(
            np.zeros(3), P0
        )
        loc = Localizer(x0, P0, cal)
        n, w = _drive(loc, lms, np.random.default_rng([run, 2]), k_true, c_true, 400, 25, cal)
        nees.extend(n)
        worst_cal.append(w)
        k, c, sk, sc = loc.calibration
        assert abs(k - k_true) <= 3 * sk and sk < cal.turn_scale_sigma / 3, (k, sk)
        assert abs(c - c_true) <= 3 * sc and sc < cal.curvature_sigma_rad_per_m / 3, (c, sc)
        other = Localizer(x0, P0, pose_only)
        assert other.calibration is None
        _, w = _drive(other, lms, np.random.default_rng([run, 2]), k_true, c_true, 400, 25, cal)
        worst_pose.append(w)
    nees = np.array(nees)
    assert 2.5 < nees.mean() < 3.5, nees.mean()
    assert np.mean((nees >= chi2.ppf(0.025, 3)) & (nees <= chi2.ppf(0.975, 3))) >= 0.85
    assert np.median(worst_cal) < 0.8 * np.median(worst_pose), (np.median(worst_cal), np.median(worst_pose))


def test_setting_the_pose_keeps_the_calibration_and_forgets_their_correlation():
    loc = Localizer([0.0, 0.0, 0.0])
    loc.predict([0.0, 0.0, 1.0])  # a turn correlates the heading with the turn scale
    assert loc.P[2, 3] != 0.0
    k_var = loc.P[3, 3]
    loc.x = [1.0, 2.0, 0.5]
    loc.Sigma = np.diag([0.01, 0.01, 0.001])
    np.testing.assert_allclose(loc.x, [1.0, 2.0, 0.5])
    assert loc.P[3, 3] == k_var and not loc.P[:3, 3:].any() and not loc.P[3:, :3].any()


def test_odometry_calibration_must_be_a_bool():
    with pytest.raises(ConfigError, match="odometry_calibration must be True or False"):
        LocalizerConfig(odometry_calibration="yes")
    with pytest.raises(ConfigError, match="turn_scale_sigma"):
        LocalizerConfig(turn_scale_sigma=-0.1)
