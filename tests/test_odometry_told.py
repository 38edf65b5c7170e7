"""The simulator's localizer is told the odometry's stated errors (:func:`lab.runs.room.odometry_told`).

The peer is the simulator's own odometry (:func:`lab.sim.sensing.odometry_increment` on the profile's
per-episode draws): the spread of what it measures must be what the localizer's calibration priors
are widened to, and the realistic profile's own odometry must leave the localizer's settings untouched.
"""

import math
from dataclasses import replace

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


@pytest.mark.parametrize("scale", [1.0, 2.0, 3.0])
def test_the_priors_cover_what_the_simulators_odometry_draws(scale):
    errors = sensing_profile("realistic").scaled(scale).odometry
    told = odometry_told(errors, B, None)
    default = LocalizerConfig()
    n = 20000
    draw = _draws(errors, n)
    zero = np.zeros(n)
    no_slip = OdometryDraw(draw.e_left, draw.e_right, draw.e_track, zero)
    # a spin in place without the slip, noise-free: its over-count's RMS is the prior's stated part, and
    # the turn scale k (the true over the measured turn), its inverse, spreads the same to first order
    _, dth_m = odometry_increment(errors, no_slip, zero, np.full(n, math.pi), B, zero, zero)
    stated = math.hypot(errors.wheel_radius_error, errors.track_width_error)
    assert np.sqrt(np.mean((dth_m / math.pi - 1.0) ** 2)) == pytest.approx(stated, rel=0.05)
    assert np.sqrt(np.mean((math.pi / dth_m - 1.0) ** 2)) == pytest.approx(stated, rel=0.05)
    assert told.turn_scale_sigma == pytest.approx(max(stated, default.turn_scale_sigma))
    # the slip: what a spin over-counts beyond the same turn's share on a drive, RMS about no slip, is
    # the slip state's prior; and the localizer knows the track that sets a motion's spin share
    _, dth_spin = odometry_increment(errors, draw, zero, np.full(n, math.pi), B, zero, zero)
    assert np.sqrt(np.mean((dth_spin / dth_m - 1.0) ** 2)) == pytest.approx(told.spin_slip_sigma, rel=0.05)
    assert told.track_m == B
    # a straight metre, noise-free: the heading it reports is the curvature the localizer calibrates
    _, dth_m = odometry_increment(errors, draw, np.ones(n), zero, B, zero, zero)
    stated = errors.wheel_ratio_error / B
    assert np.std(dth_m) == pytest.approx(stated, rel=0.05)
    assert told.curvature_sigma_rad_per_m == pytest.approx(max(stated, default.curvature_sigma_rad_per_m))
    # a straight metre with the wheels' random errors alone: the heading noise left once calibrated
    exact = OdometryDraw(zero, zero, zero, zero)
    rng = np.random.default_rng(1)
    _, dth_m = odometry_increment(errors, exact, np.ones(n), zero, B, *rng.standard_normal((2, n)))
    stated = math.sqrt(2.0) * errors.wheel_noise / B
    assert np.std(dth_m) == pytest.approx(stated, rel=0.05)
    assert told.calibrated_heading_rad_per_sqrt_m == pytest.approx(
        max(stated, default.calibrated_heading_rad_per_sqrt_m)
    )


def test_the_realistic_profiles_odometry_adds_the_slip_and_leaves_the_rest():
    profile = sensing_profile("realistic")
    told = odometry_told(profile.odometry, B, None)
    assert told == LocalizerConfig(spin_slip_sigma=2.0 * profile.odometry.spin_slip / math.sqrt(3.0))
    camera = camera_states_told(profile.reported_camera(_sim_camera()), mounts_uncertain=True)
    assert odometry_told(profile.odometry, B, camera) == replace(camera, spin_slip_sigma=told.spin_slip_sigma)
    # an odometry without a slip, inside the defaults, leaves the config as it was given
    assert odometry_told(replace(profile.odometry, spin_slip=0.0), B, camera) is camera
    # a localizer that does not calibrate its odometry is left so
    plain = LocalizerConfig(odometry_calibration=False)
    assert odometry_told(profile.scaled(3.0).odometry, B, plain) is plain


def test_it_widens_only_and_keeps_the_other_settings():
    errors = sensing_profile("realistic").scaled(2.0).odometry
    base = LocalizerConfig(turn_scale_sigma=0.5, spin_slip_sigma=0.5, camera_yaw_sigma_rad=0.01)
    told = odometry_told(errors, B, base)
    assert told.turn_scale_sigma == 0.5 and told.spin_slip_sigma == 0.5  # never narrowed
    assert told.camera_yaw_sigma_rad == 0.01
    assert told.curvature_sigma_rad_per_m == pytest.approx(errors.wheel_ratio_error / B)
    # another base's track goes with the slip: it sets a motion's spin share
    assert odometry_told(errors, 0.3, None).track_m == 0.3


def _sim_camera():
    from lab.robot import SIM_CAMERA

    return SIM_CAMERA.camera()
