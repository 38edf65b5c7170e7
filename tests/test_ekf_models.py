"""The EKF's models against independent peers: SciPy rotations, finite differences, world geometry.

* measurement model Eq. (3) against SciPy's intrinsic "ZYX" rotation;
* every analytic Jacobian (C, F, L_O, L_R, E) against central finite differences, tight tolerance;
* the motion model Eq. (1) against the same scene composed directly in the world frame with
  lab.geometry (robot poses, pan-tilt kinematics, object pose), and its static case Eq. (4).
"""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from lab.estimation import (
    ObjectNoiseKind,
    OrientationChart,
    ProcessNoise,
    euler_rate_matrix,
    euler_rate_matrix_inv,
    euler_to_rv_jacobian,
    measurement_covariance,
    measurement_jacobian,
    measurement_jacobian_rv,
    measurement_model,
    motion_jacobian,
    motion_model,
    motion_noise_jacobians,
    odometry_covariance,
    process_noise_covariance,
    retract_rv,
    rotvec_to_R,
    rv_to_euler_jacobian,
    state_residual,
)
from lab.estimation.models import canonical_state
from lab.geometry import G_to_pose6, Pose2D, euler_zyx_to_R, pose6_to_G, relative_pose2d, se3, se3_inv
from lab.robot import StereoCamera

CAM = StereoCamera.from_fov(320, 240, 60.0, baseline=0.12)

# states away from gimbal lock (|beta| <= 1.3 rad, cos(beta) >= 0.27)
state = st.tuples(
    st.floats(-2, 2),
    st.floats(-2, 2),
    st.floats(0.2, 3),
    st.floats(-np.pi, np.pi),
    st.floats(-1.3, 1.3),
    st.floats(-np.pi, np.pi),
).map(np.array)
seed = st.integers(0, 2**32 - 1)


def central_diff(f, x, h=1e-6, angle_out=True):
    """Central differences of f at x, shape (len(f(x)), len(x)); output angles differenced on the circle."""
    cols = []
    for i in range(len(x)):
        e = np.zeros(len(x))
        e[i] = h
        diff = f(x + e) - f(x - e)
        if angle_out:
            diff[3:] = (diff[3:] + np.pi) % (2 * np.pi) - np.pi
        cols.append(diff / (2 * h))
    return np.stack(cols, axis=1)


def random_G(rng, trans=1.0, ang=np.pi):
    R = Rotation.from_rotvec(rng.uniform(-1, 1, 3) * ang / np.sqrt(3)).as_matrix()
    return se3(R, rng.normal(0, trans, 3))


# ------------------------------------------------------------------ measurement model, Eq. (3)
@settings(max_examples=100, deadline=None)
@given(state, seed)
def test_measurement_model_matches_scipy_rotation(X, s):
    b = np.random.default_rng(s).uniform(-0.2, 0.2, (7, 3))
    expected = Rotation.from_euler("ZYX", X[3:]).apply(b) + X[:3]
    np.testing.assert_allclose(measurement_model(X, b), expected, atol=1e-12)


@settings(max_examples=100, deadline=None)
@given(state, seed)
def test_measurement_jacobian_matches_central_differences(X, s):
    b = np.random.default_rng(s).uniform(-0.3, 0.3, (9, 3))
    C = measurement_jacobian(X, b)
    assert C.shape == (27, 6)
    C_fd = central_diff(lambda x: measurement_model(x, b).reshape(-1), X, angle_out=False)
    np.testing.assert_allclose(C, C_fd, rtol=1e-6, atol=1e-9)


