"""Synthetic box databases and lookup tables: any number of models, without rendering.

For property tests, benchmarks at scale (the paper's future work: "numerous database objects") and
notebooks. The boxes imitate the identification database: every model is a cube whose faces -X, +Y
and -Y carry one shared page (the same points and descriptors in every model, and on each of the three
faces) and whose +X face carries a page of its own. A feature is seen from a ring viewpoint when its
face turns towards the camera by more than ``min_cos``.
"""

from __future__ import annotations

import numpy as np

from lab.identification.shared import shared_features
from lab.identification.tables import LookupTables
from lab.identification.viewpoints import viewpoint_directions
from lab.vision import FeatureDatabase

__all__ = ["synthetic_box_databases", "synthetic_tables"]

_FACES = {"+X": (0, 1.0), "-X": (0, -1.0), "+Y": (1, 1.0), "-Y": (1, -1.0)}


def _page(rng: np.random.Generator, n: int, half: float) -> tuple[np.ndarray, np.ndarray]:
    """n points (u, v) on a face and their descriptors (non-negative, norm 512 like SIFT's)."""
    uv = rng.uniform(-0.9 * half, 0.9 * half, (n, 2))
    d = rng.random((n, 128)) ** 3
    d = 512.0 * d / np.linalg.norm(d, axis=1, keepdims=True)
    return uv, d.astype(np.float32)


def _on_face(face: str, uv: np.ndarray, half: float) -> np.ndarray:
    axis, sign = _FACES[face]
    p = np.zeros((len(uv), 3))
    other = 1 - axis
    p[:, axis] = sign * half
    p[:, other] = uv[:, 0] * (-sign if axis == 0 else sign)  # the page reads the same way on every face
    p[:, 2] = uv[:, 1]
    return p


def synthetic_box_databases(
    n_models: int,
    rng: np.random.Generator,
    n_per_face: int = 30,
    size: float = 0.28,
    step_deg: float = 10.0,
    elevation_deg: float = 12.0,
    min_cos: float = 0.35,
) -> list[FeatureDatabase]:
    """``n_models`` box databases ``S0, S1, ...``: three shared faces and one unique face each.

    Feature order: the shared page on -X, +Y, -Y (identical in every model), then the unique page on +X.
    """
    half = size / 2
    shared_uv, shared_d = _page(rng, n_per_face, half)
    az = np.radians(np.arange(0.0, 360.0, step_deg))
    viewpoints = np.stack([az, np.full_like(az, np.radians(elevation_deg))], axis=1)
    U = viewpoint_directions(viewpoints)  # (V, 3)
    dbs = []
    for m in range(n_models):
        uniq_uv, uniq_d = _page(rng, n_per_face, half)
        pts, desc, normals = [], [], []
        for face, (uv, d) in (
            ("-X", (shared_uv, shared_d)),
            ("+Y", (shared_uv, shared_d)),
            ("-Y", (shared_uv, shared_d)),
            ("+X", (uniq_uv, uniq_d)),
        ):
            axis, sign = _FACES[face]
            pts.append(_on_face(face, uv, half))
            desc.append(d)
            n = np.zeros((len(uv), 3))
            n[:, axis] = sign
            normals.append(n)
        points_O, normals_O = np.concatenate(pts), np.concatenate(normals)
        seen_from = normals_O @ U.T > min_cos  # (N, V)
        dbs.append(
            FeatureDatabase(
                f"S{m}",
                points_O,
                np.concatenate(desc),
                seen_from,
                viewpoints,
                np.full(3, size),
                np.full((8, 8), 1 / 64, np.float32),
                {"synthetic": True},
            )
        )
    return dbs


def synthetic_tables(
    dbs: list[FeatureDatabase], p_match: float = 0.6, p_false: float = 0.01, n_levels: int = 16
) -> LookupTables:
    """Lookup tables for :func:`synthetic_box_databases`, without rendering.

    True model ``M_i`` seen from viewpoint ``v``: a feature ``l`` of ``M_j`` that ``M_j``'s database
    saw from ``v`` matches with probability ``p_match`` when it is on a shared face (or ``i = j``), and
    ``p_false`` otherwise (a unique page matched by chance).
    """
    L = len(dbs)
    n_shared = 3 * (len(dbs[0]) // 4)
    P = []
    for i in range(L):
        row = []
        for j in range(L):
            seen = dbs[j].seen_from.T.astype(float)  # (V, N_j)
            shared = np.arange(len(dbs[j])) < n_shared
            p = np.where(shared | (i == j), p_match, p_false)
            row.append(seen * p[None, :])
        P.append(row)
    return LookupTables([db.name for db in dbs], dbs[0].viewpoints, P, n_levels, shared_features(dbs))
