"""The localizer: its equations against finite differences and filterpy, its consistency on synthetic
data, the landmark map's validation, and a short closed loop in the simulator against the truth."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from filterpy.kalman import ExtendedKalmanFilter
from localization_helpers import NO_FLOOR, num_jac
from nav_fakes import KinematicRobot
from scipy.optimize import least_squares
from scipy.stats import chi2

from lab.errors import ConfigError
from lab.geometry import Pose2D, Rz, pan_tilt_G_RC, relative_pose2d, se3, se3_inv, wrap_angle
from lab.localization import (
    Landmark,
    LandmarkObservation,
    LandmarkObserver,
    LocalizationMode,
    LocalizedRobot,
    Localizer,
    LocalizerConfig,
    PlanarPoseEstimate,
    face_share_in_image,
    measurement_jacobian,
    measurement_model,
    motion_jacobians,
    motion_model,
    observation_of,
    odometry_increment,
)
from lab.robot import PanTiltState, StereoFrame, frame_motion
from lab.training.landmarks import landmark_map_from_scene, load_landmark_map

RNG = np.random.default_rng(20)


@pytest.mark.parametrize("k", range(20))
def test_motion_jacobians_match_finite_differences(k):
    x = RNG.uniform([-3, -4, -np.pi], [3, 4, np.pi])
    u = RNG.uniform([-0.3, -0.05, -0.5], [0.5, 0.05, 0.5])
    F, V = motion_jacobians(x, u)
    np.testing.assert_allclose(F, num_jac(lambda s: motion_model(s, u), x), atol=1e-7)
    np.testing.assert_allclose(V, num_jac(lambda s: motion_model(x, s), u), atol=1e-7)


@pytest.mark.parametrize("k", range(20))
def test_measurement_jacobian_matches_finite_differences(k):
    x = RNG.uniform([-3, -4, -np.pi], [3, 4, np.pi])
    l = RNG.uniform([-3, -4, -np.pi], [3, 4, np.pi])
    H = measurement_jacobian(x, l)
    np.testing.assert_allclose(H, num_jac(lambda s: measurement_model(s, l), x), atol=1e-7)


def test_odometry_increment_inverts_the_motion_model():
    for _ in range(50):
        a = Pose2D(*RNG.uniform([-3, -4, -np.pi], [3, 4, np.pi]))
        u = RNG.uniform([-1, -1, -3], [1, 1, 3])
        b = Pose2D(*motion_model(a.as_array(), u))
        np.testing.assert_allclose(odometry_increment(a, b), u, atol=1e-12)


def test_measurement_model_is_the_landmark_seen_from_the_robot():
    """h(x; l) against the 4x4 transforms: G_RL = G_WR^-1 G_WL."""
    x = np.array([0.7, -1.2, 0.4])
    lm = Landmark("p", (2.9, 1.6, 1.5), math.radians(170.0), (0.02, 1.2, 0.9), (-1.0, 0.0))
    G_RL = np.linalg.inv(Pose2D(*x).G()) @ lm.G_WL
    z = measurement_model(x, lm.planar)
    np.testing.assert_allclose(z[:2], G_RL[:2, 3], atol=1e-12)
    assert math.isclose(z[2], math.atan2(G_RL[1, 0], G_RL[0, 0]), abs_tol=1e-12)


def _exp(phi):
    a = np.linalg.norm(phi)
    if a < 1e-15:
        return np.eye(3)
    k = phi / a
    Kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(a) * Kx + (1 - math.cos(a)) * Kx @ Kx


def test_observation_covariance_is_the_fits_through_its_jacobian():
    """observation_of carries Sigma_rv (over t_C and phi, R <- Exp(phi) R) by J: check J numerically."""
    G_RC = pan_tilt_G_RC(0.6, -0.2, (0.0, 0.0, 1.1), (0.05, 0.06, 0.0))
    G_CL = np.linalg.inv(G_RC) @ se3(Rz(1.1), (2.0, 0.8, 0.4))
    G_CL[:3, :3] = _exp(np.array([0.02, -0.03, 0.01])) @ G_CL[:3, :3]  # not exactly upright

    def z_of(p):
        G = G_CL.copy()
        G[:3, 3] = G_CL[:3, 3] + p[:3]
        G[:3, :3] = _exp(p[3:]) @ G_CL[:3, :3]
        return observation_of(G_RC, G, np.eye(6))[0]

    J = num_jac(z_of, np.zeros(6))
    Sigma = np.diag(RNG.uniform(1e-6, 1e-4, 6))
    _, Q = observation_of(G_RC, G_CL, Sigma)
    np.testing.assert_allclose(Q, J @ Sigma @ J.T, rtol=1e-5, atol=1e-14)


def test_update_matches_filterpy():
    """One landmark update of the plain EKF (``update_iterations=1``) equals filterpy's
    ExtendedKalmanFilter.update (with the same H, h, R)."""
    cfg = LocalizerConfig(**NO_FLOOR, gate_prob=0.999999, update_iterations=1)
    lm = Landmark("p", (0.0, 3.94, 1.5), 0.0, (1.4, 0.02, 1.0), (0.0, -1.0))
    x0 = np.array([0.3, -1.0, 1.4])
    P0 = np.diag([0.04, 0.02, 0.01])
    z = measurement_model(x0 + np.array([0.05, -0.03, 0.02]), lm.planar)
    Q = np.diag([1e-4, 2e-4, 1e-4])
    loc = Localizer(x0, P0, cfg)
    loc.update(z, Q, lm)
    ekf = ExtendedKalmanFilter(3, 3)
    ekf.x, ekf.P, ekf.R = x0.copy(), P0.copy(), Q
    ekf.update(z, lambda s: measurement_jacobian(s, lm.planar), lambda s: measurement_model(s, lm.planar))
    np.testing.assert_allclose(loc.x, ekf.x, atol=1e-12)
    np.testing.assert_allclose(loc.Sigma, ekf.P, atol=1e-12)


def _map_pose(x_bar, Sigma_bar, z, Q, l):
    """The posterior's mode under the nonlinear h, by SciPy's least squares: the iterated EKF's peer."""

    def residuals(x):
        dx = x - x_bar
        dx[2] = wrap_angle(dx[2])
        r = z - measurement_model(x, l)
        r[2] = wrap_angle(r[2])
        wp = np.linalg.cholesky(np.linalg.inv(Sigma_bar)).T
        wq = np.linalg.cholesky(np.linalg.inv(Q)).T
        return np.concatenate([wp @ dx, wq @ r])

    return least_squares(residuals, x_bar, xtol=1e-14, ftol=1e-14, gtol=1e-14).x


