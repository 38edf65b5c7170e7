"""The template with every function answering something of the right shape and nothing more: zeros
(NaN rows where the docstring asks for them).

Base: template
Fails: *
"""

import numpy as np


def triangulate(uv, disparity, f, cx, cy, baseline):
    d = np.asarray(disparity, dtype=float).reshape(-1)
    out = np.zeros((d.size, 3))
    out[~(d > 0)] = np.nan
    return out


def project(points_C, f, cx, cy):
    p = np.asarray(points_C, dtype=float).reshape(-1, 3)
    out = np.zeros((p.shape[0], 2))
    out[~(p[:, 2] > 0)] = np.nan
    return out


def depth_std(Z, f, baseline, sigma_disparity):
    return np.zeros(np.shape(Z))
