"""update_probability_map returns the prior unchanged (a probability map, but no update).

Base: reference
Fails: map_update_normalised, map_update_miss, map_update_hit, map_update_other_cells, map_update_sequence
"""

import numpy as np


def update_probability_map(P, cell, detected, alpha, beta):
    return np.array(P, dtype=float)
