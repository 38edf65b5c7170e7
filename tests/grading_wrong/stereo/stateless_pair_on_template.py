"""The issue's attack as it came (issue 48: it scored 1/6): the released template with only the wrong
pair written: triangulate keeps the pixels and puts f b / d as the third coordinate, project drops it.

Base: template
Fails: *
"""

import numpy as np


def triangulate(uv, disparity, f, cx, cy, baseline):
    uv = np.asarray(uv, dtype=float).reshape(-1, 2)
    d = np.asarray(disparity, dtype=float).reshape(-1)
    out = np.full((d.size, 3), np.nan)
    ok = d > 0
    out[ok, :2] = uv[ok]
    out[ok, 2] = f * baseline / d[ok]
    return out


def project(points_C, f, cx, cy):
    p = np.asarray(points_C, dtype=float).reshape(-1, 3)
    out = np.full((p.shape[0], 2), np.nan)
    ok = p[:, 2] > 0
    out[ok] = p[ok, :2]
    return out