@pytest.mark.parametrize("heading_err_deg", [2.0, 8.0, 15.0, 25.0])
def test_iterated_update_reaches_the_posteriors_mode(heading_err_deg):
    """After a long drive the prior's heading may be 15 deg off: one EKF step, linearised there, lands
    far from a precise sighting (15 cm at 15 deg, measured in the search); the iterated update converges
    to the posterior's mode that SciPy's least squares finds, and so to the truth the sighting gives."""
    cfg = LocalizerConfig(**NO_FLOOR, gate_prob=0.999999)
    lm = Landmark("p", (0.0, 3.94, 1.5), 0.0, (1.4, 0.02, 1.0), (0.0, -1.0))
    true = np.array([0.8, 2.8, math.radians(60.0)])
    d = 0.03 * heading_err_deg  # [m]: position error grows with the heading's
    x_bar = true + np.array([0.8 * d, -0.6 * d, -math.radians(heading_err_deg)])
    Sigma_bar = np.diag([d**2, d**2, math.radians(heading_err_deg) ** 2])
    z = measurement_model(true, lm.planar)
    Q = np.diag([1e-4, 1e-4, math.radians(0.6) ** 2])
    iterated = Localizer(x_bar, Sigma_bar, cfg)
    rec = iterated.update(z, Q, lm)
    plain = Localizer(x_bar, Sigma_bar, replace(cfg, update_iterations=1))
    plain.update(z, Q, lm)
    assert rec.accepted
    np.testing.assert_allclose(iterated.x, _map_pose(x_bar, Sigma_bar, z, Q, lm.planar), atol=1e-6)
    assert np.hypot(*(iterated.x - true)[:2]) < 0.01
    if heading_err_deg >= 15.0:
        assert np.hypot(*(plain.x - true)[:2]) > 0.1  # what the plain EKF did in the search


@pytest.mark.parametrize("bad", [0, -1, 2.5, True, "3"])
def test_update_iterations_must_be_a_positive_integer(bad):
    with pytest.raises(ConfigError, match="update_iterations must be an integer >= 1"):
        LocalizerConfig(update_iterations=bad)


def test_gate_lockout_recovery_inflates_the_covariance():
    """Observations rejected in a row while driving make the filter doubt itself, not the landmarks (the
    re-find off: it would reset the pose from the second; tests/test_localization_refind.py)."""
    lm = Landmark("p", (0.0, 3.94, 1.5), 0.0, (1.4, 0.02, 1.0), (0.0, -1.0))
    cfg = LocalizerConfig(max_rejected_in_a_row=3, reject_inflation=9.0, refind=False)
    loc = Localizer([0.0, 0.0, math.pi / 2], config=cfg)
    true = np.array([0.3, 0.0, math.pi / 2])  # the robot is really 30 cm off
    Q = np.diag([1e-4, 1e-4, 1e-5])
    recs = []
    for _ in range(12):  # 6 cm ahead between frames; 1 cm -> 3 cm -> 9 cm: then it fits
        loc.predict(np.array([0.06, 0.0, 0.0]))
        true = true + [0.0, 0.06, 0.0]
        recs.append(loc.update(measurement_model(true, lm.planar), Q, lm))
    assert [r.accepted for r in recs[:3]] == [False, False, False] and loc.n_inflations >= 1
    assert any(r.accepted for r in recs[3:]) and abs(loc.x[0] - 0.3) < 0.05


def test_a_standing_robot_counts_a_landmarks_rejection_once():
    """Standing still, the same wrong fit seen frame after frame (a local search's views) is one piece of
    evidence: no inflation however often; three different landmarks rejected from one place do inflate;
    after the robot has moved ``recount_m`` the same landmark counts again (the re-find off, as above)."""
    cfg = LocalizerConfig(max_rejected_in_a_row=3, reject_inflation=9.0, refind=False)
    lms = [
        Landmark(n, (x, 3.94, 1.5), 0.0, (1.4, 0.02, 1.0), (0.0, -1.0))
        for n, x in (("a", -1.5), ("b", 0.0), ("c", 1.5))
    ]
    Q = np.diag([1e-4, 1e-4, 1e-5])
    off = np.array([0.3, 0.0, math.pi / 2])  # where the fits put the robot: 30 cm from its estimate

    loc = Localizer([0.0, 0.0, math.pi / 2], config=cfg)
    recs = [loc.update(measurement_model(off, lms[0].planar), Q, lms[0]) for _ in range(12)]
    assert not any(r.accepted for r in recs) and loc.n_inflations == 0
    loc.predict(np.array([0.0, 0.0, math.radians(0.5)]))  # a turn too small to be a new place
    loc.update(measurement_model(off + [0.0, 0.0, math.radians(0.5)], lms[0].planar), Q, lms[0])
    assert loc.n_inflations == 0 and loc.rejected_in_a_row == 1

    loc = Localizer([0.0, 0.0, math.pi / 2], config=cfg)
    recs = [loc.update(measurement_model(off, lm.planar), Q, lm) for lm in lms * 3]  # 1 -> 3 -> 9 cm
    assert loc.n_inflations == 2 and any(r.accepted for r in recs[6:]) and abs(loc.x[0] - 0.3) < 0.05

    loc = Localizer([0.0, 0.0, math.pi / 2], config=cfg)
    for k in range(3):
        loc.update(measurement_model(off + [0.0, 0.06 * k, 0.0], lms[0].planar), Q, lms[0])
        loc.predict(np.array([0.06, 0.0, 0.0]))  # 6 cm ahead (>= recount_m): a new place
    assert loc.n_inflations == 1
    with pytest.raises(ConfigError, match="recount_m"):
        LocalizerConfig(recount_m=-1.0)


