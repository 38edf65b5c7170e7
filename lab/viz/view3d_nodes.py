"""The pieces of a recorded 3D view (:mod:`lab.viz.view3d`): its nodes and timeline steps, and the
shapes several parts of the scene share (covariance ellipsoids, camera frustums, colours)."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "N_SIGMA",
    "Node",
    "Step3D",
    "ellipsoid_axes",
    "ellipsoid_mesh",
    "cmap_rgb",
    "ellipse_xy",
    "frustum_node",
]

N_SIGMA = 3.0  # the ellipses' and ellipsoids' size in standard deviations


@dataclass(frozen=True)
class Node:
    """One object of the scene: ``kind`` (box, cylinder, lines, points, frustum, mesh, image, label)
    and its properties in the world frame W (positions [m], colours RGB 0-255)."""

    kind: str
    props: dict = field(repr=False)


@dataclass(frozen=True)
class Step3D:
    """One step of the timeline: the sim time ``t`` [s], what happened, and the nodes it adds or replaces
    (by name; None removes the node)."""

    t: float
    label: str
    nodes: dict = field(repr=False)


def ellipsoid_axes(Sigma: np.ndarray, n_sigma: float = N_SIGMA) -> tuple[np.ndarray, np.ndarray]:
    """Semi-axes [m] and their directions (columns) of the ``n_sigma`` ellipsoid of a 3-D covariance.

    The ellipsoid ``x^T Sigma^-1 x = n_sigma^2`` has semi-axes ``n_sigma * sqrt(lambda_k)`` along the
    eigenvectors of ``Sigma`` [m^2]."""
    w, V = np.linalg.eigh(0.5 * (Sigma + Sigma.T))
    return n_sigma * np.sqrt(np.maximum(w, 0.0)), V


def _sphere(n_lat: int = 8, n_lon: int = 14) -> tuple[np.ndarray, np.ndarray]:
    """A unit UV sphere: vertices (n, 3), triangle faces (m, 3)."""
    lat = np.linspace(0, math.pi, n_lat + 1)
    lon = np.linspace(0, 2 * math.pi, n_lon, endpoint=False)
    v = np.array(
        [[math.sin(a) * math.cos(b), math.sin(a) * math.sin(b), math.cos(a)] for a in lat for b in lon]
    )
    f = []
    for i in range(n_lat):
        for j in range(n_lon):
            a, b = i * n_lon + j, i * n_lon + (j + 1) % n_lon
            c, d = a + n_lon, b + n_lon
            f += [(a, c, b), (b, c, d)]
    return v, np.array(f, dtype=np.uint32)


_SPHERE = _sphere()


def ellipsoid_mesh(centre, Sigma) -> Node:
    """The ``N_SIGMA`` ellipsoid of a 3-D covariance [m^2] around ``centre`` [m] as a triangle mesh."""
    axes, V = ellipsoid_axes(Sigma)
    verts = _SPHERE[0] @ (V * axes).T + np.asarray(centre, float)
    return Node("mesh", {"vertices": verts, "faces": _SPHERE[1], "axes": axes, "directions": V})


@functools.cache
def _colormap(name: str):
    from matplotlib import colormaps

    return colormaps[name]  # a copy each time it is looked up: once per name


def cmap_rgb(cmap: str, x: float) -> tuple[int, int, int]:
    """The colour of ``x`` in [0, 1] on the matplotlib colour map ``cmap``, RGB 0-255."""
    r, g, b, _ = _colormap(cmap)(float(np.clip(x, 0.0, 1.0)))
    return int(255 * r), int(255 * g), int(255 * b)


def frustum_node(G_WC: np.ndarray, camera, color=(255, 140, 0), scale: float = 0.35) -> Node:
    """A camera's frustum at the pose ``G_WC`` (C in W) with the camera model's field of view."""
    fov = 2.0 * math.atan(0.5 * camera.height / camera.fy)
    return Node(
        "frustum",
        {"G_W": G_WC, "fov": fov, "aspect": camera.width / camera.height, "scale": scale, "color": color},
    )


def ellipse_xy(centre_xy, Sigma_xy, z: float, n: int = 36) -> np.ndarray:
    """Segments (n, 2, 3) of the ``N_SIGMA`` ellipse of a 2-D covariance [m^2] at height ``z``."""
    w, V = np.linalg.eigh(0.5 * (Sigma_xy + Sigma_xy.T))
    a = np.linspace(0, 2 * math.pi, n + 1)
    pts = (V @ (N_SIGMA * np.sqrt(np.maximum(w, 0))[:, None] * np.stack([np.cos(a), np.sin(a)]))).T
    pts = np.column_stack([pts + np.asarray(centre_xy, float), np.full(n + 1, z)])
    return np.stack([pts[:-1], pts[1:]], axis=1)
