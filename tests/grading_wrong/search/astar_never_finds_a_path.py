"""astar always answers "no path".

Base: reference
Fails: astar_valid_path, astar_optimal, astar_no_path, astar_large_map
"""

import math

import numpy as np


def astar(cost, start, goal):
    return np.zeros((0, 2), dtype=int), math.inf
