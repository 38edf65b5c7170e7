"""detection_likelihood gives the detection probabilities also for a miss (y = 0 not complemented).

Base: reference
Fails: detection_likelihood_eq2, map_update_normalised, map_update_miss, map_update_other_cells,
    map_update_sequence
"""

import numpy as np


def detection_likelihood(shape, cell, detected, alpha, beta):
    lik = np.full(shape, alpha, dtype=float)
    lik[int(cell[0]), int(cell[1])] = 1.0 - beta
    return lik
