"""The colour track's filter (lab.search.colour_track, Eqs. (T1)-(T2)): hand-derived values and
filterpy's KalmanFilter as a peer on the same sequence; its gate, its speed-bounded extrapolation, and
the stereo point of a pixel and its disparity placed in the world and projected back."""

from __future__ import annotations

import math

import numpy as np
import pytest
from filterpy.common import Q_continuous_white_noise
from filterpy.kalman import KalmanFilter

from lab.errors import ConfigError
from lab.geometry import Pose2D
from lab.robot import PanTiltState, StereoCamera, StereoFrame
from lab.search.colour_track import (
    ColourTrack,
    ColourTrackConfig,
    measurement_xy,
    predicted_pixel,
    transition,
    white_noise_q,
)

CFG = ColourTrackConfig()
V = 0.1  # the speed bound [m/s]


def test_a_prediction_grows_the_covariance_by_hand_derived_amounts():
    R0 = np.diag([0.04, 0.09])
    tr = ColourTrack([1.0, 2.0, 0.3], R0, 10.0, V, CFG)
    tr.predict(12.0)
    dt, q = 2.0, V**2 / (2 * CFG.tau_s)
    pv = V**2 / 2  # the velocity's variance per axis at the start: a speed V in a random direction
    # p' = p + dt v with v independent of p: var p' = var p + dt^2 var v + q dt^3 / 3
    assert tr.P[0, 0] == pytest.approx(0.04 + dt**2 * pv + q * dt**3 / 3)
    assert tr.P[1, 1] == pytest.approx(0.09 + dt**2 * pv + q * dt**3 / 3)
    assert tr.P[0, 2] == pytest.approx(dt * pv + q * dt**2 / 2)  # cov(p', v') = dt var v + q dt^2/2
    assert tr.P[2, 2] == pytest.approx(pv + q * dt)
    assert tr.P[0, 1] == 0.0
    np.testing.assert_allclose(tr.x, [1.0, 2.0, 0.0, 0.0])  # no velocity known: it stays


def test_one_update_is_the_scalar_kalman_gain_by_hand():
    tr = ColourTrack([0.0, 0.0, 0.2], np.diag([0.04, 0.04]), 0.0, V, CFG)
    assert tr.update([0.1, -0.1], np.diag([0.01, 0.01]), 0.0)  # same time: no prediction
    k = 0.04 / (0.04 + 0.01)  # the position gain per axis
    np.testing.assert_allclose(tr.x[:2], [k * 0.1, -k * 0.1])
    assert tr.P[0, 0] == pytest.approx((1 - k) * 0.04)  # 0.04 * 0.01 / 0.05
    np.testing.assert_allclose(tr.x[2:], 0.0)  # position and velocity uncorrelated at the start


def test_the_filter_agrees_with_filterpy_on_a_sequence():
    rng = np.random.default_rng(0)
    R0 = np.array([[0.05, 0.01], [0.01, 0.03]])
    tr = ColourTrack([0.5, -1.0, 0.1], R0, 0.0, V, CFG)
    kf = KalmanFilter(dim_x=4, dim_z=2)
    kf.x = np.array([0.5, -1.0, 0.0, 0.0])
    kf.P = np.zeros((4, 4))
    kf.P[:2, :2] = R0
    kf.P[2:, 2:] = 0.5 * V**2 * np.eye(2)
    kf.H = np.hstack([np.eye(2), np.zeros((2, 2))])
    q = V**2 / (2 * CFG.tau_s)
    t = 0.0
    truth = np.array([0.5, -1.0])
    for k in range(8):
        dt = 1.0 + 0.5 * (k % 3)
        t += dt
        truth = truth + dt * np.array([0.07, 0.07])
        R = np.diag(rng.uniform(0.005, 0.03, 2))
        z = truth + rng.normal(0, 0.05, 2)
        kf.F = transition(dt)
        kf.Q = Q_continuous_white_noise(dim=2, dt=dt, spectral_density=q, block_size=2, order_by_dim=False)
        np.testing.assert_allclose(white_noise_q(dt, q), kf.Q)
        kf.predict()
        kf.update(z, R=R)
        assert tr.update(z, R, t)
        np.testing.assert_allclose(tr.x, kf.x, atol=1e-12)
        np.testing.assert_allclose(tr.P, kf.P, atol=1e-12)
    assert tr.updates == 8 and tr.t_seen == t
    assert np.linalg.norm(tr.x[2:] - 0.07) < 0.05  # it learned the velocity


