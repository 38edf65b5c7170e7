"""kalman_update uses the short covariance update (I - K C) Sigma_bar instead of the Joseph form, with
an explicit inverse: equal in exact arithmetic, not symmetric under round-off.

Base: reference
Fails: kalman_update_covariance
"""

import numpy as np


def kalman_update(mu_bar, Sigma_bar, y, C, Sigma_m):
    mu_bar, Sigma_bar, y, C, Sigma_m = (
        np.asarray(a, dtype=float) for a in (mu_bar, Sigma_bar, y, C, Sigma_m)
    )
    K = Sigma_bar @ C.T @ np.linalg.inv(C @ Sigma_bar @ C.T + Sigma_m)
    return mu_bar + K @ y, (np.eye(mu_bar.size) - K @ C) @ Sigma_bar
