"""Every function returns NaN of the right shape.

Base: reference
Fails: *
"""

import numpy as np


def rotation_zyx(alpha, beta, gamma):
    return np.full((3, 3), np.nan)


def measurement_model(X, b_O):
    return np.full(np.asarray(b_O).reshape(-1, 3).shape, np.nan)


def measurement_jacobian(X, b_O):
    return np.full((3 * np.asarray(b_O).reshape(-1, 3).shape[0], 6), np.nan)


def kalman_update(mu_bar, Sigma_bar, y, C, Sigma_m):
    return np.full(6, np.nan), np.full((6, 6), np.nan)


def data_log_likelihood(y, C, Sigma_bar, Sigma_m):
    return float("nan")


def ekf_update(mu_bar, Sigma_bar, d_C, b_O, Sigma_m):
    return np.full(6, np.nan), np.full((6, 6), np.nan)
