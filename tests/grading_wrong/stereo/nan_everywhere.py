"""Every function returns NaN of the right shape.

Base: reference
Fails: *
"""

import numpy as np


def triangulate(uv, disparity, f, cx, cy, baseline):
    return np.full((np.asarray(disparity).size, 3), np.nan)


def project(points_C, f, cx, cy):
    return np.full((np.asarray(points_C).reshape(-1, 3).shape[0], 2), np.nan)


def depth_std(Z, f, baseline, sigma_disparity):
    return np.full(np.shape(Z), np.nan)
