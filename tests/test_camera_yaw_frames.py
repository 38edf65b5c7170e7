"""The camera's yaw on the base, when the localizer estimates it (``LocalizerConfig.camera_yaw_sigma_rad``
above 0), reaches what the robot sees: every frame a :class:`~lab.localization.LocalizedRobot` hands on is
taken through the camera turned by the estimate about the pan axis (:func:`lab.mounts.with_head_yaw`)."""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from lab.geometry import Pose2D
from lab.localization import LocalizedRobot, LocalizerConfig
from lab.mounts import HeadMounts, MountedCamera, with_head_yaw
from lab.robot import SIM_CAMERA, RobotWrapper
from lab.runs.robots import make_robot
from lab.runs.room import sim_localizer_told, surveyed_map
from lab.sim import SimWorld
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
        told = sim_localizer_told(base)
        assert "config" not in told  # held exact by default (docs/tuning/localizer-camera-yaw.md)
        told["config"] = LocalizerConfig(camera_yaw_sigma_rad=math.radians(base.camera.pointing_std_deg))
        seen = []
        surveyed = surveyed_map(landmarks, base.sensing, 3)
        robot = LocalizedRobot(_Recording(base, seen), "landmarks", surveyed, log=lambda m: None, **told)
        for _ in range(2):
            frame = robot.capture_stereo()
        yaw, sd = robot.localizer.camera_yaw_estimate
        assert robot.localizer.n_updates >= 1 and yaw != 0.0 and 0 < sd < told["config"].camera_yaw_sigma_rad
        pan, tilt = frame.pan_tilt.pan, frame.pan_tilt.tilt
        np.testing.assert_allclose(frame.G_RC, _turn(yaw) @ seen[-1].camera.G_RC(pan, tilt), atol=1e-12)