@settings(max_examples=100, deadline=None)
@given(st.floats(-np.pi, np.pi), st.floats(-1.4, 1.4), st.floats(-np.pi, np.pi))
def test_euler_rate_matrix_is_the_angular_velocity_map(a, b, g):
    """omega from dR/dt R^T (finite differences) equals E * (Euler rates), and E^-1 inverts E."""
    x = np.array([a, b, g])
    rates = np.array([0.3, -0.7, 1.1])
    h = 1e-6
    Rdot = (euler_zyx_to_R(*(x + h * rates)) - euler_zyx_to_R(*(x - h * rates))) / (2 * h)
    W = Rdot @ euler_zyx_to_R(*x).T
    omega = np.array([W[2, 1], W[0, 2], W[1, 0]])
    np.testing.assert_allclose(euler_rate_matrix(a, b) @ rates, omega, atol=1e-8)
    np.testing.assert_allclose(euler_rate_matrix_inv(a, b) @ euler_rate_matrix(a, b), np.eye(3), atol=1e-9)


def test_measurement_covariance_is_block_diagonal():
    rng = np.random.default_rng(1)
    A = rng.normal(size=(4, 3, 3))
    S = A @ np.swapaxes(A, 1, 2)
    Sm = measurement_covariance(S)
    assert Sm.shape == (12, 12)
    for i in range(4):
        for j in range(4):
            blk = Sm[3 * i : 3 * i + 3, 3 * j : 3 * j + 3]
            np.testing.assert_array_equal(blk, S[i] if i == j else 0.0)


# ---------------------------------------------------------------------- motion model, Eqs. (1)-(2)
def test_motion_model_matches_world_geometry():
    """A static object seen by a robot that drives and re-points its pan-tilt: X_k from Eq. (1) equals
    the pose composed directly in the world frame, and so does a moving object with G_OO given."""
    G_WO = se3(euler_zyx_to_R(0.7, 0.2, -0.1), (2.0, 0.5, 0.4))
    a, b = Pose2D(0.3, -0.2, 0.4), Pose2D(0.55, 0.1, 0.65)
    G_RC_a, G_RC_b = CAM.G_RC(0.2, -0.1), CAM.G_RC(-0.15, -0.3)
    X_a = G_to_pose6(se3_inv(a.G() @ G_RC_a) @ G_WO)
    X_b = G_to_pose6(se3_inv(b.G() @ G_RC_b) @ G_WO)
    X_pred = motion_model(X_a, G_RC_a, G_RC_b, relative_pose2d(a, b))
    np.testing.assert_allclose(state_residual(X_pred, X_b), 0.0, atol=1e-12)

    G_OO = se3(euler_zyx_to_R(0.1, 0.0, 0.0), (0.05, -0.02, 0.0))  # the object's own motion, in O(k-1)
    X_b_moved = G_to_pose6(se3_inv(b.G() @ G_RC_b) @ G_WO @ G_OO)
    X_pred = motion_model(X_a, G_RC_a, G_RC_b, relative_pose2d(a, b), G_OO)
    np.testing.assert_allclose(state_residual(X_pred, X_b_moved), 0.0, atol=1e-12)


def test_static_case_is_the_search_papers_eq4():
    """Identity increments: X_k = X_{k-1}, F = I, and with dt = 0 Q is Eq. (4)'s eta alone."""
    X = np.array([0.1, -0.05, 1.2, 0.3, -0.4, 2.0])
    I = np.eye(4)
    G_RC = CAM.G_RC(0.1, -0.2)
    np.testing.assert_allclose(motion_model(X, G_RC, G_RC, I), X, atol=1e-14)
    np.testing.assert_allclose(motion_jacobian(X, G_RC, G_RC, I), np.eye(6), atol=1e-14)
    noise = ProcessNoise(eta_m=0.003, eta_rad=0.01)
    Q = process_noise_covariance(X, G_RC, I, 0.0, noise)
    np.testing.assert_allclose(Q, np.diag([0.003**2] * 3 + [0.01**2] * 3), atol=1e-18)


