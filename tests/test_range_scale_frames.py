"""The stereo's range scale, when the localizer estimates it (``LocalizerConfig.range_scale_sigma`` above
0), reaches what the robot measures: a frame's camera then triangulates at the ranges divided by
``1 + scale`` (its baseline divided by it). Peer: OpenCV's ``triangulatePoints`` with the rescaled
camera's projection matrices."""

import math

import cv2
import numpy as np
import pytest

from lab.localization.robot import _rescaled
from lab.robot import SIM_CAMERA
from lab.vision import triangulate


@pytest.mark.parametrize("scale", [0.012, -0.007])
def test_a_rescaled_camera_triangulates_the_stereo_points_divided_by_the_scale(scale):
    """Points a camera with ranges ``1 + scale`` too long would report come out at the true ones."""
    camera = SIM_CAMERA.camera(mount_R=(0.0, 0.0, 1.1))
    rng = np.random.default_rng(4)
    p_true = np.column_stack([rng.uniform(-0.4, 0.4, 6), rng.uniform(-0.3, 0.3, 6), rng.uniform(0.8, 3.5, 6)])
    stretched = (1 + scale) * p_true  # what the miscalibrated stereo triangulates (a uniform stretch)
    uv = (camera.K @ (stretched / stretched[:, 2:]).T).T[:, :2]
    d = camera.fx * camera.baseline / stretched[:, 2]
    fixed = _rescaled(camera, scale, sigma=0.01)
    np.testing.assert_allclose(triangulate(uv, uv - np.column_stack([d, 0 * d]), fixed), p_true, atol=1e-9)
    # OpenCV's triangulation of the same pixels, with the rescaled camera's projection matrices
    K = fixed.K
    P1 = K @ np.hstack([np.eye(3), np.zeros((3, 1))])
    P2 = K @ np.hstack([np.eye(3), [[-fixed.baseline], [0.0], [0.0]]])
    X = cv2.triangulatePoints(P1, P2, uv.T, (uv - np.column_stack([d, 0 * d])).T)
    np.testing.assert_allclose((X[:3] / X[3]).T, p_true, atol=1e-6)
    assert fixed.K.tolist() == camera.K.tolist()


def test_a_diverged_scale_is_clipped_to_three_prior_deviations():
    camera = SIM_CAMERA.camera()
    assert _rescaled(camera, 0.5, sigma=0.01).baseline == pytest.approx(camera.baseline / 1.03)
    assert _rescaled(camera, -0.5, sigma=0.01).baseline == pytest.approx(camera.baseline / 0.97)
    assert math.isclose(_rescaled(camera, 0.0, sigma=0.01).baseline, camera.baseline)
