"""Re-finding a lost robot (:mod:`lab.localization.refind`, ``LocalizerConfig(refind=True)``; off by
default): rejected sightings that agree with one another reset the pose; a wrong fit, one poster seen again
from one place, or sightings that disagree do not.

Peers: the true pose the sightings were drawn from (the re-found pose's error, and its NEES against the
covariance the reset states, within the chi-square(3) bounds), and the filter with the re-find off, which
stays lost on the same sightings.
"""

from __future__ import annotations

import math

import numpy as np
from localization_helpers import NO_FLOOR
from scipy.stats import chi2

from lab.errors import ConfigError
from lab.geometry import wrap_angle
from lab.localization import Landmark, Localizer, LocalizerConfig, measurement_model

NORTH = Landmark("north", (0.0, 3.94, 1.5), 0.0, (1.4, 0.02, 1.0), (0.0, -1.0))
EAST = Landmark("east", (3.94, 0.5, 1.5), math.pi / 2, (0.02, 1.4, 1.0), (-1.0, 0.0))
Q = np.diag([0.01**2, 0.01**2, math.radians(0.5) ** 2])  # a poster's fit at 3-4 m
TIGHT = np.diag([0.01**2, 0.01**2, math.radians(0.5) ** 2])  # what a lost estimate still claims
ON = LocalizerConfig(refind=True)


def _seen(x_true, lm, rng=None):
    z = measurement_model(x_true, lm.planar)
    if rng is not None:
        z = z + rng.multivariate_normal(np.zeros(3), Q)
    return z


def _turn(x, dth):
    return np.array([x[0], x[1], wrap_angle(x[2] + dth)])


OFF = np.array([0.4, -0.2, math.radians(35.0)])  # how far a lost estimate is from the truth


def _lost(config=None):
    """A localizer whose estimate is :data:`OFF` the truth while claiming 1 cm / 0.5 deg, and the truth."""
    truth = np.array([0.0, 0.0, math.pi / 2])
    return Localizer(truth + OFF, TIGHT, config=config or ON), truth


def test_a_lost_robot_is_refound_by_one_poster_seen_from_two_places_and_stays_lost_without_it():
    """From one place, however often the same poster is seen, the estimate stays (one piece of evidence);
    after a turn (a new place) the poster seen again agrees with the kept sighting: the pose is reset to
    within the sightings' own error. With the re-find off the same sightings leave it lost."""
    for refind in (True, False):
        loc, truth = _lost(LocalizerConfig(refind=refind))
        recs = [loc.update(_seen(truth, NORTH), Q, NORTH) for _ in range(4)]
        assert not any(r.accepted for r in recs) and loc.n_refinds == 0
        loc.predict(np.array([0.0, 0.0, math.radians(20.0)]))  # the odometry's turn is the true one
        truth = _turn(truth, math.radians(20.0))
        rec = loc.update(_seen(truth, NORTH), Q, NORTH)
        err = loc.x - truth
        err[2] = wrap_angle(err[2])
        if refind:
            assert rec.accepted and rec.kind == "refound" and loc.n_refinds == 1
            assert math.hypot(err[0], err[1]) < 1e-6 and abs(err[2]) < 1e-6  # noise-free sightings
            assert loc.rejected_in_a_row == 0
            rec = loc.update(_seen(truth, EAST), Q, EAST)  # the next poster now passes the gate
            assert rec.accepted and rec.kind == "update"
        else:
            assert not rec.accepted and loc.n_refinds == 0
            assert math.hypot(err[0], err[1]) > 0.3 and abs(err[2]) > math.radians(30.0)


def test_two_posters_seen_from_one_place_refind_the_robot():
    loc, truth = _lost()
    assert not loc.update(_seen(truth, NORTH), Q, NORTH).accepted
    rec = loc.update(_seen(truth, EAST), Q, EAST)
    assert rec.kind == "refound" and np.allclose(loc.x, truth, atol=1e-6)


def test_the_refound_pose_is_consistent_with_the_covariance_it_states():
    """Noisy sightings (drawn from ``Q``) of two posters from one place, lost robots at random: the
    re-found pose's NEES against its covariance is chi-square(3) (mean within its 99 % bounds)."""
    rng = np.random.default_rng(7)
    nees = []
    for _ in range(300):
        truth = np.array([rng.uniform(-1.5, 1.5), rng.uniform(-1.5, 1.0), rng.uniform(0.3, 1.3)])
        off = np.array([*rng.uniform(-0.8, 0.8, 2), math.radians(rng.uniform(-60, 60))])
        loc = Localizer(
            truth + off, TIGHT, LocalizerConfig(**NO_FLOOR, refind=True)
        )  # Q is the sightings' whole noise
        first = loc.update(_seen(truth, NORTH, rng), Q, NORTH)
        rec = loc.update(_seen(truth, EAST, rng), Q, EAST)
        if first.accepted or rec.kind != "refound":
            continue  # the offset was small enough for the gate: not a lost robot
        e = loc.x - truth
        e[2] = wrap_angle(e[2])
        nees.append(float(e @ np.linalg.solve(loc.Sigma, e)))
    n = len(nees)
    assert n > 250
    lo, hi = chi2.ppf([0.005, 0.995], 3 * n) / n
    assert lo <= np.mean(nees) <= hi, (np.mean(nees), lo, hi)