@settings(max_examples=100, deadline=None)
@given(state, seed, st.booleans())
def test_motion_jacobian_matches_central_differences(X, s, with_object_motion):
    rng = np.random.default_rng(s)
    G_RC_prev = CAM.G_RC(*rng.uniform(-1, 0.5, 2))
    G_RC = CAM.G_RC(*rng.uniform(-1, 0.5, 2))
    G_odom = se3(euler_zyx_to_R(rng.uniform(-0.5, 0.5), 0, 0), (*rng.normal(0, 0.3, 2), 0.0))
    G_OO = random_G(rng, 0.1, 0.3) if with_object_motion else None
    args = (G_RC_prev, G_RC, G_odom, G_OO)
    X_k = motion_model(X, *args)
    if abs(np.cos(X_k[4])) < 0.25:  # the output near gimbal lock: Euler angles are ill-conditioned there
        return
    F = motion_jacobian(X, *args)
    F_fd = central_diff(lambda x: motion_model(x, *args), X)
    np.testing.assert_allclose(F, F_fd, rtol=1e-6, atol=1e-8)


def _exp(delta):
    """A first-order-exact SE(3) perturbation (translation, rotation vector), via SciPy."""
    return se3(Rotation.from_rotvec(delta[3:]).as_matrix(), delta[:3])


@settings(max_examples=60, deadline=None)
@given(state, seed)
def test_noise_jacobians_match_central_differences(X_prev, s):
    """L_O: object twist in O(k) on G_OO; L_R: odometry error twist in R(k) on G_odom."""
    rng = np.random.default_rng(s)
    G_RC_prev, G_RC = CAM.G_RC(*rng.uniform(-1, 0.5, 2)), CAM.G_RC(*rng.uniform(-1, 0.5, 2))
    G_odom = se3(euler_zyx_to_R(rng.uniform(-0.5, 0.5), 0, 0), (*rng.normal(0, 0.3, 2), 0.0))
    X_k = motion_model(X_prev, G_RC_prev, G_RC, G_odom)
    if abs(np.cos(X_k[4])) < 0.25:
        return
    L_O, L_R = motion_noise_jacobians(X_k, G_RC)
    L_O_fd = central_diff(lambda d: motion_model(X_prev, G_RC_prev, G_RC, G_odom, _exp(d)), np.zeros(6))
    L_R_fd = central_diff(lambda d: motion_model(X_prev, G_RC_prev, G_RC, G_odom @ _exp(d)), np.zeros(6))
    np.testing.assert_allclose(L_O, L_O_fd, rtol=1e-6, atol=1e-8)
    np.testing.assert_allclose(L_R, L_R_fd, rtol=1e-6, atol=1e-8)


def test_process_noise_matches_monte_carlo():
    """Q against the sample covariance of X_k when the object's velocity and the odometry are drawn
    from the stated model and pushed through the exact (nonlinear) composition of Eq. (1)."""
    rng = np.random.default_rng(5)
    X_prev = np.array([0.1, 0.05, 1.1, 0.4, 0.3, -0.6])
    G_RC_prev, G_RC = CAM.G_RC(0.1, -0.2), CAM.G_RC(0.25, -0.25)
    G_odom = relative_pose2d(Pose2D(0, 0, 0), Pose2D(0.1, 0.01, 0.08))
    noise = ProcessNoise(sigma_v=0.1, sigma_w=0.2, eta_m=0.0, eta_rad=0.0, odom_trans_per_m=0.2)
    dt = 0.5
    Q = process_noise_covariance(motion_model(X_prev, G_RC_prev, G_RC, G_odom), G_RC, G_odom, dt, noise)
    Sod = odometry_covariance(G_odom, noise)
    n = 12000
    obj = rng.normal(size=(n, 6)) * np.r_[[noise.sigma_v] * 3, [noise.sigma_w] * 3] * dt  # v dt, w dt
    odo = rng.normal(size=(n, 6)) * np.sqrt(np.diag(Sod))
    Xs = np.array(
        [
            motion_model(X_prev, G_RC_prev, G_RC, G_odom @ _exp(o), _exp(v))
            for v, o in zip(obj, odo, strict=True)
        ]
    )
    mean = Xs.mean(axis=0)
    dev = np.array([state_residual(x, mean) for x in Xs])
    Q_mc = dev.T @ dev / (n - 1)
    sd = np.sqrt(np.diag(Q))
    # correlation-scale comparison; the MC standard error is about 1/sqrt(n) ~ 0.009
    np.testing.assert_allclose(Q_mc / np.outer(sd, sd), Q / np.outer(sd, sd), atol=0.05)


