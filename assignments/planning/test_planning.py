"""Public tests of assignment 2: run them with ``python -m pytest test_planning.py``."""

import numpy as np
import pytest
from planning import entropy, expected_entropy, feature_log_likelihood, model_probabilities, next_best_action

DELTA_O = np.array([0.003, -0.002, 0.004])
SIGMA_O = np.diag([0.005, 0.005, 0.008]) ** 2


def test_equal_likelihoods_leave_the_prior_unchanged():
    P = np.array([0.1, 0.2, 0.3, 0.4])
    np.testing.assert_allclose(model_probabilities(P, np.full(4, -7.0)), P)


def test_a_likelihood_ratio_of_e_multiplies_the_odds_by_e():
    P = model_probabilities([0.5, 0.5], [0.0, -1.0])
    assert P.sum() == pytest.approx(1.0)
    assert P[0] / P[1] == pytest.approx(np.e)


def test_very_small_likelihoods_still_give_probabilities():
    P = model_probabilities([0.5, 0.5], [-3000.0, -3001.0])
    assert np.all(np.isfinite(P))
    assert P[0] / P[1] == pytest.approx(np.e)


def test_the_floor_keeps_every_model_alive():
    P = model_probabilities([0.25] * 4, [0.0, 0.0, 0.0, -1e4], floor=0.01)
    assert P.sum() == pytest.approx(1.0)
    assert P.min() == pytest.approx(0.01)


def test_entropy_of_uniform_and_certain():
    assert entropy(np.full(4, 0.25)) == pytest.approx(np.log(4))
    assert entropy(np.array([0.0, 1.0, 0.0, 0.0])) == 0.0


def test_no_features_no_likelihood():
    assert feature_log_likelihood(0, DELTA_O, SIGMA_O) == 0.0


def test_an_action_that_matches_every_model_equally_teaches_nothing():
    P = np.array([0.4, 0.3, 0.2, 0.1])
    W = np.full((4, 4), 25)
    assert expected_entropy(P, W, DELTA_O, SIGMA_O) == pytest.approx(entropy(P))


def test_the_view_of_the_unique_faces_is_the_best_action():
    P = np.full(4, 0.25)
    shared = np.full((4, 4), 40)
    unique = 5 + 60 * np.eye(4, dtype=int)
    best, gains = next_best_action(P, np.stack([shared, unique]), DELTA_O, SIGMA_O)
    assert best == 1
    assert gains[0] == pytest.approx(0.0, abs=1e-12) and gains[1] > 1.0


# The notebook's checks (lab.exercises), where the course package is installed: they name a mistake
# ("transposed axes", "a wrong sign", "missing normalisation") where the tests above only fail.
@pytest.mark.parametrize(
    "check, function", [("check_entropy", "entropy"), ("check_model_probabilities", "model_probabilities")]
)
def test_the_notebooks_check_says_correct(check, function):
    exercises = pytest.importorskip("lab.exercises")
    feedback = getattr(exercises, check)(globals()[function])
    assert feedback.correct, str(feedback)
