"""Every function returns NaN of the right shape; astar a path of no cells with a NaN total.

Base: reference
Fails: *
"""

import numpy as np


def detection_likelihood(shape, cell, detected, alpha, beta):
    return np.full(shape, np.nan)


def update_probability_map(P, cell, detected, alpha, beta):
    return np.full(np.shape(P), np.nan)


def octile_heuristic(cell, goal, min_cost):
    return float("nan")


def astar(cost, start, goal):
    return np.zeros((0, 2), dtype=int), float("nan")
