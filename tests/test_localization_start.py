"""A start measured by hand: the localizer's first landmark sighting fuses with it or corrects it.

Peers: finite differences (the inverse observation's Jacobian), the measurement model itself (the
inverse gives back the observation), filterpy's linear KalmanFilter (the fused first sighting is its
update with H = I in the pose's space), and the true pose the noise-free observations were made from.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter
from localization_helpers import NO_FLOOR, num_jac
from scipy.stats import chi2

from lab.geometry import wrap_angle
from lab.localization import Landmark, Localizer, LocalizerConfig, measurement_model, pose_from_observation

RNG = np.random.default_rng(20)
NORTH = Landmark("poster_north", (0.0, 3.94, 1.5), 0.0, (1.4, 0.02, 1.0), (0.0, -1.0))
Q = np.diag([1e-4, 1e-4, math.radians(0.3) ** 2])
NO_FLOOR_CONFIG = LocalizerConfig(**NO_FLOOR)


@pytest.mark.parametrize("k", range(10))
def test_pose_from_observation_inverts_the_measurement_model(k):
    x = RNG.uniform([-3, -4, -np.pi], [3, 4, np.pi])
    l = RNG.uniform([-3, -4, -np.pi], [3, 4, np.pi])
    z = measurement_model(x, l)
    x_back, J = pose_from_observation(z, l)
    d = x_back - x
    d[2] = wrap_angle(d[2])
    np.testing.assert_allclose(d, 0.0, atol=1e-12)
    np.testing.assert_allclose(J, num_jac(lambda s: pose_from_observation(s, l)[0], z), atol=1e-7)


def _off(x_true, dxy_m: float, dth_deg: float, direction: float):
    return x_true + np.array(
        [dxy_m * math.cos(direction), dxy_m * math.sin(direction), math.radians(dth_deg)]
    )


def test_a_start_30cm_10deg_off_is_reset_by_the_first_sighting_not_gated_out():
    """Sigma0 says 1 cm / 0.5 deg; the robot stood 30 cm / 10 deg off. The plain EKF gates the true
    observation out; with the first-sighting path the pose becomes the one the landmark says."""
    x_true = np.array([0.2, -2.0, math.radians(80.0)])
    start = _off(x_true, 0.30, 10.0, 2.0)
    z = measurement_model(x_true, NORTH.planar)
    plain = Localizer(start)
    assert not plain.update(z, Q, NORTH).accepted  # the problem
    loc = Localizer(start, first_sighting=True)
    rec = loc.update(z, Q, NORTH)
    assert rec.accepted and rec.kind == "reset" and rec.nis > 16.3
    d = loc.x - x_true
    np.testing.assert_allclose([d[0], d[1], wrap_angle(d[2])], 0.0, atol=1e-9)
    # its covariance is the sighting's (J Q J^T, with the observation floor), not the 1 cm start's
    _, J = pose_from_observation(z, NORTH.planar)
    np.testing.assert_allclose(loc.Sigma, J @ rec.Q @ J.T, atol=1e-15)
    # later observations are EKF updates
    x_moved = x_true + np.array([0.0, 0.3, 0.0])
    loc.predict(
        np.array([0.3 * math.cos(-x_true[2] + math.pi / 2), 0.3 * math.sin(-x_true[2] + math.pi / 2), 0.0])
    )
    rec2 = loc.update(measurement_model(x_moved, NORTH.planar), Q, NORTH)
    assert rec2.accepted and rec2.kind == "update"
    assert np.hypot(*(loc.x[:2] - x_moved[:2])) < 0.01


def test_a_consistent_first_sighting_is_fused_as_filterpys_update_with_H_identity():
    """Sigma0 says 10 cm / 5 deg and the start is 20 cm / 6 deg off: within the gate, the sighting's pose
    and the start are fused: filterpy's KalmanFilter with H = I, R = Sigma_z gives the same."""
    x_true = np.array([-1.0, 0.5, math.radians(100.0)])
    start = _off(x_true, 0.20, 6.0, -0.7)
    Sigma0 = np.diag([0.1**2, 0.1**2, math.radians(5.0) ** 2])
    z = measurement_model(x_true, NORTH.planar)
    loc = Localizer(start, Sigma0, NO_FLOOR_CONFIG, first_sighting=True)
    rec = loc.update(z, Q, NORTH)
    assert rec.accepted and rec.kind == "fused"
    x_z, J = pose_from_observation(z, NORTH.planar)
    kf = KalmanFilter(3, 3)
    kf.x, kf.P, kf.H, kf.R = start.copy(), Sigma0.copy(), np.eye(3), J @ Q @ J.T
    kf.update(x_z)
    np.testing.assert_allclose(loc.x, kf.x, atol=1e-12)
    np.testing.assert_allclose(loc.Sigma, kf.P, atol=1e-14)
    # the sighting is far more precise than the start: the fused pose is near the truth
    assert np.hypot(*(loc.x[:2] - x_true[:2])) < 0.015 and abs(math.degrees(loc.x[2] - x_true[2])) < 0.2


