"""ekf_update stacks the innovation coordinate by coordinate (all x, then all y, then all z) while the
Jacobian stacks feature by feature.

Base: reference
Fails: ekf_update_one_step, ekf_consistency
"""

import numpy as np


def ekf_update(mu_bar, Sigma_bar, d_C, b_O, Sigma_m):
    mu_bar = np.asarray(mu_bar, dtype=float)
    y = (np.asarray(d_C, dtype=float) - measurement_model(mu_bar, b_O)).T.reshape(-1)  # noqa: F821
    return kalman_update(mu_bar, Sigma_bar, y, measurement_jacobian(mu_bar, b_O), Sigma_m)  # noqa: F821
