"""Public tests of assignment 0: run them with ``python -m pytest test_stereo.py``."""

import numpy as np
import pytest
from stereo import depth_std, project, triangulate

F, CX, CY, B = 207.8, 159.5, 119.5, 0.12  # the simulated head: 320 x 240, 60 deg vertical field of view


def test_a_point_on_the_optical_axis():
    p = triangulate([[CX, CY]], [F * B / 2.0], F, CX, CY, B)
    np.testing.assert_allclose(p, [[0.0, 0.0, 2.0]])


def test_a_point_off_the_axis():
    # u - cx = f / 2 at depth 2 m: x = (u - cx) Z / f = 1 m
    p = triangulate([[CX + F / 2, CY]], [F * B / 2.0], F, CX, CY, B)
    np.testing.assert_allclose(p, [[1.0, 0.0, 2.0]])


def test_zero_disparity_has_no_depth():
    p = triangulate([[10.0, 20.0], [CX, CY]], [0.0, 12.0], F, CX, CY, B)
    assert np.all(np.isnan(p[0])) and np.all(np.isfinite(p[1]))


def test_projection_inverts_triangulation():
    uv = np.array([[30.0, 40.0], [300.0, 200.0]])
    p = triangulate(uv, [5.0, 20.0], F, CX, CY, B)
    np.testing.assert_allclose(project(p, F, CX, CY), uv)


def test_the_right_camera_sees_the_point_shifted_by_the_disparity():
    # inverting each other is not enough: the right camera, b along x, sees the point at (u - d, v)
    uv, d = np.array([[30.0, 40.0], [300.0, 200.0]]), np.array([5.0, 20.0])
    p = triangulate(uv, d, F, CX, CY, B)
    np.testing.assert_allclose(project(p - [B, 0.0, 0.0], F, CX, CY), uv - np.column_stack([d, [0.0, 0.0]]))


def test_depth_error_grows_with_the_square_of_the_distance():
    assert depth_std(2.0, F, B, 0.25) == pytest.approx(4 * depth_std(1.0, F, B, 0.25))


# The notebook's checks (lab.exercises), where the course package is installed: they name a mistake
# ("transposed axes", "a wrong sign", "missing normalisation") where the tests above only fail.
@pytest.mark.parametrize(
    "check, function",
    [("check_triangulate", "triangulate"), ("check_project", "project"), ("check_depth_std", "depth_std")],
)
def test_the_notebooks_check_says_correct(check, function):
    exercises = pytest.importorskip("lab.exercises")
    feedback = getattr(exercises, check)(globals()[function])
    assert feedback.correct, str(feedback)