def test_the_gate_refuses_a_far_blob_and_the_track_is_lost_later():
    tr = ColourTrack([0.0, 0.0, 0.2], np.diag([0.01, 0.01]), 0.0, V, CFG)
    # S = 0.01 + 0.5 V^2 + ... per axis at 1 s: about 0.016; 1 m away is far beyond chi2 9.21
    assert not tr.update([1.0, 0.0], np.diag([0.001, 0.001]), 1.0)
    assert tr.updates == 0 and tr.t_seen == 0.0 and tr.t == 1.0
    assert not tr.lost(CFG.lost_after_s) and tr.lost(CFG.lost_after_s + 0.1)
    assert not tr.lost(CFG.lost_after_s + 0.1, since=1.0)  # counted from when the looks began


def test_the_pixel_gate_grows_with_the_tracks_deviation():
    tr = ColourTrack([0.0, 0.0, 0.2], np.diag([0.01, 0.04]), 0.0, V, CFG)
    assert tr.gate_px(4.0, 200.0) == CFG.gate_px  # 3 * 0.2 m at 4 m is 30 px: the floor
    tr.predict(10.0)  # var grows by 100 * V^2 / 2 + q 1000 / 3 = 0.5 + 0.167
    sigma = math.sqrt(0.04 + 0.5 + V**2 / (2 * CFG.tau_s) * 1000 / 3)
    assert tr.gate_px(2.0, 200.0) == pytest.approx(3 * sigma * 200.0 / 2.0)
    with pytest.raises(ConfigError, match="back in time"):
        tr.predict(0.5)


def test_the_extrapolation_keeps_the_speed_bound():
    tr = ColourTrack([0.0, 0.0, 0.2], np.eye(2) * 0.01, 0.0, V, CFG)
    tr.x[2:] = [0.3, 0.4]  # a noisy estimate of 0.5 m/s
    p = tr.position_at(10.0)
    assert np.linalg.norm(p) == pytest.approx(V * 10.0)  # 1 m in 10 s, not 5 m
    np.testing.assert_allclose(p / np.linalg.norm(p), [0.6, 0.8])
    tr.x[2:] = [0.03, 0.0]
    np.testing.assert_allclose(tr.position_at(10.0), [0.3, 0.0])


def test_a_pixel_and_its_disparity_go_to_the_world_and_project_back():
    cam = StereoCamera.from_fov(320, 240, 60.0, 0.12, mount_R=(0.0, 0.0, 1.1))
    pan, tilt = math.radians(30.0), math.radians(-20.0)
    odom = Pose2D(1.0, -0.5, math.radians(45.0))
    empty = np.zeros((240, 320, 3), np.uint8)
    frame = StereoFrame(2.0, empty, empty, cam, PanTiltState(pan, tilt, 2.0, pan, tilt), odom)
    d = cam.fx * cam.baseline / 3.0  # 3 m away
    p_W, R = measurement_xy(frame, (200.0, 150.0), d, CFG)
    u, v, Z = predicted_pixel(frame, p_W)
    np.testing.assert_allclose((u, v, Z), (200.0, 150.0, 3.0), atol=1e-9)
    G_WC = odom.G() @ frame.G_RC
    assert np.linalg.norm(p_W - G_WC[:3, 3]) == pytest.approx(
        3.0 * math.sqrt(1 + ((200 - cam.cx) / cam.fx) ** 2 + ((150 - cam.cy) / cam.fy) ** 2)
    )
    # the depth's deviation Z^2 sigma_d / (f b) dominates, along the viewing ray
    sz = 9.0 * CFG.sigma_disparity_px / (cam.fx * cam.baseline)
    ev = np.linalg.eigvalsh(R)
    assert ev[-1] > sz**2 * 0.5 and ev[0] >= CFG.sigma_floor_m**2
    assert predicted_pixel(frame, G_WC[:3, 3] - 2.0 * G_WC[:3, 2]) is None  # behind the camera
