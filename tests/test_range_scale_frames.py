"""The stereo's range scale, when the localizer estimates it (``LocalizerConfig.range_scale_sigma`` above
0), reaches what the robot measures: a frame's camera then has its focal lengths divided by ``1 + scale``.
A camera whose focal lengths are off makes everything look larger or smaller (a fit reads its range
from that) and its disparities too; the rescaled camera undoes both. Peer: OpenCV's
``triangulatePoints`` with the rescaled camera's projection matrices."""

import math
from dataclasses import replace

import cv2
import numpy as np
import pytest

from lab.localization.robot import _rescaled
from lab.robot import SIM_CAMERA
from lab.vision import triangulate


@pytest.mark.parametrize("focal_error", [0.012, -0.007])
def test_a_rescaled_camera_triangulates_what_a_camera_with_longer_focal_lengths_saw(focal_error):
    """The true camera's focal lengths are ``1 + focal_error`` times the nominal ones; the nominal
    camera reads its ranges ``1 / (1 + focal_error)`` times the true ones, which is the range scale;
    rescaled by it, the nominal camera triangulates the true points, with every pixel's ray right."""
    nominal = SIM_CAMERA.camera(mount_R=(0.0, 0.0, 1.1))
    true = replace(nominal, fx=nominal.fx * (1 + focal_error), fy=nominal.fy * (1 + focal_error))
    rng = np.random.default_rng(4)
    p_true = np.column_stack([rng.uniform(-0.4, 0.4, 6), rng.uniform(-0.3, 0.3, 6), rng.uniform(0.8, 3.5, 6)])
    uv = (true.K @ (p_true / p_true[:, 2:]).T).T[:, :2]
    d = true.fx * true.baseline / p_true[:, 2]
    right = uv - np.column_stack([d, 0 * d])
    scale = 1 / (1 + focal_error) - 1
    seen = triangulate(uv, right, nominal)
    np.testing.assert_allclose(seen[:, 2], (1 + scale) * p_true[:, 2], rtol=1e-9)  # the range scale
    fixed = _rescaled(nominal, scale, sigma=0.01)
    np.testing.assert_allclose(triangulate(uv, right, fixed), p_true, atol=1e-9)
    # OpenCV's triangulation of the same pixels, with the rescaled camera's projection matrices
    K = fixed.K
    P1 = K @ np.hstack([np.eye(3), np.zeros((3, 1))])
    P2 = K @ np.hstack([np.eye(3), [[-fixed.baseline], [0.0], [0.0]]])
    X = cv2.triangulatePoints(P1, P2, uv.T, right.T)
    np.testing.assert_allclose((X[:3] / X[3]).T, p_true, atol=1e-6)
    assert (fixed.cx, fixed.cy, fixed.baseline) == (nominal.cx, nominal.cy, nominal.baseline)


def test_a_diverged_scale_is_clipped_to_three_prior_deviations():
    camera = SIM_CAMERA.camera()
    assert _rescaled(camera, 0.5, sigma=0.01).fx == pytest.approx(camera.fx / 1.03)
    assert _rescaled(camera, -0.5, sigma=0.01).fy == pytest.approx(camera.fy / 0.97)
    assert math.isclose(_rescaled(camera, 0.0, sigma=0.01).fx, camera.fx)