def test_a_first_sighting_far_from_the_start_is_an_outlier_and_the_next_one_is_tried():
    x_true = np.array([0.0, -2.5, math.radians(90.0)])
    loc = Localizer(x_true, first_sighting=True)
    wrong = measurement_model(_off(x_true, 1.5, 0.0, 0.0), NORTH.planar)  # a pose 1.5 m away: a bad fit
    rec = loc.update(wrong, Q, NORTH)
    assert not rec.accepted and rec.kind == "outlier"
    np.testing.assert_array_equal(loc.x, x_true)
    assert loc.first_sighting_pending
    rec = loc.update(measurement_model(x_true, NORTH.planar), Q, NORTH)
    assert rec.accepted and rec.kind == "fused" and not loc.first_sighting_pending


def _first_sighting_nees(rng, Sigma0, start_error, n=300):
    nees, kinds = [], []
    for _ in range(n):
        x_true = np.array([rng.uniform(-2, 2), rng.uniform(-3, 1), rng.uniform(1.0, 2.1)])
        start = x_true + start_error(rng)
        z = measurement_model(x_true, NORTH.planar) + rng.multivariate_normal(np.zeros(3), Q)
        loc = Localizer(start, Sigma0, NO_FLOOR_CONFIG, first_sighting=True)
        rec = loc.update(z, Q, NORTH)
        assert rec.accepted
        kinds.append(rec.kind)
        e = loc.x - x_true
        e[2] = wrap_angle(e[2])
        nees.append(float(e @ np.linalg.solve(loc.Sigma, e)))
    return np.array(nees), kinds


SIGMA0 = np.diag([0.05**2, 0.05**2, math.radians(3.0) ** 2])  # hardware/robot.toml's start_sigma


def test_first_sighting_is_consistent_when_the_start_is_as_good_as_its_covariance_says():
    """Start errors drawn from Sigma0, noisy observations of covariance Q: the NEES after the first
    sighting is chi-square(3) (its mean 3 within 3 standard errors, sqrt(6 / n))."""
    nees, kinds = _first_sighting_nees(
        np.random.default_rng(7), SIGMA0, lambda r: r.multivariate_normal(np.zeros(3), SIGMA0)
    )
    assert abs(nees.mean() - 3.0) < 3 * math.sqrt(6.0 / len(nees))
    assert kinds.count("fused") > 0.95 * len(kinds)


