"""Public tests of assignment 1: run them with ``python -m pytest test_ekf.py``.

They check shapes, a few values you can work out by hand, and your Jacobian against finite
differences of *your* measurement model. The graded tests check more, against independent references.
"""

import numpy as np
import pytest
from ekf import (
    data_log_likelihood,
    ekf_update,
    kalman_update,
    measurement_jacobian,
    measurement_model,
    rotation_zyx,
)


def test_rotation_turns_the_axes_as_expected():
    # yaw by 90 degrees takes x to y; pitch by 90 degrees takes x to -z; roll by 90 degrees takes y to z
    np.testing.assert_allclose(rotation_zyx(np.pi / 2, 0, 0) @ [1, 0, 0], [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(rotation_zyx(0, np.pi / 2, 0) @ [1, 0, 0], [0, 0, -1], atol=1e-12)
    np.testing.assert_allclose(rotation_zyx(0, 0, np.pi / 2) @ [0, 1, 0], [0, 0, 1], atol=1e-12)


def test_rotation_is_a_rotation():
    R = rotation_zyx(0.3, -0.4, 1.1)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)


def test_measurement_model_at_the_identity_orientation_only_translates():
    b = np.array([[0.1, 0.0, 0.0], [0.0, -0.1, 0.05]])
    d = measurement_model([1.0, 2.0, 3.0, 0.0, 0.0, 0.0], b)
    assert d.shape == (2, 3)
    np.testing.assert_allclose(d, b + [1.0, 2.0, 3.0])


def test_jacobian_matches_finite_differences_of_your_measurement_model():
    rng = np.random.default_rng(0)
    X = np.array([0.1, -0.2, 1.5, 0.4, -0.3, 0.7])
    b = rng.uniform(-0.14, 0.14, (4, 3))
    C = measurement_jacobian(X, b)
    assert C.shape == (12, 6)
    h = 1e-6
    for k in range(6):
        e = np.zeros(6)
        e[k] = h
        fd = (measurement_model(X + e, b) - measurement_model(X - e, b)).reshape(-1) / (2 * h)
        np.testing.assert_allclose(C[:, k], fd, atol=1e-6, err_msg=f"column {k}")


def test_kalman_update_with_equal_prior_and_measurement_uncertainty_meets_halfway():
    # C = I, Sigma_bar = Sigma_m = I: the gain is I/2
    mu, Sigma = kalman_update(np.zeros(6), np.eye(6), np.full(6, 2.0), np.eye(6), np.eye(6))
    np.testing.assert_allclose(mu, np.full(6, 1.0))
    np.testing.assert_allclose(Sigma, 0.5 * np.eye(6))


def test_log_likelihood_of_a_perfect_prediction():
    m = 6
    ll = data_log_likelihood(np.zeros(m), np.eye(m), np.zeros((6, 6)), np.eye(m))
    assert ll == pytest.approx(-0.5 * m * np.log(2 * np.pi))


def test_ekf_update_moves_towards_the_truth():
    rng = np.random.default_rng(1)
    X = np.array([0.05, 0.02, 1.2, 0.3, 0.1, -0.2])
    b = rng.uniform(-0.14, 0.14, (8, 3))
    d = measurement_model(X, b)  # noise-free measurement
    mu_bar = X + [0.02, -0.01, 0.03, 0.05, -0.04, 0.03]
    Sigma_bar = np.diag([0.02**2] * 3 + [0.05**2] * 3)
    mu, Sigma = ekf_update(mu_bar, Sigma_bar, d, b, 1e-6 * np.eye(24))
    assert np.linalg.norm(mu - X) < 0.2 * np.linalg.norm(mu_bar - X)
    assert np.all(np.linalg.eigvalsh(Sigma) > 0)


# The notebook's checks (lab.exercises), where the course package is installed: they name a mistake
# ("transposed axes", "a wrong sign", "missing normalisation") where the tests above only fail.
@pytest.mark.parametrize(
    "check, function",
    [
        ("check_rotation_zyx", "rotation_zyx"),
        ("check_measurement_jacobian", "measurement_jacobian"),
        ("check_kalman_update", "kalman_update"),
    ],
)
def test_the_notebooks_check_says_correct(check, function):
    exercises = pytest.importorskip("lab.exercises")
    feedback = getattr(exercises, check)(globals()[function])
    assert feedback.correct, str(feedback)