def test_process_noise_kinds_scale_with_dt():
    X = np.array([0.0, 0.0, 1.0, 0.2, 0.1, 0.3])
    G_RC, I = CAM.G_RC(0.0, 0.0), np.eye(4)
    zero_floor = {"eta_m": 0.0, "eta_rad": 0.0}
    vel = ProcessNoise(ObjectNoiseKind.VELOCITY, **zero_floor)
    wie = ProcessNoise(ObjectNoiseKind.WIENER, **zero_floor)
    Qv1, Qv2 = (process_noise_covariance(X, G_RC, I, dt, vel) for dt in (0.1, 0.2))
    Qw1, Qw2 = (process_noise_covariance(X, G_RC, I, dt, wie) for dt in (0.1, 0.2))
    np.testing.assert_allclose(Qv2, 4 * Qv1, rtol=1e-12)  # variance ~ dt^2
    np.testing.assert_allclose(Qw2, 2 * Qw1, rtol=1e-12)  # variance ~ dt
    np.testing.assert_allclose(np.diag(Qv1)[:3], (0.15 * 0.1) ** 2, rtol=1e-12)  # isotropic in position


# --------------------------------------------------------------------------- angles and shapes
@settings(max_examples=100, deadline=None)
@given(state)
def test_canonical_state_keeps_the_rotation_and_flips_beta_covariance(X):
    X_alt = X.copy()
    X_alt[3] += np.pi
    X_alt[4] = np.pi - X[4]  # the same rotation with beta outside [-pi/2, pi/2]
    X_alt[5] -= np.pi
    np.testing.assert_allclose(pose6_to_G(X_alt), pose6_to_G(X), atol=1e-12)
    Sigma = np.diag(np.arange(1.0, 7.0)) + 0.1
    Xc, Sc = canonical_state(X_alt, Sigma)
    np.testing.assert_allclose(pose6_to_G(Xc), pose6_to_G(X), atol=1e-12)
    assert -np.pi / 2 <= Xc[4] <= np.pi / 2 and -np.pi < Xc[3] <= np.pi and -np.pi < Xc[5] <= np.pi
    J = np.diag([1, 1, 1, 1, -1, 1.0])  # d canonical / d X_alt
    np.testing.assert_allclose(Sc, J @ Sigma @ J.T, atol=1e-15)


def test_wrong_shapes_raise_value_error():
    X = np.zeros(6)
    with pytest.raises(ValueError, match="shape"):
        measurement_model(np.zeros(5), np.zeros((3, 3)))
    with pytest.raises(ValueError, match=r"\(n, 3\)"):
        measurement_jacobian(X, np.zeros((3, 2)))
    with pytest.raises(ValueError, match="4x4"):
        motion_model(X, np.eye(3), np.eye(4), np.eye(4))
    with pytest.raises(ValueError, match=r"\(n, 3, 3\)"):
        measurement_covariance(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="Sigma_odom"):
        process_noise_covariance(X, np.eye(4), np.eye(4), 0.1, ProcessNoise(), Sigma_odom=np.eye(3))


# ------------------------------------------------------------- the rotation-vector chart
# includes exact gimbal lock (beta = +-pi/2), where this chart is still well defined
state_any = st.tuples(
    st.floats(-2, 2),
    st.floats(-2, 2),
    st.floats(0.2, 3),
    st.floats(-np.pi, np.pi),
    st.sampled_from([np.pi / 2, -np.pi / 2, 0.3]) | st.floats(-1.57, 1.57),
    st.floats(-np.pi, np.pi),
).map(np.array)


def local_diff(X_a, X_b):
    """[x_a - x_b, Log(R_a R_b^T)] via SciPy: the rotation-vector chart's difference."""
    R = pose6_to_G(X_a)[:3, :3] @ pose6_to_G(X_b)[:3, :3].T
    return np.concatenate([X_a[:3] - X_b[:3], Rotation.from_matrix(R).as_rotvec()])


