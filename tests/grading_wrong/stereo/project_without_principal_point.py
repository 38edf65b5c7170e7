"""project forgets the principal point: u = f x / z instead of f x / z + cx (and v likewise).

Base: reference
Fails: project_matches_opencv, round_trip
"""

import numpy as np


def project(points_C, f, cx, cy):
    p = np.asarray(points_C, dtype=float).reshape(-1, 3)
    out = np.full((p.shape[0], 2), np.nan)
    ok = p[:, 2] > 0
    out[ok, 0] = f * p[ok, 0] / p[ok, 2]
    out[ok, 1] = f * p[ok, 1] / p[ok, 2]
    return out