def test_first_sighting_accepts_starts_up_to_30cm_10deg_off_and_stays_consistent():
    """Starts off by up to 30 cm and 10 deg though Sigma0 says 5 cm / 3 deg: every first sighting is
    accepted (fused or reset), and the NEES is inside chi-square(3)'s 95 % bound on >= 90 % of them."""

    def off(r):
        a = r.uniform(-np.pi, np.pi)
        d = r.uniform(0.0, 0.3)
        return np.array([d * math.cos(a), d * math.sin(a), math.radians(r.uniform(-10, 10))])

    nees, kinds = _first_sighting_nees(np.random.default_rng(8), SIGMA0, off)
    assert kinds.count("reset") > 50 and kinds.count("fused") > 50
    assert np.mean(nees <= chi2.ppf(0.95, 3)) >= 0.90


def _operator_start_in_the_simulator(seed: int, Sigma0, first_sighting: bool):
    """The simulator's robot behind the localizer, its odometry starting at an operator's mark 5 cm and
    3 deg from where the robot really stands; the localizer re-localizes before a report. Returns the
    localizer's records, the final estimate's position and heading errors against the truth, and its
    estimate."""
    from lab.geometry import Pose2D
    from lab.localization import LocalizedRobot
    from lab.runs.robots import PlacedRobot, make_robot
    from lab.scene import load_scene
    from lab.sim import RenderSettings, SimWorld
    from lab.training.landmarks import trained_landmark_map

    scene = load_scene("lab_room")
    landmarks = trained_landmark_map(scene, progress=False)
    with (
        SimWorld(scene, RenderSettings()) as w,
        make_robot(world=w, seed=seed, sensing="sensors") as run,  # the test makes its own start error
    ):
        run.robot.enable()
        T = w.truth.robot_pose()
        mark = Pose2D(T.x - 0.03, T.y + 0.04, T.theta - math.radians(3.0))  # 5 cm, 3 deg off
        G = mark.G() @ np.linalg.inv(T.G())  # odometry = G (+) the simulator's, which starts at T
        placed = PlacedRobot(run.robot, Pose2D(G[0, 3], G[1, 3], math.atan2(G[1, 0], G[0, 0])))
        robot = LocalizedRobot(
            placed,
            "landmarks",
            landmarks,
            rng=np.random.default_rng([seed, 21]),
            log=lambda m: None,
            Sigma0=Sigma0,
            start_measured_by_hand=first_sighting,
        )
        assert math.hypot(robot.odometry().x - mark.x, robot.odometry().y - mark.y) < 1e-9
        robot.relocalize_to_report()
        est, T = robot.pose_estimate(), w.truth.robot_pose()
    e = est.pose.as_array() - T.as_array()
    e[2] = wrap_angle(e[2])
    return robot.localizer.history, e, est


@pytest.mark.slow
def test_an_operators_start_5cm_3deg_off_is_corrected_by_the_first_sightings_in_the_simulator():
    """A start 5 cm and 3 deg off its mark. Told the simulator's 1 cm / 0.5 deg, the localizer is sure of
    the wrong pose: the re-localization before a report makes no view, and the error stays. Told the
    operator's 10 cm / 5 deg with a measured start, the first sighting is fused (not gated out, the
    gate's S holds the start's covariance) and the pose ends within 2.5 cm and 0.5 deg of the truth,
    inside the 99.9 % bound of its covariance."""
    recs, e, _ = _operator_start_in_the_simulator(2, None, False)
    assert recs == [] and math.hypot(e[0], e[1]) > 0.049 and abs(e[2]) > math.radians(2.9)
    Sigma0 = np.diag([0.1**2, 0.1**2, math.radians(5.0) ** 2])
    recs, e, est = _operator_start_in_the_simulator(2, Sigma0, True)
    print(f"start 5 cm / 3 deg -> {100 * math.hypot(e[0], e[1]):.2f} cm / {math.degrees(e[2]):.2f} deg")
    assert recs[0].kind == "fused" and all(r.accepted for r in recs)
    assert math.hypot(e[0], e[1]) < 0.025 and abs(e[2]) < math.radians(0.5)
    assert e @ np.linalg.solve(est.Sigma, e) < chi2.ppf(0.999, 3)
