"""Notebook 03's checks: the detection model (Eq. (2)), the map update (Eqs. (1)-(3)) and A*'s octile
heuristic (assignment ``search``).

See :mod:`lab.exercises` for what a check does and how it avoids carrying the answer.
"""

from __future__ import annotations

import math

import numpy as np

from lab.exercises.feedback import Feedback, Mistake, answer_array, call_answer, checked, verdict

__all__ = ["check_detection_likelihood", "check_map_update", "check_octile_heuristic"]

_SHAPE, _CELL = (5, 4), (1, 3)


def _eq2(shape, cell, detected, alpha, beta):
    """P(y | h_ij = 1) of Eq. (2), written out cell by cell."""
    L = np.empty(shape)
    for i in range(shape[0]):
        for j in range(shape[1]):
            there = (i, j) == tuple(cell)
            p_miss = beta if there else 1 - alpha  # P(y = 0 | h_ij = 1)
            L[i, j] = 1 - p_miss if detected else p_miss
    return L


@checked
def check_detection_likelihood(detection_likelihood) -> Feedback:
    """Check ``detection_likelihood(shape, cell, detected, alpha, beta) -> L``, ``L[i, j] = P(y | h_ij = 1)``
    of Eq. (2) of the search paper, after a detection and after a miss."""
    name = "detection_likelihood"
    a, b = 0.1, 0.3
    got = np.concatenate(
        [
            answer_array(
                name, call_answer(name, detection_likelihood, _SHAPE, _CELL, y, a, b), _SHAPE
            ).ravel()
            for y in (True, False)
        ]
    )
    ref = lambda shape, cell, a_, b_, flip=False: np.concatenate(  # noqa: E731
        [_eq2(shape, cell, y != flip, a_, b_).ravel() for y in (True, False)]
    )
    want = ref(_SHAPE, _CELL, a, b)
    mistakes = [
        Mistake(
            "swapped_rates",
            "alpha and beta swapped: alpha is the false-alarm rate, beta the missed detection",
            ref(_SHAPE, _CELL, b, a),
        ),
        Mistake(
            "outcome",
            "the likelihood of the other outcome: for a detection (y = 1) it is 1 - beta in the cell",
            ref(_SHAPE, _CELL, a, b, True),
        ),
        Mistake(
            "transposed",
            "transposed axes: the cell is (row i, column j) = cell[0], cell[1]",
            ref(_SHAPE, _CELL[::-1], a, b),
        ),
    ]
    return verdict(
        name,
        got,
        want,
        1e-12,
        mistakes,
        "not Eq. (2): 1 - beta / beta in the cell, alpha / 1 - alpha elsewhere",
    )


def _map_prior():
    rng = np.random.default_rng(5)
    P = rng.uniform(0.2, 1.0, _SHAPE)
    return P / P.sum()


@checked
def check_map_update(update_probability_map) -> Feedback:
    """Check ``update_probability_map(P, cell, detected, alpha, beta) -> P_post``, Eqs. (1)-(3) of the search
    paper, against the posterior taken from the joint distribution ``p(h, y)`` of the hypotheses and the
    measurement."""
    name = "update_probability_map"
    P = _map_prior()
    a, b = 0.1, 0.3

    def post(cell, detected, a_, b_, normalise=True):
        joint = _eq2(_SHAPE, cell, detected, a_, b_) * P  # p(h_ij = 1, y)
        return joint / joint.sum() if normalise else joint

    got = np.concatenate(
        [
            answer_array(
                name, call_answer(name, update_probability_map, P.copy(), _CELL, y, a, b), _SHAPE
            ).ravel()
            for y in (True, False)
        ]
    )

    def both(cell=_CELL, flip=False, ab=(a, b), norm=True):  # the posteriors after a detection and a miss
        return np.concatenate([post(cell, y != flip, *ab, norm).ravel() for y in (True, False)])

    want = both()
    mistakes = [
        Mistake(
            "normalisation",
            "missing normalisation: divide by P(y) (Eq. (3)) so that the map sums to 1",
            both(norm=False),
        ),
        Mistake(
            "swapped_rates",
            "alpha and beta swapped: alpha is the false-alarm rate, beta the missed detection",
            both(ab=(b, a)),
        ),
        Mistake(
            "outcome",
            "the update of the other outcome: a detection (y = 1) must make the cell MORE probable",
            both(flip=True),
        ),
        Mistake(
            "transposed",
            "transposed axes: the cell is (row i, column j) = cell[0], cell[1]",
            both(cell=_CELL[::-1]),
        ),
    ]
    return verdict(
        name, got, want, 1e-12, mistakes, "not Eqs. (1)-(3): likelihood times prior, divided by their sum"
    )


_OCTILE_CASES = (((0, 0), (3, 7)), ((6, 2), (1, 5)), ((4, 4), (4, 0)), ((2, 8), (7, 3)))


@checked
def check_octile_heuristic(octile_heuristic) -> Feedback:
    """Check ``octile_heuristic(cell, goal, min_cost) -> h``, the cost of the cheapest 8-connected path on
    open floor where every cell costs ``min_cost`` (steps of length 1 and sqrt 2), against networkx's
    Dijkstra on that grid."""

    name = "octile_heuristic"
    m = 1.5
    got = answer_array(
        name, [call_answer(name, octile_heuristic, c, g, m) for c, g in _OCTILE_CASES], (len(_OCTILE_CASES),)
    )
    import networkx as nx  # after the answer ran: a stub costs nothing

    G = nx.Graph()
    for i in range(9):
        for j in range(9):
            for di, dj in ((1, 0), (0, 1), (1, 1), (1, -1)):
                if 0 <= i + di < 9 and 0 <= j + dj < 9:
                    G.add_edge((i, j), (i + di, j + dj), weight=m * math.hypot(di, dj))
    want = np.array([nx.dijkstra_path_length(G, c, g) for c, g in _OCTILE_CASES])
    delta = np.array([[abs(c[0] - g[0]), abs(c[1] - g[1])] for c, g in _OCTILE_CASES], float)
    mistakes = [
        Mistake(
            "euclidean",
            "that is the straight line: admissible, but on an 8-connected "
            "grid the exact cost is the octile distance",
            m * np.hypot(*delta.T),
        ),
        Mistake(
            "manhattan",
            "that is the Manhattan distance: it overestimates a diagonal step "
            "(sqrt 2 < 2), so A* may miss the cheapest path",
            m * delta.sum(1),
        ),
        Mistake("chebyshev", "a diagonal step costs sqrt 2 cells, not 1", m * delta.max(1)),
        Mistake("scale", "scale by min_cost: the heuristic is a cost, not a number of cells", want / m),
    ]
    return verdict(
        name, got, want, 1e-9, mistakes, "not the octile distance: max + (sqrt 2 - 1) min of the cell offsets"
    )
