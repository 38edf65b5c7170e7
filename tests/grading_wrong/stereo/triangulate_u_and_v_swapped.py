"""triangulate takes x from the row v and y from the column u (the image axes mixed up).

Base: reference
Fails: triangulate_matches_opencv, triangulate_invalid_disparity, round_trip
"""

import numpy as np


def triangulate(uv, disparity, f, cx, cy, baseline):
    uv = np.asarray(uv, dtype=float).reshape(-1, 2)
    d = np.asarray(disparity, dtype=float).reshape(-1)
    out = np.full((d.size, 3), np.nan)
    ok = d > 0
    Z = f * baseline / d[ok]
    out[ok, 0] = (uv[ok, 1] - cy) * Z / f
    out[ok, 1] = (uv[ok, 0] - cx) * Z / f
    out[ok, 2] = Z
    return out
