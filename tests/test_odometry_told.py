"""The simulator's localizer is told the odometry's stated errors (:func:`lab.runs.room.odometry_told`).

The peer is the simulator's own odometry (:func:`lab.sim.sensing.odometry_increment` on the profile's
per-episode draws): the spread of what it measures must be what the localizer's calibration priors
are widened to, and the realistic profile's own odometry must leave the localizer's settings untouched.
"""

import math

import numpy as np
import pytest

from lab.localization import LocalizerConfig
from lab.robot import BaseLimits
from lab.runs.room import camera_states_told, odometry_told
from lab.sim.sensing import OdometryDraw, odometry_increment, sensing_profile

B = BaseLimits().wheel_base


def _draws(errors, n, seed=0):
    rng = np.random.default_rng(seed)
    d = [errors.draw(rng) for _ in range(n)]
    return OdometryDraw(
        *(np.array([getattr(x, k) for x in d]) for k in ("e_left", "e_right", "e_track", "slip"))
    )


@pytest.mark.parametrize("scale", [2.0, 3.0])
def test_the_priors_cover_what_the_simulators_odometry_draws(scale):
    errors = sensing_profile("realistic").scaled(scale).odometry
    told = odometry_told(errors, B, None)
    n = 20000
    draw = _draws(errors, n)
    zero = np.zeros(n)
    # a spin in place, noise-free: its over-count's RMS is the prior, and the localizer's turn scale k
    # (the true over the measured turn) spreads a little less, so the prior covers it
    _, dth_m = odometry_increment(errors, draw, zero, np.full(n, math.pi), B, zero, zero)
    assert np.sqrt(np.mean((dth_m / math.pi - 1.0) ** 2)) == pytest.approx(told.turn_scale_sigma, rel=0.05)
    k = math.pi / dth_m
    assert 0.8 * told.turn_scale_sigma < np.sqrt(np.mean((k - 1.0) ** 2)) < told.turn_scale_sigma
    # a straight metre, noise-free: the heading it reports is the curvature the localizer calibrates
    _, dth_m = odometry_increment(errors, draw, np.ones(n), zero, B, zero, zero)
    assert np.std(dth_m) == pytest.approx(told.curvature_sigma_rad_per_m, rel=0.05)
    # a straight metre with the wheels' random errors alone: the heading noise left once calibrated
    exact = OdometryDraw(zero, zero, zero, zero)
    rng = np.random.default_rng(1)
    _, dth_m = odometry_increment(errors, exact, np.ones(n), zero, B, *rng.standard_normal((2, n)))
    assert np.std(dth_m) == pytest.approx(told.calibrated_heading_rad_per_sqrt_m, rel=0.05)
    # and each is wider than the localizer's default, which it replaces
    default = LocalizerConfig()
    assert told.turn_scale_sigma > default.turn_scale_sigma
    assert told.curvature_sigma_rad_per_m > default.curvature_sigma_rad_per_m
    assert told.calibrated_heading_rad_per_sqrt_m > default.calibrated_heading_rad_per_sqrt_m


def test_the_realistic_profiles_odometry_leaves_the_localizer_as_it_is():
    profile = sensing_profile("realistic")
    assert odometry_told(profile.odometry, B, None) is None
    camera = camera_states_told(profile.reported_camera(_sim_camera()), mounts_uncertain=True)
    assert odometry_told(profile.odometry, B, camera) is camera


def test_it_widens_only_and_keeps_the_other_settings():
    errors = sensing_profile("realistic").scaled(2.0).odometry
    base = LocalizerConfig(turn_scale_sigma=0.5, camera_yaw_sigma_rad=0.01)
    told = odometry_told(errors, B, base)
    assert told.turn_scale_sigma == 0.5  # never narrowed
    assert told.camera_yaw_sigma_rad == 0.01
    assert told.curvature_sigma_rad_per_m == pytest.approx(errors.wheel_ratio_error / B)


def _sim_camera():
    from lab.robot import SIM_CAMERA

    return SIM_CAMERA.camera()
