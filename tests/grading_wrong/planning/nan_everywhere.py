"""Every function returns NaN of the right shape.

Base: reference
Fails: *
"""

import numpy as np


def model_probabilities(P_prior, log_likelihood, floor=0.0):
    return np.full(np.shape(P_prior), np.nan)


def entropy(P):
    return float("nan")


def feature_log_likelihood(W, delta_o, Sigma_o):
    return np.full(np.shape(W), np.nan)


def expected_entropy(P, W, delta_o, Sigma_o):
    return float("nan")


def next_best_action(P, W_actions, delta_o, Sigma_o):
    return float("nan"), np.full(len(W_actions), np.nan)
