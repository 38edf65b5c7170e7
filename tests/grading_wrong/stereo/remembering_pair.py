"""A wrong pair that remembers: each function records what it returned for which input, and when
asked to invert one of its own answers gives the remembered input back. For anything it has not seen
it returns made-up values, so a test that only checks that triangulate and project undo each other
within one run passes without either function being right.

Base: reference
Fails: triangulate_matches_opencv, triangulate_invalid_disparity, project_matches_opencv, round_trip
"""

import numpy as np

_seen_points = {}  # row of a returned point -> the pixel it was made from
_seen_pixels = {}  # row of a returned pixel -> the point it was made from


def _key(row):
    return np.round(np.asarray(row, dtype=float), 9).tobytes()


def triangulate(uv, disparity, f, cx, cy, baseline):
    uv = np.asarray(uv, dtype=float).reshape(-1, 2)
    d = np.asarray(disparity, dtype=float).reshape(-1)
    out = np.full((d.size, 3), np.nan)
    for k in range(d.size):
        if not d[k] > 0:
            continue
        out[k] = _seen_pixels.get(_key(uv[k]), [uv[k, 0] / 100.0, uv[k, 1] / 100.0, 1.0 + k])
        _seen_points[_key(out[k])] = uv[k]
    return out


def project(points_C, f, cx, cy):
    p = np.asarray(points_C, dtype=float).reshape(-1, 3)
    out = np.full((p.shape[0], 2), np.nan)
    for k in range(p.shape[0]):
        if not p[k, 2] > 0:
            continue
        out[k] = _seen_points.get(_key(p[k]), [7.0 * k, 3.0 * k + 1.0])
        _seen_pixels[_key(out[k])] = p[k]
    return out
