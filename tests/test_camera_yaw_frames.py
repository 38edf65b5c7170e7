"""The camera's yaw on the base, when the localizer estimates it (``LocalizerConfig.camera_yaw_sigma_rad``
above 0), reaches what the robot sees: every frame a :class:`~lab.localization.LocalizedRobot` hands on is
taken through the camera turned by the estimate about the pan axis (:func:`lab.mounts.with_head_yaw`)."""

import math
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from lab.errors import ConfigError
from lab.geometry import Pose2D
from lab.localization import LocalizedRobot, Localizer, LocalizerConfig
from lab.mounts import HeadMounts, MountedCamera, with_head_yaw
from lab.robot import SIM_CAMERA, BaseLimits, RobotWrapper
from lab.runs.robots import make_robot
from lab.runs.room import sim_localizer_told, surveyed_map
from lab.sim import SimWorld
from lab.sim.sensing import OdometryErrors
from lab.training.landmarks import trained_landmark_map


class _Recording(RobotWrapper):
    """The robot, keeping each frame it captures (before the localizer hands it on)."""

    def __init__(self, base, seen: list):
        super().__init__(base)
        self.seen = seen

    def capture_stereo(self, after=None):
        frame = self.base.capture_stereo(after)
        self.seen.append(frame)
        return frame


def _turn(yaw: float) -> np.ndarray:
    """A turn about R's vertical (scipy's rotation: the peer of lab.geometry's)."""
    G = np.eye(4)
    G[:3, :3] = Rotation.from_euler("z", yaw).as_matrix()
    return G


@pytest.mark.parametrize(
    "mounts",
    [None, HeadMounts(head_rpy=(0.004, -0.006, 0.003), camera_rpy=(0.002, 0.001, -0.005), pan_zero=0.002)],
)
def test_a_yawed_camera_is_the_camera_turned_about_the_pan_axis(mounts):
    camera = SIM_CAMERA.camera(mount_R=(0.0, 0.0, 1.1))
    if mounts is not None:
        camera = MountedCamera.of(camera, mounts)
    yaw = math.radians(1.3)
    turned = with_head_yaw(camera, yaw)
    for pan, tilt in [(0.0, 0.0), (0.7, -0.3), (-2.1, 0.4)]:
        np.testing.assert_allclose(turned.G_RC(pan, tilt), _turn(yaw) @ camera.G_RC(pan, tilt), atol=1e-12)
    assert turned.pointing_std_deg == camera.pointing_std_deg and turned.K.tolist() == camera.K.tolist()
    np.testing.assert_allclose(
        with_head_yaw(turned, -yaw).G_RC(0.7, -0.3), camera.G_RC(0.7, -0.3), atol=1e-12
    )


def test_a_localized_robots_frames_are_taken_through_the_estimated_yaw():
    """A realistic robot in the lab room, its localizer estimating the camera's yaw (prior: the camera's
    stated pointing), looks at a poster: the localizer updates (its yaw among the rest), and the frame it
    hands on is the base's frame with the camera turned by the estimate after the update."""
    landmarks = trained_landmark_map("lab_room", progress=False)
    with (
        SimWorld("lab_room") as w,
        make_robot(world=w, seed=3, sensing="realistic", start=Pose2D(0, 0, 1.4)) as run,
    ):
        base = run.robot
        base.enable()
        told = sim_localizer_told(base)  # the mounts stated uncertain: the yaw in the state by default
        assert told["config"].camera_yaw_sigma_rad == pytest.approx(
            math.radians(base.camera.pointing_std_deg)
        )
        assert told["config"].camera_yaw_sigma_rad > 0
        seen = []
        surveyed = surveyed_map(landmarks, base.sensing, 3)
        robot = LocalizedRobot(_Recording(base, seen), "landmarks", surveyed, log=lambda m: None, **told)
        for _ in range(2):
            frame = robot.capture_stereo()
        yaw, sd = robot.localizer.camera_yaw_estimate
        assert robot.localizer.n_updates >= 1 and yaw != 0.0 and 0 < sd < told["config"].camera_yaw_sigma_rad
        pan, tilt = frame.pan_tilt.pan, frame.pan_tilt.tilt
        np.testing.assert_allclose(frame.G_RC, _turn(yaw) @ seen[-1].camera.G_RC(pan, tilt), atol=1e-12)
        # standing, the sightings fix the camera's heading (the base's plus the yaw) better than either
        base_est, cam_est = robot.pose_estimate(), robot.camera_pose_estimate()
        assert cam_est.sigma_theta_rad < base_est.sigma_theta_rad
        assert cam_est.pose.theta == pytest.approx(base_est.pose.theta + yaw, abs=1e-12)
        # the calibration stated uncertain: the range scale in the state, and the frame's ranges corrected
        assert told["config"].range_scale_sigma == base.camera.depth_scale_std > 0
        scale, sd_scale = robot.localizer.range_scale_estimate
        assert scale != 0.0 and 0 < sd_scale < told["config"].range_scale_sigma
        assert frame.camera.fx == pytest.approx(seen[-1].camera.fx / (1 + scale), rel=1e-12)
        assert frame.camera.baseline == seen[-1].camera.baseline


