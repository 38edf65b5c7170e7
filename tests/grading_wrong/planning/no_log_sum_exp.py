"""model_probabilities exponentiates the log-likelihoods directly: exp(-5000) is 0.0, so the
posterior is 0/0 for very negative log-likelihoods (and overflows for large positive ones).

Base: reference
Fails: posterior_log_space, expected_entropy_properties
"""

import numpy as np


def model_probabilities(P_prior, log_likelihood, floor=0.0):
    with np.errstate(all="ignore"):
        post = np.asarray(P_prior, dtype=float) * np.exp(np.asarray(log_likelihood, dtype=float))
        post = post / post.sum()
    return floor + (1.0 - post.size * floor) * post