def central_diff_local(f, X0, h=1e-6):
    """Central differences of X(delta) -> local_diff(X(delta), X(0)) at delta = 0."""
    f0 = f(np.zeros(6))
    cols = []
    for i in range(6):
        e = np.zeros(6)
        e[i] = h
        cols.append((local_diff(f(e), f0) - local_diff(f(-e), f0)) / (2 * h))
    return np.stack(cols, axis=1)


@settings(max_examples=100, deadline=None)
@given(st.lists(st.floats(-3, 3), min_size=3, max_size=3), st.sampled_from([1.0, 1e-3, 1e-7, 0.0]))
def test_rotvec_to_R_matches_scipy(v, scale):
    phi = np.array(v) * scale
    np.testing.assert_allclose(rotvec_to_R(phi), Rotation.from_rotvec(phi).as_matrix(), atol=1e-14)


@settings(max_examples=100, deadline=None)
@given(state_any, seed)
def test_rv_measurement_jacobian_matches_central_differences(X, s):
    b = np.random.default_rng(s).uniform(-0.3, 0.3, (9, 3))
    C = measurement_jacobian_rv(X, b)
    C_fd = central_diff(
        lambda dl: measurement_model(retract_rv(X, dl), b).reshape(-1), np.zeros(6), angle_out=False
    )
    np.testing.assert_allclose(C, C_fd, rtol=1e-6, atol=1e-9)
    # and it is the Euler Jacobian seen through T^-1 (away from gimbal lock)
    if abs(np.cos(X[4])) > 0.1:
        np.testing.assert_allclose(C, measurement_jacobian(X, b) @ rv_to_euler_jacobian(X), atol=1e-9)


@settings(max_examples=100, deadline=None)
@given(state_any, seed, st.booleans())
def test_rv_motion_and_noise_jacobians_match_central_differences(X, s, with_object_motion):
    rng = np.random.default_rng(s)
    G_RC_prev, G_RC = CAM.G_RC(*rng.uniform(-1, 0.5, 2)), CAM.G_RC(*rng.uniform(-1, 0.5, 2))
    G_odom = se3(euler_zyx_to_R(rng.uniform(-0.5, 0.5), 0, 0), (*rng.normal(0, 0.3, 2), 0.0))
    G_OO = random_G(rng, 0.1, 0.3) if with_object_motion else None
    rv = OrientationChart.ROTATION_VECTOR
    F = motion_jacobian(X, G_RC_prev, G_RC, G_odom, G_OO, chart=rv)
    F_fd = central_diff_local(lambda dl: motion_model(retract_rv(X, dl), G_RC_prev, G_RC, G_odom, G_OO), X)
    np.testing.assert_allclose(F, F_fd, rtol=1e-6, atol=1e-8)
    X_k = motion_model(X, G_RC_prev, G_RC, G_odom, G_OO)
    L_O, L_R = motion_noise_jacobians(X_k, G_RC, chart=rv)
    G_OO_ = np.eye(4) if G_OO is None else G_OO
    L_O_fd = central_diff_local(lambda dl: motion_model(X, G_RC_prev, G_RC, G_odom, G_OO_ @ _exp(dl)), X)
    L_R_fd = central_diff_local(lambda dl: motion_model(X, G_RC_prev, G_RC, G_odom @ _exp(dl), G_OO), X)
    np.testing.assert_allclose(L_O, L_O_fd, rtol=1e-6, atol=1e-8)
    np.testing.assert_allclose(L_R, L_R_fd, rtol=1e-6, atol=1e-8)


@settings(max_examples=50, deadline=None)
@given(state)
def test_chart_conversions_are_inverse(X):
    T, T_inv = euler_to_rv_jacobian(X), rv_to_euler_jacobian(X)
    np.testing.assert_allclose(T @ T_inv, np.eye(6), atol=1e-9)
    # T maps Euler differentials to rotation-vector ones (finite differences of the local difference)
    T_fd = central_diff_local(lambda dX: X + dX, X)
    np.testing.assert_allclose(T, T_fd, rtol=1e-6, atol=1e-8)