@pytest.mark.parametrize("depth_scale_std", [0.0, 0.007])
def test_the_yaw_is_held_exact_when_the_profile_states_the_mounts_exact(depth_scale_std):
    """A profile without mount errors (the survey-and-start condition's): the camera's yaw on the base is
    not in the state; the range scale is when the camera's calibration is stated uncertain, and with
    neither the localizer keeps its default config."""
    room = SimpleNamespace(
        camera_mount_deg=0.0,
        head_mount_deg=0.0,
        latency_s=0.0,
        start_m=0.05,
        start_deg=3.0,
        start_sigma=(0.1, math.radians(5.0)),
    )
    camera = replace(SIM_CAMERA.camera(), depth_scale_std=depth_scale_std)
    # realistic's odometry without its spin slip: the defaults cover it, so odometry_told leaves the config
    sensing = SimpleNamespace(room=room, odometry=replace(OdometryErrors(), spin_slip=0.0))
    robot = SimpleNamespace(sensing=sensing, camera=camera, base_limits=BaseLimits())
    told = sim_localizer_told(robot)
    assert told["start_measured_by_hand"]
    if depth_scale_std == 0:
        assert "config" not in told
    else:
        assert (
            told["config"].camera_yaw_sigma_rad == 0 and told["config"].range_scale_sigma == depth_scale_std
        )


def _state_with_yaw(seed: int = 0) -> Localizer:
    """A localizer estimating the camera's yaw, its state's covariance a random one (every term
    correlated), as a run leaves it."""
    loc = Localizer([1.0, 2.0, 0.3], config=LocalizerConfig(camera_yaw_sigma_rad=math.radians(0.7)))
    n = loc.s.size
    A = np.random.default_rng(seed).normal(size=(n, n)) * 0.05
    loc.P = A @ A.T + 1e-4 * np.eye(n)
    loc.s[loc.camera_yaw] = 0.02
    return loc


def test_the_camera_pose_is_the_base_pose_turned_by_the_yaw_with_its_covariance():
    """``Localizer.camera_pose``: (x, y, theta + beta) and the covariance of that sum, term by term
    (Var(theta + beta) = P_tt + 2 P_tb + P_bb; Cov(x, theta + beta) = P_xt + P_xb); without the yaw in the
    state, the base's pose."""
    loc = _state_with_yaw()
    P, b = loc.P, loc.camera_yaw
    x, C = loc.camera_pose()
    np.testing.assert_allclose(x, [1.0, 2.0, 0.32], atol=1e-12)
    np.testing.assert_allclose(C[:2, :2], P[:2, :2], atol=1e-15)
    for i in (0, 1):
        assert C[i, 2] == pytest.approx(P[i, 2] + P[i, b], abs=1e-15) and C[2, i] == C[i, 2]
    assert C[2, 2] == pytest.approx(P[2, 2] + 2 * P[2, b] + P[b, b], abs=1e-15)
    plain = Localizer([1.0, 2.0, 0.3])
    x0, C0 = plain.camera_pose()
    np.testing.assert_array_equal(x0, plain.x)
    np.testing.assert_array_equal(C0, plain.Sigma)


def test_the_kept_pose_of_a_detour_is_the_cameras_too():
    """Right after ``start_clone`` the kept pose is the pose now, so the kept camera pose (built from the
    clone's cross-covariance with the yaw) is :meth:`Localizer.camera_pose` (built from the state's
    covariance); without ``camera`` it is the base's."""
    loc = _state_with_yaw(1)
    loc.start_clone()
    x, C = loc.cloned_estimate(camera=True)
    x_now, C_now = loc.camera_pose()
    np.testing.assert_allclose(x, x_now, atol=1e-12)
    np.testing.assert_allclose(C, C_now, atol=1e-15)
    np.testing.assert_allclose(loc.cloned_estimate()[1], loc.Sigma, atol=1e-15)


def test_a_diverged_yaw_estimate_turns_the_camera_to_the_mounts_limit_not_past_it():
    """The estimate put into the head's yaw is clipped to the mounts' limit (``MAX_MOUNT_DEG``), so a
    frame is still made (``HeadMounts`` refuses more); a yaw within the limit passes unchanged."""
    from lab.localization.robot import _within_mount_limit
    from lab.mounts import MAX_MOUNT_DEG

    camera = MountedCamera.of(SIM_CAMERA.camera(), HeadMounts(head_rpy=(0.0, 0.0, math.radians(9.0))))
    small = math.radians(0.5)
    assert _within_mount_limit(camera, small) == pytest.approx(small, abs=1e-15)
    big = _within_mount_limit(camera, math.radians(3.0))
    assert math.degrees(big) == pytest.approx(MAX_MOUNT_DEG - 9.0, abs=1e-6)
    turned = with_head_yaw(camera, big)  # no ConfigError
    assert math.degrees(turned.mounts.head_rpy[2]) == pytest.approx(MAX_MOUNT_DEG, abs=1e-6)
    with pytest.raises(ConfigError, match="beyond"):
        with_head_yaw(camera, math.radians(3.0))
