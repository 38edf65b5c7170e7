"""Public tests of assignment 3: run them with ``python -m pytest test_search.py``."""

import math

import numpy as np
import pytest
from search import astar, detection_likelihood, octile_heuristic, update_probability_map


def test_detection_model_in_the_cell_looked_at():
    lik = detection_likelihood((4, 3), (1, 2), True, alpha=0.1, beta=0.3)
    assert lik.shape == (4, 3)
    assert lik[1, 2] == pytest.approx(0.7)  # detected, and it is there: 1 - beta
    assert lik[0, 0] == pytest.approx(0.1)  # detected, but it is elsewhere: a false alarm


def test_a_miss_moves_probability_away_from_the_cell():
    P = np.full((5, 5), 1 / 25)
    Q = update_probability_map(P, (2, 2), False, alpha=0.05, beta=0.2)
    assert Q.sum() == pytest.approx(1.0)
    assert Q[2, 2] < P[2, 2] and Q[0, 0] > P[0, 0]
    # Bayes by hand: beta P / (beta P + (1 - alpha)(1 - P)) with P = 1/25
    assert Q[2, 2] == pytest.approx(0.2 / 25 / (0.2 / 25 + 0.95 * 24 / 25))


def test_a_perfect_sensor_finds_the_object_at_once():
    P = np.full((3, 3), 1 / 9)
    Q = update_probability_map(P, (0, 1), True, alpha=1e-12, beta=1e-12)
    assert Q[0, 1] == pytest.approx(1.0)


def test_octile_distance():
    assert octile_heuristic((0, 0), (3, 4), 1.0) == pytest.approx(4 + 3 * (math.sqrt(2) - 1))
    assert octile_heuristic((5, 5), (5, 5), 2.0) == 0.0


def test_astar_on_open_floor_goes_diagonally():
    path, total = astar(np.ones((6, 6)), (0, 0), (5, 5))
    assert total == pytest.approx(5 * math.sqrt(2))
    assert [tuple(p) for p in path] == [(k, k) for k in range(6)]


def test_astar_goes_round_a_wall():
    cost = np.ones((7, 7))
    cost[3, :6] = np.inf
    path, total = astar(cost, (0, 0), (6, 0))
    assert tuple(path[0]) == (0, 0) and tuple(path[-1]) == (6, 0)
    assert all(np.isfinite(cost[tuple(p)]) for p in path)
    # the only way is through the gap at column 6 and back: 4 diagonal steps and 10 straight ones
    assert total == pytest.approx(10 + 4 * math.sqrt(2))


def test_astar_without_a_path():
    cost = np.ones((5, 5))
    cost[2, :] = np.inf
    path, total = astar(cost, (0, 0), (4, 4))
    assert len(path) == 0 and total == math.inf


# The notebook's checks (lab.exercises), where the course package is installed: they name a mistake
# ("transposed axes", "a wrong sign", "missing normalisation") where the tests above only fail.
@pytest.mark.parametrize(
    "check, function",
    [
        ("check_detection_likelihood", "detection_likelihood"),
        ("check_map_update", "update_probability_map"),
        ("check_octile_heuristic", "octile_heuristic"),
    ],
)
def test_the_notebooks_check_says_correct(check, function):
    exercises = pytest.importorskip("lab.exercises")
    feedback = getattr(exercises, check)(globals()[function])
    assert feedback.correct, str(feedback)
