"""Geometry against SciPy's Rotation (an independent implementation) to 1e-12."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from lab import geometry as g

angle = st.floats(-np.pi, np.pi, allow_nan=False)
half = st.floats(-np.pi / 2 + 1e-6, np.pi / 2 - 1e-6, allow_nan=False)


@settings(max_examples=300, deadline=None)
@given(angle, half, angle)
def test_euler_zyx_matches_scipy_intrinsic_ZYX(a, b, c):
    R = g.euler_zyx_to_R(a, b, c)
    np.testing.assert_allclose(R, Rotation.from_euler("ZYX", [a, b, c]).as_matrix(), atol=1e-12)
    np.testing.assert_allclose(R, g.Rz(a) @ g.Ry(b) @ g.Rx(c), atol=1e-12)


@settings(max_examples=300, deadline=None)
@given(angle, half, angle)
def test_euler_round_trip_and_scipy_inverse(a, b, c):
    R = g.euler_zyx_to_R(a, b, c)
    e = g.R_to_euler_zyx(R)
    np.testing.assert_allclose(g.euler_zyx_to_R(*e), R, atol=1e-12)
    # same angles as SciPy's inverse, compared on the circle (pi and -pi are one angle)
    np.testing.assert_allclose(g.wrap_angle(e - Rotation.from_matrix(R).as_euler("ZYX")), 0.0, atol=1e-9)


def test_euler_gimbal_lock_keeps_the_rotation():
    for b in (np.pi / 2, -np.pi / 2):
        R = g.euler_zyx_to_R(0.3, b, -0.7)
        e = g.R_to_euler_zyx(R)
        assert e[2] == 0.0 and abs(abs(e[1]) - np.pi / 2) < 1e-12
        np.testing.assert_allclose(g.euler_zyx_to_R(*e), R, atol=1e-12)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-1, 1), min_size=4, max_size=4).filter(lambda q: np.linalg.norm(q) > 1e-3))
def test_quaternion_xyzw_matches_scipy(q):
    q = np.array(q) / np.linalg.norm(q)
    R = Rotation.from_quat(q).as_matrix()
    np.testing.assert_allclose(g.quat_xyzw_to_R(q), R, atol=1e-12)
    q2 = g.R_to_quat_xyzw(R)
    assert q2[3] >= 0
    np.testing.assert_allclose(g.quat_xyzw_to_R(q2), R, atol=1e-12)


def test_se3_inverse_compose_and_points():
    rng = np.random.default_rng(0)
    for _ in range(50):
        X1 = np.concatenate([rng.normal(size=3), rng.uniform(-3, 3, 3) * [1, 0.5, 1]])
        X2 = np.concatenate([rng.normal(size=3), rng.uniform(-3, 3, 3) * [1, 0.5, 1]])
        G1, G2 = g.pose6_to_G(X1), g.pose6_to_G(X2)
        np.testing.assert_allclose(g.compose(G1, g.se3_inv(G1)), np.eye(4), atol=1e-12)
        np.testing.assert_allclose(g.se3_inv(G1), np.linalg.inv(G1), atol=1e-12)
        p = rng.normal(size=(7, 3))
        r1 = Rotation.from_euler("ZYX", X1[3:])
        np.testing.assert_allclose(g.transform_points(G1, p), r1.apply(p) + X1[:3], atol=1e-12)
        # composition equals applying one after the other
        np.testing.assert_allclose(
            g.transform_points(g.compose(G1, G2), p),
            g.transform_points(G1, g.transform_points(G2, p)),
            atol=1e-12,
        )
        np.testing.assert_allclose(g.pose6_to_G(g.G_to_pose6(G1)), G1, atol=1e-12)


def test_wrap_angle():
    assert g.wrap_angle(np.pi) == pytest.approx(np.pi)
    assert g.wrap_angle(-np.pi) == pytest.approx(np.pi)
    assert g.wrap_angle(3 * np.pi / 2) == pytest.approx(-np.pi / 2)
    np.testing.assert_allclose(g.wrap_angle(np.array([0.1, 2 * np.pi + 0.1])), [0.1, 0.1], atol=1e-12)


def test_pan_tilt_camera_frame_looks_where_it_should():
    mount, off = (0.0, 0.0, 0.8), (0.05, 0.06, 0.0)
    G = g.pan_tilt_G_RC(0.0, 0.0, mount, off)
    # optical z is robot x (forward), optical x is robot -y (right), optical y is robot -z (down)
    np.testing.assert_allclose(G[:3, 2], [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(G[:3, 0], [0, -1, 0], atol=1e-12)
    np.testing.assert_allclose(G[:3, 1], [0, 0, -1], atol=1e-12)
    np.testing.assert_allclose(G[:3, 3], [0.05, 0.06, 0.8], atol=1e-12)
    # pan +90 deg looks left (+y), tilt +30 deg looks up
    G = g.pan_tilt_G_RC(np.pi / 2, 0.0, mount, off)
    np.testing.assert_allclose(G[:3, 2], [0, 1, 0], atol=1e-12)
    G = g.pan_tilt_G_RC(0.0, np.radians(30), mount, off)
    np.testing.assert_allclose(G[:3, 2], [np.cos(np.radians(30)), 0, np.sin(np.radians(30))], atol=1e-12)
    # the same transform built with SciPy from its parts
    pan, tilt = 0.4, -0.3
    R_ref = (
        Rotation.from_euler("z", pan)
        * Rotation.from_euler("y", -tilt)
        * Rotation.from_matrix(g.R_BODY_TO_OPTICAL)
    ).as_matrix()
    t_ref = np.array(mount) + (Rotation.from_euler("z", pan) * Rotation.from_euler("y", -tilt)).apply(off)
    G = g.pan_tilt_G_RC(pan, tilt, mount, off)
    np.testing.assert_allclose(G[:3, :3], R_ref, atol=1e-12)
    np.testing.assert_allclose(G[:3, 3], t_ref, atol=1e-12)


def test_relative_pose2d_is_the_odometry_increment():
    a, b = g.Pose2D(1.0, 2.0, 0.5), g.Pose2D(1.5, 2.5, 1.2)
    G_ab = g.relative_pose2d(a, b)
    np.testing.assert_allclose(a.G() @ G_ab, b.G(), atol=1e-12)
