"""expected_entropy averages the hypothetical entropies with equal weights instead of weighting them
by the current model probabilities.

Base: reference
Fails: expected_entropy_value, expected_entropy_properties, next_best_action_choice
"""

import numpy as np


def expected_entropy(P, W, delta_o, Sigma_o):
    P = np.asarray(P, dtype=float)
    log_lik = feature_log_likelihood(np.asarray(W), delta_o, Sigma_o)  # noqa: F821
    return float(np.mean([entropy(model_probabilities(P, log_lik[i])) for i in range(P.size)]))  # noqa: F821