def test_gate_rejects_an_outlier():
    lm = Landmark("p", (0.0, 3.94, 1.5), 0.0, (1.4, 0.02, 1.0), (0.0, -1.0))
    loc = Localizer([0.0, 0.0, math.pi / 2])
    z = measurement_model(np.array([0.8, 0.0, math.pi / 2]), lm.planar)  # 80 cm off, sigma 1 cm
    rec = loc.update(z, np.diag([1e-4, 1e-4, 1e-5]), lm)
    assert not rec.accepted and rec.nis > chi2.ppf(0.999, 3)
    np.testing.assert_array_equal(loc.x, [0.0, 0.0, math.pi / 2])


def test_filter_is_consistent_on_synthetic_data():
    """Drive a synthetic robot whose odometry errors are drawn from the filter's own motion noise and
    observe landmarks with noise drawn from Q: the NEES is chi-square(3): its mean is about 3 and >= 90 %
    of the updates fall in the 95 % band."""
    rng = np.random.default_rng(7)
    # a moderate heading noise: with the default's 0.1 rad/sqrt(rad) the linearisation shows (mean NEES 3.6)
    cfg = LocalizerConfig(
        **NO_FLOOR,
        gate_prob=0.99999,
        sigma_heading_rad_per_sqrt_rad=0.06,
    )
    lms = landmark_map_from_scene("lab_room")
    nees = []
    for run in range(20):
        x_true = np.array([0.0, -3.0, math.pi / 2])
        loc = Localizer(
            x_true + rng.multivariate_normal(np.zeros(3), np.diag([1e-4, 1e-4, 7.6e-5])),
            np.diag([1e-4, 1e-4, 7.6e-5]),
            cfg,
        )
        for k in range(200):
            u = np.array([0.05, 0.0, 0.02 * math.sin(k / 10.0)])
            x_true = motion_model(x_true, u)
            loc.predict(rng.multivariate_normal(u, cfg.motion_noise(u)))
            if k % 10 == 9:
                lm = lms.landmarks[(k // 10 + run) % len(lms)]
                Q = np.diag([1e-4, 1e-4, math.radians(0.5) ** 2])
                z = measurement_model(x_true, lm.planar) + rng.multivariate_normal(np.zeros(3), Q)
                rec = loc.update(z, Q, lm)
                assert rec.accepted
                e = loc.x - x_true
                e[2] = wrap_angle(e[2])
                nees.append(e @ np.linalg.solve(loc.Sigma, e))
                assert np.all(np.linalg.eigvalsh(loc.Sigma) > 0) and np.allclose(loc.Sigma, loc.Sigma.T)
    nees = np.array(nees)
    assert 2.5 < nees.mean() < 3.5
    assert np.mean((nees >= chi2.ppf(0.025, 3)) & (nees <= chi2.ppf(0.975, 3))) >= 0.9


# --- stochastic cloning: a past pose corrected by what the robot sees later --------------------------


def test_a_cloned_pose_is_filterpys_ekf_on_the_joint_state():
    """Clone, drive two increments, one landmark update (the plain EKF): the clone and the moving pose
    are filterpy's ExtendedKalmanFilter on the 6-state ``[x, x_c]`` with ``H = [H, 0]``, predicted by
    ``F_joint = blockdiag(F, I)``."""
    cfg = LocalizerConfig(**NO_FLOOR, gate_prob=0.999999, update_iterations=1)
    lm = Landmark("p", (0.0, 3.94, 1.5), 0.0, (1.4, 0.02, 1.0), (0.0, -1.0))
    x0 = np.array([0.3, -1.0, 1.4])
    P0 = np.diag([0.09, 0.04, 0.01])
    loc = Localizer(x0, P0, cfg)
    loc.start_clone()
    ekf = ExtendedKalmanFilter(6, 3)
    ekf.x, ekf.P, ekf.R = np.concatenate([x0, x0]), np.block([[P0, P0], [P0, P0]]), None
    for u in ([0.4, 0.05, 0.3], [0.6, -0.02, -0.1]):
        loc.predict(u)
        F, V = motion_jacobians(ekf.x[:3], u)
        Fj = np.block([[F, np.zeros((3, 3))], [np.zeros((3, 3)), np.eye(3)]])
        Gj = np.vstack([V, np.zeros((3, 3))])
        ekf.x = np.concatenate([motion_model(ekf.x[:3], u), ekf.x[3:]])
        ekf.P = Fj @ ekf.P @ Fj.T + Gj @ cfg.motion_noise(u) @ Gj.T
    z = measurement_model(ekf.x[:3] + np.array([0.05, -0.03, 0.02]), lm.planar)
    Q = np.diag([1e-4, 2e-4, 1e-4])
    assert loc.update(z, Q, lm).accepted
    ekf.R = Q
    ekf.update(
        z,
        lambda s: np.hstack([measurement_jacobian(s[:3], lm.planar), np.zeros((3, 3))]),
        lambda s: measurement_model(s[:3], lm.planar),
    )
    x_c, S_c = loc.cloned_estimate()
    np.testing.assert_allclose(loc.x, ekf.x[:3], atol=1e-12)
    np.testing.assert_allclose(x_c, ekf.x[3:], atol=1e-12)
    np.testing.assert_allclose(loc.Sigma, ekf.P[:3, :3], atol=1e-12)
    np.testing.assert_allclose(S_c, ekf.P[3:, 3:], atol=1e-12)
    assert loc.cloning
    loc.end_clone()
    assert not loc.cloning
    with pytest.raises(ValueError, match="no pose is cloned"):
        loc.cloned_estimate()


def test_a_cloned_pose_is_corrected_by_a_landmark_seen_after_a_drive_and_stays_consistent():
    """The found-object case: a pose known to 20 cm and 3 deg is cloned, the robot drives 1.2 m and
    turns, then sees a landmark well (iterated updates, the default). Over 300 seeded runs the clone's
    error against the truth is chi-square(3) by its covariance (mean NEES about 3, >= 90 % in the 95 %
    band), and its position standard deviation drops to under a third of where it started."""
    rng = np.random.default_rng(11)
    cfg = LocalizerConfig(**NO_FLOOR, gate_prob=0.99999)
    lm = Landmark("p", (0.0, 3.94, 1.5), 0.0, (1.4, 0.02, 1.0), (0.0, -1.0))
    P0 = np.diag([0.2**2, 0.2**2, math.radians(3.0) ** 2])
    Q = np.diag([0.005**2, 0.005**2, math.radians(0.3) ** 2])
    nees, shrink = [], []
    for _ in range(300):
        x_true0 = np.array([0.5, 1.0, math.pi / 2])
        loc = Localizer(x_true0 + rng.multivariate_normal(np.zeros(3), P0), P0, cfg)
        loc.start_clone()
        x_true = x_true0.copy()
        for u in ([0.0, 0.0, 0.4], [0.6, 0.0, 0.0], [0.0, 0.0, -0.8], [0.6, 0.0, 0.0]):
            u = np.array(u)
            x_true = motion_model(x_true, u)
            loc.predict(rng.multivariate_normal(u, cfg.motion_noise(u)))
        z = measurement_model(x_true, lm.planar) + rng.multivariate_normal(np.zeros(3), Q)
        assert loc.update(z, Q, lm).accepted
        x_c, S_c = loc.end_clone()
        e = x_c - x_true0
        e[2] = wrap_angle(e[2])
        nees.append(e @ np.linalg.solve(S_c, e))
        shrink.append(math.sqrt(np.linalg.eigvalsh(S_c[:2, :2])[-1]) / 0.2)
    nees = np.array(nees)
    assert 2.5 < nees.mean() < 3.5, nees.mean()
    assert np.mean((nees >= chi2.ppf(0.025, 3)) & (nees <= chi2.ppf(0.975, 3))) >= 0.9
    assert max(shrink) < 1 / 3


def test_a_pose_cannot_be_cloned_before_a_measured_starts_first_sighting():
    loc = Localizer([0.0, 0.0, 0.0], first_sighting=True)
    with pytest.raises(ValueError, match="first landmark sighting"):
        loc.start_clone()


def test_motion_covariance_grows_with_distance_and_turning():
    cfg = LocalizerConfig()
    loc = Localizer([0, 0, 0], np.zeros((3, 3)), cfg)
    traces = []
    for _ in range(10):
        loc.predict([0.1, 0.0, 0.0])
        traces.append(np.trace(loc.Sigma))
    assert np.all(np.diff(traces) > 0)
    s = loc.Sigma[2, 2]
    loc.predict([0.0, 0.0, 1.0])
    assert loc.Sigma[2, 2] > s


def test_mode_parse_names_the_allowed_values():
    assert LocalizationMode.parse("odometry") is LocalizationMode.ODOMETRY
    with pytest.raises(ConfigError, match="odometry, landmarks"):
        LocalizationMode.parse("gps")


# --- the landmark map -------------------------------------------------------------------------------


def test_lab_room_landmarks_face_into_the_room():
    m = landmark_map_from_scene("lab_room")
    assert len(m) >= 3
    for lm in m:
        inward = -np.asarray(lm.centre_W[:2])
        assert np.dot(lm.normal_W, inward) > 0
        assert abs(lm.centre_W[0]) <= 3 and abs(lm.centre_W[1]) <= 4


_GOOD = """
room_size = [6.0, 8.0]
[[landmark]]
name = "a"
texture = "{tex}"
size = [1.4, 0.02, 1.0]
centre = [0.0, 3.94, 1.5]
yaw_deg = 0.0
"""


def _write(tmp_path, text):
    from lab.paths import worlds_dir

    p = tmp_path / "landmarks.toml"
    p.write_text(text.replace("{tex}", str(worlds_dir() / "textures" / "poster0.png")))
    return p


def test_landmark_file_loads(tmp_path):
    m = load_landmark_map(_write(tmp_path, _GOOD))
    assert m.names() == ["a"] and m.landmarks[0].normal_W == pytest.approx((0.0, -1.0))


@pytest.mark.parametrize(
    "edit, field",
    [
        (lambda t: t.replace('texture = "{tex}"', 'texture = "nope.png"'), "texture"),
        (lambda t: t + t.split("\n", 2)[2], "name"),  # the same [[landmark]] twice
        (lambda t: t.replace("[0.0, 3.94, 1.5]", "[0.0, 4.5, 1.5]"), "centre"),
        (lambda t: t.replace("yaw_deg", "yaw"), "unknown key"),
    ],
)
def test_bad_landmark_file_gives_one_line_naming_file_and_field(tmp_path, edit, field):
    p = _write(tmp_path, edit(_GOOD))
    with pytest.raises(ConfigError) as e:
        load_landmark_map(p)
    msg = str(e.value)
    assert "\n" not in msg and str(p) in msg and field in msg


def test_hardware_landmark_file_is_valid():
    from lab.paths import repo_root

    m = load_landmark_map(repo_root() / "hardware" / "landmarks.toml")
    assert len(m) >= 3


# --- the closed loop ----------------------------------------------------------------------------------


# --- how much of a landmark's face is in view ---------------------------------------------------------


@pytest.mark.parametrize(
    "size, yaw, normal", [((1.4, 0.02, 1.0), 0.0, (0.0, -1.0)), ((0.02, 1.2, 0.7), 0.3, None)]
)
def test_face_points_span_the_printed_side(size, yaw, normal):
    """The grid lies on the panel's side that looks along its normal, edge to edge."""
    if normal is None:  # a panel turned by yaw whose thin axis is x: the face looks along -x of L
        normal = tuple(-Rz(yaw)[:2, 0])
    lm = Landmark("p", (0.5, 1.0, 1.5), yaw, size, normal)
    P_W = (lm.G_WL[:3, :3] @ lm.face_points_L(5).T).T + lm.centre_W
    offset = (P_W[:, :2] - lm.centre_W[:2]) @ np.asarray(normal)
    assert np.allclose(offset, 0.5 * min(size[:2]))  # on the printed side, at half the thickness
    assert np.isclose(np.ptp(P_W[:, 2]), size[2])
    assert np.isclose(np.ptp((P_W[:, :2] - lm.centre_W[:2]) @ [-normal[1], normal[0]]), max(size[:2]))


def test_face_share_is_the_part_of_the_face_inside_the_image():
    """Straight ahead: all of it; the face's centre on the image's right edge: half (give or take the
    grid's middle column, on the edge); behind the camera: none."""
    from lab.robot import SIM_CAMERA

    cam = SIM_CAMERA.camera()
    lm = Landmark("p", (0.0, 0.0, 0.0), 0.0, (1.4, 0.02, 1.0), (0.0, -1.0))
    # L in C: the face (normal -y of L) towards the camera, 3 m down the optical axis (C: z forward)
    R_CL = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    assert face_share_in_image(lm, se3(R_CL, [0.0, 0.0, 3.0]), cam) == 1.0
    x_edge = (cam.width - cam.cx) * 3.0 / cam.fx  # the image's right edge at 3 m
    assert face_share_in_image(lm, se3(R_CL, [x_edge, 0.0, 3.0]), cam, n=15) == pytest.approx(0.5, abs=1 / 15)
    assert face_share_in_image(lm, se3(R_CL, [0.0, 0.0, -3.0]), cam) == 0.0


def test_a_fit_of_a_poster_mostly_outside_the_image_is_dropped():
    """Rendered: poster_east 1.3 m ahead. With the head turned 39 deg, under a third of it is in the
    image; its fit has inliers enough (the observer keeps it when any share will do) but is dropped
    below ``min_face_in_image`` and counted; straight ahead the same poster is kept. The share at the
    fitted pose is the share at the true pose."""
    from lab.sim import SimRobot, SimWorld
    from lab.training.landmarks import trained_landmark_map

    room = trained_landmark_map("lab_room", progress=False)
    lm = room.get("poster_east")
    start = Pose2D(1.6, 1.6, 0.0)
    with SimWorld("lab_room") as w:
        robot = SimRobot(w, start=start, seed=0)
        robot.enable()
        frames = {}
        for pan in (0.0, 39.0):
            robot.command_pan_tilt(math.radians(pan), 0.0)
            robot.wait_pan_tilt()
            frames[pan] = robot.capture_stereo()

    def observer(share):
        return LandmarkObserver(room, LocalizerConfig(min_face_in_image=share), np.random.default_rng(0))

    side = frames[39.0]
    true_share = face_share_in_image(lm, se3_inv(start.G() @ side.G_RC) @ lm.G_WL, side.camera)
    assert 0.2 < true_share < 0.4
    (kept,) = observer(0.0).observe(side, [lm])
    assert face_share_in_image(lm, kept.G_CL, side.camera) == pytest.approx(true_share, abs=0.05)
    strict = observer(0.5)
    assert strict.observe(side, [lm]) == [] and strict.n_partial == 1
    assert len(strict.observe(frames[0.0], [lm])) == 1 and strict.n_partial == 1


@pytest.mark.slow
def test_closed_loop_drive_localizes_against_the_truth():
    """A short seeded drive under realistic sensing: the localizer was updated and ends nearer the truth
    than odometry, within 8 cm and within three of its stated deviations times the profile's mismatch
    (the world draws its errors at that factor of what the filters are told); odometry mode reports the
    wheel odometry unchanged. (All 40 tuning drives of docs/tuning/localizer-camera-yaw.md hold this; the
    end's error there is 2.2 cm at the median, 6.9 cm at worst.)"""
    from lab.runs.localization import run_localization_drive
    from lab.sim.sensing import sensing_profile

    mismatch = sensing_profile("realistic").mismatch
    loc = run_localization_drive(3, "landmarks", length_m=6.0)
    assert loc.n_updates >= 5
    assert loc.localization_error_m < min(3 * mismatch * loc.sigma_xy_m, 0.08)
    assert loc.localization_error_m < loc.odometry_error_m
    odo = run_localization_drive(3, "odometry", length_m=3.0)
    assert odo.localization_error_m == odo.odometry_error_m and odo.n_updates == 0


# --- the object filters' motion under a localized pose -------------------------------------------------


class _FramedRobot(KinematicRobot):
    """The kinematic robot with a (blank) stereo camera: frames carry its wheel odometry."""

    def capture_stereo(self, after=None):
        cam = self.camera
        img = np.zeros((cam.height, cam.width, 3), np.uint8)
        return StereoFrame(self.now(), img, img, cam, self.pan_tilt(), self.odometry())


class _OneLandmarkObserver:
    """Sees one poster in every frame, as if the robot stood ``offset`` away from its wheel odometry."""

    def __init__(self, robot, offset):
        self.robot, self.offset = robot, np.asarray(offset, float)
        self.lm = Landmark("p", (0.0, 3.94, 1.5), 0.0, (1.4, 0.02, 1.0), (0.0, -1.0))

    def candidates(self, x, frame):
        return [self.lm]

    def observe(self, frame, candidates):
        z = measurement_model(frame.odom.as_array() + self.offset, self.lm.planar)
        return [LandmarkObservation(self.lm, np.eye(4), z, np.diag([1e-6, 1e-6, 1e-6]), 30)]


def test_a_landmark_update_between_frames_is_not_robot_motion():
    """Behind the localizer a frame's ``odom`` is the estimate, which a landmark update moves while the
    wheels stand still; ``frame_motion`` (what the object EKFs predict with) is the wheels' increment:
    the identity when they did not move, their increment when they did; and the EKF predicted with it
    equals the EKF predicted with the true (zero) motion."""
    from lab.estimation.ekf import PoseEKF

    base = _FramedRobot(Pose2D(0.3, -1.0, 1.4))
    # every look counted in full (shared_floor off): the fake observer's second look, from the same place,
    # would otherwise move the estimate by less than the assertion's 2 mm
    robot = LocalizedRobot(base, "odometry", config=LocalizerConfig(shared_floor=False))
    robot.mode = LocalizationMode.LANDMARKS  # the observer below stands in for a trained map
    robot.observer = _OneLandmarkObserver(robot, [0.06, -0.04, 0.02])
    f1 = robot.capture_stereo()
    f2 = robot.capture_stereo()  # the wheels did not move; the estimate did
    assert f1.wheel_odom == f2.wheel_odom == base.odometry()
    assert math.hypot(f2.odom.x - f1.odom.x, f2.odom.y - f1.odom.y) > 0.002
    np.testing.assert_allclose(frame_motion(f1, f2), np.eye(4), atol=1e-15)
    assert not np.allclose(relative_pose2d(f1.odom, f2.odom), np.eye(4), atol=1e-3)  # what it was

    def predicted(G_odom):
        ekf = PoseEKF(rng=np.random.default_rng(0))
        ekf.initialize(np.array([0.05, -0.02, 1.0, 0.3, -0.2, 0.1]), np.diag([1e-4] * 3 + [1e-3] * 3))
        ekf.predict(f1.G_RC, f2.G_RC, G_odom, 0.1)
        return ekf.estimate

    a, b = predicted(frame_motion(f1, f2)), predicted(np.eye(4))
    np.testing.assert_allclose(a.mu, b.mu, atol=1e-15)
    np.testing.assert_allclose(a.Sigma, b.Sigma, atol=1e-15)

    base.enable()
    for _ in range(20):  # the wheels move: 0.2 m/s for 1 s
        base.drive(0.2, 0.1)
        base.step(0.05)
    f3 = robot.capture_stereo()
    np.testing.assert_allclose(
        frame_motion(f2, f3), relative_pose2d(f2.wheel_odom, base.odometry()), atol=1e-12
    )
    assert frame_motion(f2, f3)[0, 3] > 0.1
    # in odometry mode frames are the base's own: the wheels are the odometry
    plain = LocalizedRobot(_FramedRobot(Pose2D(0.0, 0.0, 0.0)), "odometry").capture_stereo()
    assert plain.wheel_odom is None and plain.wheels == plain.odom


def test_a_landmark_correction_is_not_distance_driven():
    """The search's path length (``BudgetedRobot.path_length_m``) sums the wheels' path: a landmark
    updates that pull the estimate 7 cm ahead while the robot drives 0.36 m add nothing to it, though
    the estimate's own path is longer by them."""
    from lab.search.budget import BudgetedRobot

    base = _FramedRobot(Pose2D(0.3, -1.0, 1.4))
    robot = LocalizedRobot(base, "odometry")
    robot.mode = LocalizationMode.LANDMARKS
    robot.observer = _OneLandmarkObserver(robot, [0.01, 0.07, 0.0])  # ahead of the wheels
    budget = BudgetedRobot(robot, max_time_s=60.0)
    budget.enable()
    wheels, estimate = [base.odometry()], [robot.odometry()]
    for k in range(40):  # 0.2 m/s for 2 s, a frame (and so an update) every other step
        budget.drive(0.2, 0.0)
        budget.step(0.05)
        if k % 2 == 0:
            budget.capture_stereo()
        wheels.append(base.odometry())
        estimate.append(robot.odometry())

    def length(poses):
        return sum(math.hypot(b.x - a.x, b.y - a.y) for a, b in zip(poses[:-1], poses[1:], strict=True))

    assert robot.localizer.n_updates == 20
    assert 0.3 < length(wheels) <= 0.4  # (the base accelerates at its slew limit)
    assert budget.path_length_m == pytest.approx(length(wheels), abs=1e-9)
    assert length(estimate) > length(wheels) + 0.03  # what the path length used to sum
    assert budget.wheel_odometry() == base.odometry() and robot.wheel_odometry() == base.odometry()


@pytest.mark.parametrize("r, bearing_deg", [(0.8, 0.0), (2.0, 35.0), (4.5, -120.0), (7.0, 170.0)])
def test_the_observation_floor_is_long_along_the_line_of_sight(r, bearing_deg):
    """The floor's position ellipse has its axes along and across the line of sight to the landmark,
    with the standard deviations the attributes give at that range; the heading's is apart."""
    cfg = LocalizerConfig()
    a = math.radians(bearing_deg)
    Q = cfg.observation_floor([r * math.cos(a), r * math.sin(a), 0.3])
    u, v = np.array([math.cos(a), math.sin(a)]), np.array([-math.sin(a), math.cos(a)])
    s_along = cfg.obs_sigma_m + cfg.obs_sigma_rel * r + cfg.obs_sigma_per_m * r * r
    s_across = cfg.obs_sigma_m + cfg.obs_sigma_rel_across * r
    assert u @ Q[:2, :2] @ u == pytest.approx(s_along**2, rel=1e-12)
    assert v @ Q[:2, :2] @ v == pytest.approx(s_across**2, rel=1e-12)
    assert u @ Q[:2, :2] @ v == pytest.approx(0.0, abs=1e-15)
    assert Q[2, 2] == cfg.obs_sigma_rad**2 and not Q[:2, 2].any() and np.array_equal(Q, Q.T)
    assert s_along > s_across  # stereo measures range worse than bearing
    assert not LocalizerConfig(**NO_FLOOR).observation_floor([r, 0.0, 0.0]).any()


def test_point_sigma_matches_a_monte_carlo_of_the_pose():
    """The standard deviation of a point the robot places 0.8 m ahead, from the pose covariance, against
    the spread of that point over 200 000 poses drawn from it (the point fixed in the robot frame)."""
    rng = np.random.default_rng(5)
    pose = Pose2D(0.4, -1.2, 0.7)
    A = rng.normal(size=(3, 3)) * np.array([0.02, 0.02, 0.01])
    Sigma = A @ A.T + np.diag([1e-4, 1e-4, 1e-5])
    p_R = np.array([0.8, 0.1])
    c, s = math.cos(pose.theta), math.sin(pose.theta)
    p_W = np.array([pose.x + c * p_R[0] - s * p_R[1], pose.y + s * p_R[0] + c * p_R[1]])
    x = rng.multivariate_normal(pose.as_array(), Sigma, size=200_000)
    cs, sn = np.cos(x[:, 2]), np.sin(x[:, 2])
    pts = np.stack([x[:, 0] + cs * p_R[0] - sn * p_R[1], x[:, 1] + sn * p_R[0] + cs * p_R[1]], axis=1)
    mc = math.sqrt(np.linalg.eigvalsh(np.cov(pts.T))[-1])
    est = PlanarPoseEstimate(pose, Sigma)
    assert est.point_sigma_m(p_W) == pytest.approx(mc, rel=0.01)
    assert est.point_sigma_m([pose.x, pose.y]) == pytest.approx(est.sigma_xy_m, rel=1e-9)


# --- re-localization before a report -------------------------------------------------------------------


class _HeadRobot(_FramedRobot):
    """The framed kinematic robot with a head that is where it was told at once."""

    head = (0.0, 0.0)

    def pan_tilt(self):
        return PanTiltState(*self.head, self.now(), *self.head)

    def command_pan_tilt(self, pan, tilt, speed=None):
        self.head = (float(pan), float(tilt))


class _PosterObserver:
    """Sees the room's poster the head points at, as from the robot's true pose, with noise drawn from
    the covariance the filter is told (the fit's ``Q`` plus the localizer's floor)."""

    def __init__(self, robot, landmarks, config, rng):
        self.robot, self.map, self.config, self.rng = robot, landmarks, config, rng
        self.Q = np.diag([0.02**2, 0.02**2, math.radians(0.8) ** 2])
        self.seen: dict[str, int] = {}

    def candidates(self, x, frame):
        true = self.robot.odometry().as_array()
        out = []
        for lm in self.map:
            _, bearing = self.map.bearing_in_robot(lm, true)
            if abs(wrap_angle(bearing - frame.pan_tilt.pan)) < math.radians(5.0):
                out.append(lm)
        return out

    outlier: str | None = None  # a poster always fitted 2 m off (a look-alike's features)

    def observe(self, frame, candidates):
        true = self.robot.odometry().as_array()
        out = []
        for lm in candidates:
            self.seen[lm.name] = self.seen.get(lm.name, 0) + 1
            z0 = measurement_model(true, lm.planar) + ([0.0, 2.0, 0.4] if lm.name == self.outlier else 0.0)
            C = self.Q + self.config.observation_floor(z0)
            z = z0 + self.rng.multivariate_normal(np.zeros(3), C)
            out.append(LandmarkObservation(lm, np.eye(4), z, self.Q, 30))
        return out


def test_report_relocalization_gets_the_object_point_within_the_report_sigma():
    """A robot by the shelf, its estimate 12 cm and 3 deg off with a covariance that says so: the
    ordinary re-localization stops at 5 cm, short of the report's 1.5 cm at a point 0.8 m ahead; the
    report's goes on, ends within it there, and the point's error is within 3 of its sigmas (30 seeds:
    the covariance at the point is honest, checked against the point's true position)."""
    room = landmark_map_from_scene("lab_room")
    cfg = LocalizerConfig()
    misses, point_sigmas = 0, []
    for seed in range(30):
        true = Pose2D(-1.7, 2.6, math.pi)
        base = _HeadRobot(true)
        base.enable()
        robot = LocalizedRobot(base, "odometry", config=cfg)
        robot.mode = LocalizationMode.LANDMARKS  # the observer below stands in for a trained map
        robot.observer = _PosterObserver(base, room, cfg, np.random.default_rng(seed))
        robot.localizer.x = true.as_array() + np.array([0.1, -0.07, math.radians(3.0)])
        robot.localizer.Sigma = np.diag([0.1**2, 0.1**2, math.radians(4.0) ** 2])
        p_W = np.array([true.x - 0.8, true.y])  # the object 0.8 m ahead
        assert robot.relocalize()
        if seed == 0:
            assert robot.pose_estimate().point_sigma_m(p_W) > cfg.report_sigma_m
        robot.relocalize_to_report(at_W=p_W)
        est = robot.pose_estimate()
        s = est.point_sigma_m(p_W)
        point_sigmas.append(s)
        # the object's point as the robot places it (fixed in R) against where it is
        p_R = relative_pose2d(true, Pose2D(*p_W, 0.0))[:2, 3]
        p_est = est.pose.G()[:2, :2] @ p_R + [est.pose.x, est.pose.y]
        misses += np.linalg.norm(p_est - p_W) > 3.0 * s
    assert max(point_sigmas) <= cfg.report_sigma_m + 1e-12
    assert misses <= 2, misses  # 3 sigma on the larger axis: rarely outside


def test_later_report_passes_look_only_where_a_landmark_was_accepted():
    """A poster whose fit is always 2 m off (an outlier the gate rejects) is looked at once, not once
    per pass: three rejections in a row of the same view would inflate the covariance (the gate
    lock-out recovery) although the robot has not moved; the good posters are looked at again. The map
    leaves out poster_north_west: with it, one pass reaches the report's sigma here and there is no later
    pass to test."""
    room = landmark_map_from_scene("lab_room")
    room = replace(room, landmarks=tuple(lm for lm in room if lm.name != "poster_north_west"))
    cfg = LocalizerConfig()
    true = Pose2D(-1.7, 2.6, math.pi)
    base = _HeadRobot(true)
    base.enable()
    robot = LocalizedRobot(base, "odometry", config=cfg, log=lambda m: None)
    robot.mode = LocalizationMode.LANDMARKS
    robot.observer = obs = _PosterObserver(base, room, cfg, np.random.default_rng(1))
    names = [v[2] for v in robot.landmark_views()]
    obs.outlier = names[0]
    robot.localizer.Sigma = np.diag([0.04**2, 0.04**2, math.radians(0.4) ** 2])
    robot.relocalize_to_report(at_W=[true.x - 0.8, true.y])
    assert obs.seen[names[0]] == 1
    assert max(obs.seen.get(n, 0) for n in names[1:]) >= 2
    assert robot.localizer.n_inflations == 0
    assert not any(r.accepted for r in robot.localizer.history if r.landmark == names[0])


# --- the detour before a report: no landmark seen well where the object was found ---------------------


class _NearPosterObserver(_PosterObserver):
    """Sees a poster only when it is 1-4 m away and at most 60 deg off its normal (a little more than
    :meth:`LocalizedRobot.landmark_vantage_points` asks of a place), the head within 10 deg of it."""

    def candidates(self, x, frame):
        true = self.robot.odometry().as_array()
        out = []
        for lm in self.map:
            r, bearing = self.map.bearing_in_robot(lm, true)
            seen_well = 1.0 <= r <= 4.0 and lm.facing(true[:2]) >= 0.5
            if seen_well and abs(wrap_angle(bearing - frame.pan_tilt.pan)) < math.radians(10.0):
                out.append(lm)
        return out


def _driving_navigate(robot, base, free=lambda x, y: True):
    """``navigate(target_xy, min_distance, max_distance)`` that steers the kinematic robot (by its true
    pose) to the target through ``robot``, so the localizer predicts from its odometry on the way; its
    ``navigator.planning_grid()`` is the room's floor, blocked where ``free`` says."""
    from types import SimpleNamespace

    from lab.navigation.costmap import CostGrid
    from lab.navigation.grid import GridSpec

    spec = GridSpec.from_bounds(-3.0, -4.0, 3.0, 4.0, 0.1)
    X, Y = spec.cell_centers()
    cost = np.where(np.vectorize(free)(X, Y), 1.0, np.inf)
    goals = []

    def navigate(target_xy, min_distance, max_distance):
        goals.append(tuple(target_xy))
        for _ in range(3000):
            p = base.odometry()  # the kinematic robot's odometry is its true pose
            dx, dy = target_xy[0] - p.x, target_xy[1] - p.y
            if math.hypot(dx, dy) <= max(max_distance, 0.05):
                break
            err = wrap_angle(math.atan2(dy, dx) - p.theta)
            robot.drive(0.3 * max(0.0, math.cos(err)), float(np.clip(2.0 * err, -1.0, 1.0)))
            robot.step(0.05)
        robot.stop()
        return SimpleNamespace(arrived=math.hypot(dx, dy) <= max(max_distance, 0.05))

    navigate.navigator = SimpleNamespace(planning_grid=lambda: CostGrid(spec, cost))
    navigate.goals = goals
    return navigate


def _found_far_from_landmarks(seed: int, offset=(0.25, -0.2, 0.035)):
    """A robot in the room's north-east corner, (2.5, 3.5), facing west, where no poster is seen, its
    estimate ``offset`` [m, m, rad] off with a covariance that says about that; an object found 0.8 m
    ahead, placed from the estimate."""
    from lab.search.agent import AgentResult

    room = landmark_map_from_scene("lab_room")
    cfg = LocalizerConfig()
    true = Pose2D(2.5, 3.5, math.pi)
    base = _HeadRobot(true)
    base.enable()
    robot = LocalizedRobot(base, "odometry", config=cfg, log=lambda m: None)
    robot.mode = LocalizationMode.LANDMARKS  # the observer below stands in for a trained map
    robot.observer = _NearPosterObserver(base, room, cfg, np.random.default_rng(seed))
    robot.localizer.x = true.as_array() + np.asarray(offset)
    robot.localizer.Sigma = np.diag([0.3**2, 0.3**2, math.radians(3.0) ** 2])
    G_RO = se3(Rz(0.3), [0.8, 0.0, 0.5])
    found = AgentResult(True, "found", G_WO=Pose2D(*robot.localizer.x).G() @ G_RO)
    return robot, base, found, true.G() @ G_RO


def test_a_find_where_no_landmark_is_seen_is_reported_from_the_kept_pose_after_a_detour():
    """The estimate is 32 cm off where the object was found and no poster is seen well from there: the
    report's re-localization alone leaves it so. The detour keeps that pose in the filter, drives at
    most 1.5 m to a poster (the corner leaves none nearer), and the poster corrects the kept pose: over
    10 seeds the reported object is within the search's 5 cm of the truth (from about 30 cm) and its
    position standard deviation says so (the error within 3 of them; the odometry of a 1.5 m drive
    leaves about 3 cm), and the robot is where the detour said it would go."""
    from lab.search.report_policy import ReportPolicy

    for seed in range(10):
        robot, base, found, G_WO_true = _found_far_from_landmarks(seed)
        p0 = robot.pose_estimate().pose
        navigate = _driving_navigate(robot, base)
        res, info = ReportPolicy(robot, navigate, navigate.navigator).report(found)
        before = np.linalg.norm(found.G_WO[:3, 3] - G_WO_true[:3, 3])
        after = np.linalg.norm(res.G_WO[:3, 3] - G_WO_true[:3, 3])
        d = info["detour"]
        assert before > 0.25 and after < 0.05, (seed, before, after, info)
        assert after <= 3.0 * info["point_sigma_after_m"] and info["point_sigma_after_m"] < 0.05
        assert d["arrived"] and d["updates"] >= 1 and d["stopped"] is None
        assert navigate.goals[0] == pytest.approx(d["to"], abs=1e-3)
        assert math.hypot(d["to"][0] - p0.x, d["to"][1] - p0.y) <= robot.config.report_detour_m + 1e-3
        true_now = base.odometry()
        assert math.hypot(true_now.x - d["to"][0], true_now.y - d["to"][1]) < 0.3
        assert not robot.localizer.cloning


def test_no_detour_without_a_place_to_go_and_the_find_is_reported_as_it_was():
    """Every place within reach blocked: the detour says so, the robot stays, the report is unchanged;
    with report_detour_m = 0 there is none at all."""
    from lab.search.report_policy import ReportPolicy

    robot, base, found, _ = _found_far_from_landmarks(0)
    here = base.odometry()
    navigate = _driving_navigate(robot, base, free=lambda x, y: math.hypot(x - here.x, y - here.y) < 0.3)
    res, info = ReportPolicy(robot, navigate, navigate.navigator).report(found)
    assert info["detour"]["stopped"] == "no place within reach sees a landmark well"
    assert not info["detour"]["arrived"] and navigate.goals == []
    np.testing.assert_allclose(res.G_WO, found.G_WO)
    robot.config = replace(robot.config, report_detour_m=0.0)
    res, info = ReportPolicy(robot, navigate, navigate.navigator).report(found)
    assert info["detour"] is None and navigate.goals == []


def test_a_find_known_to_a_few_centimetres_makes_no_detour():
    """The point's sigma is above the report's 1.5 cm but below ``report_detour_above_m`` (a detour's own
    odometry would leave about as much): no detour, the robot stays."""
    from lab.search.report_policy import ReportPolicy

    robot, base, found, _ = _found_far_from_landmarks(0, offset=(0.01, -0.01, 0.002))
    robot.localizer.Sigma = np.diag([0.02**2, 0.02**2, math.radians(0.5) ** 2])
    navigate = _driving_navigate(robot, base)
    res, info = ReportPolicy(robot, navigate, navigate.navigator).report(found)
    assert robot.config.report_sigma_m < info["point_sigma_after_m"] < robot.config.report_detour_above_m
    assert info["detour"] is None and navigate.goals == []
    np.testing.assert_allclose(res.G_WO, found.G_WO)
