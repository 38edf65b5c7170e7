"""feature_log_likelihood with the paper's printed normalisation (2 pi)^(W/2): log 2 pi instead of
3 log 2 pi per feature.

Base: reference
Fails: feature_log_likelihood_eq15, expected_entropy_value, expected_entropy_properties,
    next_best_action_choice
"""

import numpy as np


def feature_log_likelihood(W, delta_o, Sigma_o):
    delta_o, Sigma_o = np.asarray(delta_o, dtype=float), np.asarray(Sigma_o, dtype=float)
    _, log_det = np.linalg.slogdet(Sigma_o)
    per_feature = -0.5 * (np.log(2.0 * np.pi) + log_det + delta_o @ np.linalg.solve(Sigma_o, delta_o))
    return np.asarray(W, dtype=float) * per_feature