def test_a_wrong_fit_seen_again_from_one_place_never_moves_a_good_estimate():
    """A well-localized robot, one poster's fit wrong the same way frame after frame (a partly hidden
    poster): rejected every time, never a re-find, the estimate unchanged."""
    truth = np.array([0.0, 0.0, math.pi / 2])
    loc = Localizer(truth, TIGHT, ON)
    wrong = truth + [0.3, 0.1, math.radians(8.0)]
    for _ in range(10):
        assert not loc.update(_seen(wrong, NORTH), Q, NORTH).accepted
    assert loc.n_refinds == 0 and np.allclose(loc.x, truth)


def test_rejected_sightings_that_disagree_with_each_other_refind_nothing():
    """Two wrong fits of two posters that put the robot in different places: neither is believed."""
    truth = np.array([0.0, 0.0, math.pi / 2])
    loc = Localizer(truth, TIGHT, ON)
    assert not loc.update(_seen(truth + [0.3, 0.1, 0.1], NORTH), Q, NORTH).accepted
    assert not loc.update(_seen(truth + [-0.3, 0.2, -0.2], EAST), Q, EAST).accepted
    assert loc.n_refinds == 0 and np.allclose(loc.x, truth)


def test_an_accepted_sighting_between_two_rejected_ones_drops_the_first():
    """An accepted update says the estimate is not lost: a rejected sighting before it cannot pair with
    one after it."""
    truth = np.array([0.0, 0.0, math.pi / 2])
    wrong = truth + [0.4, -0.2, math.radians(35.0)]
    loc = Localizer(truth, TIGHT, ON)
    assert not loc.update(_seen(wrong, NORTH), Q, NORTH).accepted
    assert loc.update(_seen(truth, NORTH), Q, NORTH).accepted
    rec = loc.update(_seen(wrong, EAST), Q, EAST)
    assert not rec.accepted and loc.n_refinds == 0


def test_a_kept_sighting_is_carried_by_the_odometry_with_its_calibration():
    """The robot spins with a turn scale its odometry over-counts by 25 % (six times the prior's 4 %):
    the estimate's heading drifts out of its covariance and the gate rejects the poster. After a further
    turn of 20 deg (the same over-count) it sees the poster again, from a new place: the kept sighting,
    carried by the odometry with the turn scale's uncertainty, still agrees, and the robot is re-found."""
    truth = np.array([0.0, 0.0, math.pi / 2])
    loc = Localizer(truth, TIGHT, ON)
    assert loc.calibration is not None  # the turn scale is in the state
    for _ in range(24):  # 240 deg true, in 10 deg steps; the odometry says 12.5
        loc.predict(np.array([0.0, 0.0, math.radians(12.5)]))
        truth = _turn(truth, math.radians(10.0))
    assert not loc.update(_seen(truth, NORTH), Q, NORTH).accepted  # 60 deg off
    for _ in range(2):
        loc.predict(np.array([0.0, 0.0, math.radians(12.5)]))
        truth = _turn(truth, math.radians(10.0))
    rec = loc.update(_seen(truth, NORTH), Q, NORTH)
    assert rec.kind == "refound"
    assert abs(wrap_angle(loc.x[2] - truth[2])) < 1e-6


def test_the_refind_is_off_by_default():
    """Off by default (docs/tuning/localizer-refind.md): the same sightings leave a default filter lost."""
    truth = np.array([0.0, 0.0, math.pi / 2])
    loc = Localizer(truth + OFF, TIGHT)
    assert loc.refinder is None
    assert not loc.update(_seen(truth, NORTH), Q, NORTH).accepted
    assert not loc.update(_seen(truth, EAST), Q, EAST).accepted and loc.n_refinds == 0


def test_refind_must_be_a_bool():
    try:
        LocalizerConfig(refind="yes")
    except ConfigError as e:
        assert "refind must be True or False" in str(e)
    else:
        raise AssertionError("refind='yes' was accepted")


def test_a_refind_keeps_a_cloned_poses_joint_covariance_valid():
    """A pose kept in the state (stochastic cloning: the pose an object was found from) while the robot is
    re-found: the clone keeps its own mean and covariance (the reset tells nothing new about where the
    robot was then), and the joint covariance of the state and the clone stays symmetric positive
    semi-definite."""
    loc, truth = _lost()
    loc.start_clone()
    x_c, C_c = loc.cloned_estimate()
    loc.predict(np.array([0.1, 0.0, 0.0]))
    truth = truth + [0.0, 0.1, 0.0]  # heading 90 deg: ahead is +y
    assert not loc.update(_seen(truth, NORTH), Q, NORTH).accepted
    assert loc.update(_seen(truth, EAST), Q, EAST).kind == "refound"
    x_after, C_after = loc.cloned_estimate()
    np.testing.assert_allclose(x_after, x_c)
    np.testing.assert_allclose(C_after, C_c)
    cross = loc._clone.cross  # Cov(s, x_c) after the reset: J_l Cov(s, x_c) in the pose's rows
    J = np.block([[loc.P, cross], [cross.T, C_after]])
    np.testing.assert_allclose(J, J.T, atol=1e-15)
    assert np.linalg.eigvalsh(J).min() > -1e-12
