"""The observation floor shared by sightings of one landmark from one place
(``LocalizerConfig.shared_floor``): a second look brings fresh image noise but the same calibration
error, and the filter's information must add up to what the looks hold together."""

from __future__ import annotations

import math

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter
from scipy.stats import chi2

from lab.localization import Landmark, Localizer, LocalizerConfig, measurement_model

NORTH = Landmark("poster_north", (0.0, 3.94, 1.5), 0.0, (1.4, 0.02, 1.0), (0.0, -1.0))
X_TRUE = np.array([0.3, 0.9, 1.5])  # 3 m from the poster, facing it
R = np.diag([0.004**2, 0.003**2, math.radians(0.3) ** 2])  # a fit's own covariance (fresh image noise)


@pytest.mark.parametrize("n_looks", [1, 2, 5, 12])
def test_n_sightings_with_one_shared_error_leave_the_information_of_the_batch(n_looks):
    """A linear peer: ``z_i = x + c + e_i`` with one shared ``c ~ N(0, F)`` and fresh ``e_i ~ N(0, R)``.
    filterpy's KalmanFilter, updated once per look with ``shared_floor_covariance(R, F, i)``, ends with the
    covariance of the batch estimate from all looks with their joint covariance
    ``kron(I, R) + kron(1 1^T, F)`` (generalized least squares). Its mean is not the batch's (the
    sequential updates weight the first look most, the batch all alike): both unbiased, the sequential
    one's spread a little above what it states (the NEES test below bounds it)."""
    rng = np.random.default_rng(n_looks)
    F = LocalizerConfig().observation_floor(measurement_model(X_TRUE, NORTH.planar))
    P0 = np.diag([0.05**2, 0.05**2, math.radians(3.0) ** 2])
    kf = KalmanFilter(3, 3)
    kf.x, kf.P, kf.H = np.zeros(3), P0.copy(), np.eye(3)
    for i in range(1, n_looks + 1):
        kf.update(rng.normal(0, 0.01, 3), R=LocalizerConfig.shared_floor_covariance(R, F, i))
    H = np.tile(np.eye(3), (n_looks, 1))
    Sigma = np.kron(np.eye(n_looks), R) + np.kron(np.ones((n_looks, n_looks)), F)
    info = np.linalg.inv(P0) + H.T @ np.linalg.solve(Sigma, H)
    P = np.linalg.inv(info)
    np.testing.assert_allclose(kf.P, P, rtol=1e-6, atol=1e-14)


def test_the_first_sighting_is_the_fits_covariance_plus_the_floor_and_a_bad_count_is_refused():
    F = np.diag([1e-4, 4e-5, 1e-4])
    np.testing.assert_allclose(LocalizerConfig.shared_floor_covariance(R, F, 1), R + F)
    q2 = LocalizerConfig.shared_floor_covariance(R, F, 2)
    assert np.all(np.linalg.eigvalsh(q2 - (R + F)) > 0)  # the second look tells less than the first
    with pytest.raises(ValueError, match="count n must be >= 1"):
        LocalizerConfig.shared_floor_covariance(R, F, 0)


def _stand_and_look(rng, n_looks, shared, move_between=False):
    """A robot standing 3 m from a poster looks at it ``n_looks`` times; the world draws one calibration
    error from the floor (the same for every look) and fresh fit noise per look. The pose's error and
    covariance at the end."""
    cfg = LocalizerConfig(shared_floor=shared, odometry_calibration=False, gate_prob=0.999999)
    P0 = np.diag([0.2**2, 0.2**2, math.radians(5.0) ** 2])
    x0 = X_TRUE + rng.multivariate_normal(np.zeros(3), P0)
    loc = Localizer(x0, P0, cfg)
    z_true = measurement_model(X_TRUE, NORTH.planar)
    c = rng.multivariate_normal(np.zeros(3), cfg.observation_floor(z_true))  # the shared error
    for i in range(n_looks):
        if move_between and i:  # a step of recount_m forward (a new place) and back to the same pose
            loc.predict([cfg.recount_m, 0.0, 0.0])
            loc.predict([-cfg.recount_m, 0.0, 0.0])
        loc.update(z_true + c + rng.multivariate_normal(np.zeros(3), R), R, NORTH)
    e = loc.x - X_TRUE
    return e, loc


def test_looks_from_one_place_leave_a_consistent_pose_and_counted_as_independent_do_not():
    """200 seeded trials of 10 looks from one place: with the floor shared, the pose's NEES is
    chi-square(3) (mean within [2.2, 4.2]: 3.0-3.7 over seeds 0-4, a little above 3 as the sequential
    weighting predicts); counting each look as independent it is far above (the filter trusting ten
    copies of one calibration error)."""
    rng = np.random.default_rng(3)
    nees = {True: [], False: []}
    for _ in range(200):
        state = rng.bit_generator.state
        for shared in (True, False):
            rng.bit_generator.state = state  # the same world for both
            e, loc = _stand_and_look(rng, 10, shared)
            nees[shared].append(float(e @ np.linalg.solve(loc.Sigma, e)))
    shared, independent = np.mean(nees[True]), np.mean(nees[False])
    print(f"NEES mean: shared floor {shared:.2f}, independent {independent:.2f} (chi-square 3: 3)")
    assert 2.2 < shared < 4.2
    assert independent > 2 * shared
    assert np.mean(np.array(nees[True]) > chi2.ppf(0.99, 3)) < 0.05


def test_the_count_starts_again_after_the_robot_moves_and_rejected_looks_do_not_count():
    rng = np.random.default_rng(4)
    _, still = _stand_and_look(rng, 3, True)
    _, moved = _stand_and_look(rng, 3, True, move_between=True)
    floor = LocalizerConfig().observation_floor  # of the look's own z
    first = [r.Q for r in still.history]
    np.testing.assert_allclose(first[0], R + floor(still.history[0].z))
    assert np.trace(first[2]) > np.trace(first[1]) > np.trace(first[0])
    for r in moved.history:  # every look from a new place: the fit's covariance plus the floor
        np.testing.assert_allclose(r.Q, R + floor(r.z))
    F = floor(measurement_model(X_TRUE, NORTH.planar))
    loc = Localizer(X_TRUE, np.diag([1e-6, 1e-6, 1e-8]), LocalizerConfig(odometry_calibration=False))
    far = measurement_model(X_TRUE + [0.5, 0.0, 0.0], NORTH.planar)  # 50 cm off: refused by the gate
    assert not loc.update(far, R, NORTH).accepted
    rec = loc.update(measurement_model(X_TRUE, NORTH.planar), R, NORTH)
    assert rec.accepted
    np.testing.assert_allclose(rec.Q, R + F)  # the refused look did not count
