"""The localizer that calibrates its odometry (``LocalizerConfig.odometry_calibration``): the augmented
motion model against finite differences, the filter against filterpy's EKF on the 5- and 6-state, and on
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
    spin_fraction,
)
from lab.training.landmarks import landmark_map_from_scene

RNG = np.random.default_rng(33)
#: the calibrating filter without the observation floor (filterpy's peer)
CALIBRATED = {**NO_FLOOR, "odometry_calibration": True}
LM = Landmark("p", (0.0, 3.94, 1.5), 0.0, (1.4, 0.02, 1.0), (0.0, -1.0))
H = 0.1175  # the Create 2's half-track [m]: it sets a motion's spin fraction


@pytest.mark.parametrize("k", range(10))
@pytest.mark.parametrize("n", [5, 6])
def test_calibrated_motion_jacobians_match_finite_differences(k, n):
    s = RNG.uniform([-3, -4, -np.pi, 0.9, -0.05, 0.0], [3, 4, np.pi, 1.1, 0.05, 0.15])[:n]
    u = RNG.uniform([-0.3, -0.05, -0.5], [0.5, 0.05, 0.5])
    if k == 0:
        u[0] = 1e-3  # nearly a spin in place
    F, V = calibrated_motion_jacobians(s, u, H)
    np.testing.assert_allclose(F, num_jac(lambda a: calibrated_motion_model(a, u, H), s), atol=1e-7)
    np.testing.assert_allclose(V, num_jac(lambda a: calibrated_motion_model(s, a, H), u), atol=1e-7)


def test_the_spin_fraction_and_the_slips_correction():
    """A turn in place is all spin, a straight drive none; an arc of radius r is ``h / (r + h)`` spin.
    With the slip in the state, a spin's turn is scaled by ``k - sigma``, a drive's by ``k`` alone."""
    assert spin_fraction([0.0, 0.0, 0.3], H) == 1.0
    assert spin_fraction([0.5, 0.0, 0.0], H) == 0.0 and spin_fraction([0.0, 0.0, 0.0], H) == 0.0
    r = 0.8
    assert spin_fraction([0.2, 0.0, -0.2 / r], H) == pytest.approx(H / (r + H))
    s = np.array([0.0, 0.0, 0.0, 0.98, 0.0, 0.05])
    assert calibrated_motion_model(s, [0.0, 0.0, 1.0], H)[2] == pytest.approx(0.98 - 0.05)
    assert calibrated_motion_model(s, [0.3, 0.0, 0.0], H)[2] == 0.0
    arc = calibrated_motion_model(s, [0.2, 0.0, 0.25], H)[2]
    assert arc == pytest.approx((0.98 - 0.05 * H * 0.25 / (0.2 + H * 0.25)) * 0.25)
    with pytest.raises(ValueError, match="needs half_track_m > 0"):  # else the slip silently does nothing
        calibrated_motion_model(s, [0.0, 0.0, 1.0])
    with pytest.raises(ValueError, match="needs half_track_m > 0"):
        calibrated_motion_jacobians(s, [0.0, 0.0, 1.0])
    s[5] = 0.0  # no slip: the five-state's motion
    np.testing.assert_allclose(
        calibrated_motion_model(s, [0.2, 0.01, 0.25], H)[:5],
        calibrated_motion_model(s[:5], [0.2, 0.01, 0.25]),
    )


def test_nominal_calibration_is_the_pose_models_motion():
    """k = 1, c = 0: the pose moves as in :func:`motion_model`, the calibration stays."""
    for _ in range(20):
        x = RNG.uniform([-3, -4, -np.pi], [3, 4, np.pi])
        u = RNG.uniform([-0.3, -0.05, -0.5], [0.5, 0.05, 0.5])
        out = calibrated_motion_model(np.concatenate([x, [1.0, 0.0]]), u)
        np.testing.assert_allclose(out[:3], motion_model(x, u), atol=1e-12)
        np.testing.assert_allclose(out[3:], [1.0, 0.0])


@pytest.mark.parametrize("n", [5, 6])
def test_calibrated_filter_is_filterpys_ekf_on_the_five_or_six_state(n):
    """Two predictions and one plain EKF update (``update_iterations=1``), starting from a correlated
    prior, with a pose kept (cloned) on the way: filterpy's ExtendedKalmanFilter on ``[s, x_c]`` (8 or 9
    states, the spin's slip in the state or not) with ``H = [H_x, 0, 0]``, its prediction done by hand
    with the same F, V and M (and the turn scale's walk)."""
    slip = {"spin_slip_sigma": 0.03} if n == 6 else {}
    cfg = LocalizerConfig(**CALIBRATED, **slip, gate_prob=0.999999, update_iterations=1)
    h = 0.5 * cfg.track_m
    loc = Localizer([0.3, -1.0, 1.4], np.diag([0.09, 0.04, 0.01]), cfg)
    loc.s[3:] = (1.03, 0.01, 0.02)[: n - 3]
    loc.P[2, 3] = loc.P[3, 2] = 0.3 * math.sqrt(loc.P[2, 2] * loc.P[3, 3])
    loc.start_clone()
    ekf = ExtendedKalmanFilter(n + 3, 3)
    ekf.x = np.concatenate([loc.s, loc.s[:3]])
    ekf.P = np.block([[loc.P, loc.P[:, :3]], [loc.P[:3, :], loc.P[:3, :3]]])
    for u in ([0.4, 0.05, 0.3], [0.6, -0.02, -0.1], [0.0, 0.0, 1.2]):
        u = np.asarray(u)
        loc.predict(u)
        F, V = calibrated_motion_jacobians(ekf.x[:n], u, h)
        Fj = np.eye(n + 3)
        Fj[:n, :n] = F
        Gj = np.vstack([V, np.zeros((3, 3))])
        ekf.x = np.concatenate([calibrated_motion_model(ekf.x[:n], u, h), ekf.x[n:]])
        ekf.P = Fj @ ekf.P @ Fj.T + Gj @ cfg.motion_noise(u) @ Gj.T
        ekf.P[3, 3] += cfg.turn_scale_walk_per_sqrt_rad**2 * abs(u[2])
    z = measurement_model(ekf.x[:3] + np.array([0.05, -0.03, 0.02]), LM.planar)
    Q = np.diag([1e-4, 2e-4, 1e-4])
    assert loc.update(z, Q, LM).accepted
    ekf.R = Q
    ekf.update(
        z,
        lambda a: np.hstack([measurement_jacobian(a[:3], LM.planar), np.zeros((3, n))]),
        lambda a: measurement_model(a[:3], LM.planar),
    )
    x_c, S_c = loc.cloned_estimate()
    np.testing.assert_allclose(loc.s, ekf.x[:n], atol=1e-12)
    np.testing.assert_allclose(loc.P, ekf.P[:n, :n], atol=1e-12)
    np.testing.assert_allclose(x_c, ekf.x[n:], atol=1e-12)
    np.testing.assert_allclose(S_c, ekf.P[n:, n:], atol=1e-12)
    np.testing.assert_allclose(loc.x, loc.s[:3])
    np.testing.assert_allclose(loc.Sigma, loc.P[:3, :3])
    assert (loc.spin_slip is not None) == (n == 6)


def _drive(loc, lms, rng, k_true, c_true, n_steps, fix_every, noise, slip=0.0, arc=0.0):
    """A synthetic drive: legs of 0.1 m steps alternating with turns in place; the odometry reports the
    turns divided by ``k_true`` and leaves out the curvature ``c_true`` (so the true heading change is
    ``k dtheta_odo + c dx``), and over-counts each by ``slip`` times its spin fraction (as the
    simulator's wheels scrub), with a random error drawn from ``noise.motion_noise`` (the calibrating
    filter's own). The legs turn ``arc`` rad per step besides, to alternate sides. A landmark fix every
    ``fix_every`` steps. Returns the pose NEES after each fix and the largest position error between
    fixes."""
    x_true = np.array([0.0, -3.0, math.pi / 2])
    nees, worst = [], 0.0
    for i in range(n_steps):
        side = 1 if (i // 20) % 2 else -1
        if i % 20 < 4:  # a turn in place, 4 steps of 0.4 rad, alternating sides
            u_true = np.array([0.0, 0.0, 0.4 * side])
        else:
            u_true = np.array([0.1, 0.0, 0.02 * math.sin(i / 7.0) - arc * side])
        x_true = motion_model(x_true, u_true)
        u_odo = u_true.copy()
        u_odo[2] = (u_true[2] - c_true * u_true[0]) / k_true * (1.0 + slip * spin_fraction(u_true, H))
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


def test_the_spins_slip_in_the_state_keeps_a_drives_turns_right():
    """Spins that over-count by 8 % more than a drive's turns (the slip scaled by the spin fraction, as
    the simulator's wheels scrub), on legs that arc 1 rad per metre: with the slip in the state the
    filter learns the turn scale and the slip apart, each within 3 sigma, and its pose NEES is
    chi-square(3); with one turn scale for both, the spins teach it their slip, the arcs are then
    turned wrong, and its NEES runs high."""
    lms = landmark_map_from_scene("lab_room")
    k_true, c_true, slip = 1.0 / 1.02, 0.01, 0.08
    kw = dict(
        **CALIBRATED,
        gate_prob=0.99999,
        calibrated_heading_rad_per_sqrt_rad=0.01,
        calibrated_heading_rad_per_sqrt_m=0.01,
    )
    six, five = LocalizerConfig(**kw, spin_slip_sigma=0.06), LocalizerConfig(**kw)
    sigma_true = k_true * slip / (1.0 + slip)  # a spin's k / (1 + slip) is k - sigma
    nees = {5: [], 6: []}
    for run in range(30):
        P0 = np.diag([1e-4, 1e-4, 7.6e-5])
        x0 = np.array([0.0, -3.0, math.pi / 2]) + np.random.default_rng([run, 1]).multivariate_normal(
            np.zeros(3), P0
        )
        for cfg in (six, five):
            loc = Localizer(x0, P0, cfg)
            rng = np.random.default_rng([run, 2])
            n, _ = _drive(loc, lms, rng, k_true, c_true, 400, 25, six, slip=slip, arc=0.1)
            nees[loc.s.size].extend(n)
            if loc.spin_slip is not None:
                (k, _, sk, _), (sigma, ss) = loc.calibration, loc.spin_slip
                assert abs(k - k_true) <= 3 * sk and sk < cfg.turn_scale_sigma / 3, (k, sk)
                assert abs(sigma - sigma_true) <= 3 * ss and ss < cfg.spin_slip_sigma / 3, (sigma, ss)
    six_nees, five_nees = np.array(nees[6]), np.array(nees[5])
    assert 2.5 < six_nees.mean() < 3.5, six_nees.mean()
    assert np.mean((six_nees >= chi2.ppf(0.025, 3)) & (six_nees <= chi2.ppf(0.975, 3))) >= 0.9
    assert five_nees.mean() > 3.8, five_nees.mean()


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
    with pytest.raises(ConfigError, match="spin_slip_sigma > 0 needs odometry_calibration"):
        LocalizerConfig(odometry_calibration=False, spin_slip_sigma=0.03)
    with pytest.raises(ConfigError, match="track_m must be > 0"):
        LocalizerConfig(track_m=0.0)
    with pytest.raises(ConfigError, match="turn_scale_sigma"):
        LocalizerConfig(turn_scale_sigma=-0.1)
