"""The template with every function answering something of the right shape and nothing more: the
identity rotation, the features where they are, a zero Jacobian, the prior back, a zero likelihood.

Base: template
Fails: *
"""

import numpy as np


def rotation_zyx(alpha, beta, gamma):
    return np.eye(3)


def measurement_model(X, b_O):
    return np.asarray(b_O, dtype=float).reshape(-1, 3).copy()


def measurement_jacobian(X, b_O):
    return np.zeros((3 * np.asarray(b_O).reshape(-1, 3).shape[0], 6))


def kalman_update(mu_bar, Sigma_bar, y, C, Sigma_m):
    return np.asarray(mu_bar, dtype=float), np.asarray(Sigma_bar, dtype=float)


def data_log_likelihood(y, C, Sigma_bar, Sigma_m):
    return 0.0


def ekf_update(mu_bar, Sigma_bar, d_C, b_O, Sigma_m):
    return np.asarray(mu_bar, dtype=float), np.asarray(Sigma_bar, dtype=float)
