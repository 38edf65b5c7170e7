"""The template with the three answers a do-nothing submission has (issue 48): a map update that
returns the map unchanged, a heuristic of 0, an A* that never finds a path.

Base: template
Fails: *
"""

import math

import numpy as np


def update_probability_map(P, cell, detected, alpha, beta):
    return np.array(P, dtype=float)


def octile_heuristic(cell, goal, min_cost):
    return 0.0


def astar(cost, start, goal):
    return np.zeros((0, 2), dtype=int), math.inf
