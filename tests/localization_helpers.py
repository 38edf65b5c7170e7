"""What the localizer's tests share: central differences for Jacobians, and the localizer without its
observation floor (the fit's own covariance only), for comparisons with filterpy."""

from __future__ import annotations

import numpy as np

from lab.geometry import wrap_angle

#: ``LocalizerConfig(**NO_FLOOR)``: every term of ``LocalizerConfig.observation_floor`` zero, and the
#: filter over the pose alone (no odometry calibration in the state): filterpy's 3-state peer.
NO_FLOOR = {
    "odometry_calibration": False,
    "obs_sigma_m": 0.0,
    "obs_sigma_rel": 0.0,
    "obs_sigma_per_m": 0.0,
    "obs_sigma_rel_across": 0.0,
    "obs_sigma_rad": 0.0,
}


def num_jac(f, x, eps=1e-6):
    """``df/dx`` by central differences; the third entry of a 3-vector or longer (a heading) is wrapped."""
    x = np.asarray(x, float)
    cols = []
    for i in range(len(x)):
        d = np.zeros_like(x)
        d[i] = eps
        diff = f(x + d) - f(x - d)
        if len(diff) >= 3:
            diff[2] = wrap_angle(diff[2])
        cols.append(diff / (2 * eps))
    return np.stack(cols, axis=1)
