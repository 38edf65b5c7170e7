"""Synthetic scenes for the navigation tests: random cost grids, and stereo views of a floor with boxes
(ground truth by ray casting).

A pinhole camera on the robot's pan-tilt head casts one ray per pixel against a (possibly tilted and
offset) floor plane and axis-aligned boxes standing on it. Stereo noise is modelled where it arises:
a disparity error ``N(0, sigma_d)`` [px], so the depth error grows with the square of the depth and
lies along the ray, ``Z' = f b / (f b / Z + e)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lab.geometry import Pose2D, transform_points
from lab.navigation.costmap import CostGrid
from lab.navigation.grid import GridSpec
from lab.robot import StereoCamera


@dataclass(frozen=True)
class Box:
    """An axis-aligned box standing on the floor: footprint ``[x0, x1] x [y0, y1]``, top at ``z1`` [m]."""

    x0: float
    x1: float
    y0: float
    y1: float
    z1: float
    z0: float = -1.0  # reaches below the floor so it meets a tilted floor everywhere

    def footprint_cells(self, spec) -> np.ndarray:
        """Cells of ``spec`` whose square overlaps the footprint (bool, shape spec.shape)."""
        (ox, oy), r = spec.origin_xy, spec.resolution
        i0, i1 = math.floor((self.x0 - ox) / r), math.ceil((self.x1 - ox) / r)
        j0, j1 = math.floor((self.y0 - oy) / r), math.ceil((self.y1 - oy) / r)
        m = np.zeros(spec.shape, dtype=bool)
        m[max(i0, 0) : max(i1, 0), max(j0, 0) : max(j1, 0)] = True
        return m


@dataclass(frozen=True)
class Floor:
    """The floor ``z = z0 + x tan(tilt_x) + y tan(tilt_y)``."""

    z0: float = 0.0
    tilt_x: float = 0.0
    tilt_y: float = 0.0

    @property
    def normal(self) -> np.ndarray:
        n = np.array([-math.tan(self.tilt_x), -math.tan(self.tilt_y), 1.0])
        return n / np.linalg.norm(n)

    @property
    def offset(self) -> float:
        return -self.z0 * self.normal[2]


def cast(origin: np.ndarray, dirs: np.ndarray, floor: Floor, boxes) -> tuple[np.ndarray, np.ndarray]:
    """Ray depths ``t`` (along unit-free ``dirs``) to the first hit, and which thing was hit (-1 floor)."""
    n, d = floor.normal, floor.offset
    denom = dirs @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        t_best = np.where(denom < -1e-9, -(origin @ n + d) / denom, np.inf)
    hit = np.full(len(dirs), -2)
    hit[np.isfinite(t_best)] = -1
    for k, b in enumerate(boxes):
        lo = np.array([b.x0, b.y0, b.z0])
        hi = np.array([b.x1, b.y1, b.z1])
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (lo - origin) / dirs
            t2 = (hi - origin) / dirs
        tmin = np.nanmax(np.minimum(t1, t2), axis=1)
        tmax = np.nanmin(np.maximum(t1, t2), axis=1)
        ok = (tmax >= tmin) & (tmin > 0) & (tmin < t_best)
        t_best = np.where(ok, tmin, t_best)
        hit = np.where(ok, k, hit)
    return t_best, hit


def stereo_view(
    pose: Pose2D,
    floor: Floor,
    boxes,
    rng: np.random.Generator,
    *,
    pan: float = 0.0,
    tilt: float = math.radians(-25.0),
    sigma_d: float = 0.2,
    camera: StereoCamera | None = None,
    max_depth: float = 6.0,
) -> tuple[np.ndarray, np.ndarray]:
    """World points triangulated from one noisy stereo view, and what each pixel truly hit.

    Returns
    -------
    points_W : ndarray, shape (n, 3) [m]
    hit : ndarray, shape (n,), int
        Index of the box hit, or -1 for the floor.
    """
    cam = camera or StereoCamera.from_fov(320, 240, 60.0, 0.12)
    u, v = np.meshgrid(np.arange(cam.width), np.arange(cam.height))
    rays_C = np.stack([(u.ravel() - cam.cx) / cam.fx, (v.ravel() - cam.cy) / cam.fy, np.ones(u.size)], axis=1)
    G_WC = pose.G() @ cam.G_RC(pan, tilt)
    origin = G_WC[:3, 3]
    dirs_W = rays_C @ G_WC[:3, :3].T  # a ray's parameter t is then its depth Z in the camera
    Z, hit = cast(origin, dirs_W, floor, boxes)
    keep = np.isfinite(Z) & (Z < max_depth) & (hit > -2)
    Z, hit, rays_C = Z[keep], hit[keep], rays_C[keep]
    fb = cam.fx * cam.baseline
    disparity = fb / Z + rng.normal(0.0, sigma_d, Z.shape)
    ok = disparity > fb / max_depth
    Z_noisy = fb / disparity[ok]
    p_C = rays_C[ok] * Z_noisy[:, None]
    return transform_points(G_WC, p_C), hit[ok]


def random_grid(rng, shape=None, res=None) -> CostGrid:
    """A random cost grid: 0-45 % blocked cells, multipliers in {1, 1.5, 2, 4} (or all 1), a random origin."""
    shape = shape or tuple(int(v) for v in rng.integers(4, 28, size=2))
    res = res or float(rng.choice([0.05, 0.1, 0.25, 1.0]))
    density = rng.uniform(0.0, 0.45)
    cost = rng.choice([1.0, 1.0, 1.0, 1.5, 2.0, 4.0], size=shape)
    if rng.random() < 0.3:
        cost[:] = 1.0  # uniform costs: many equal-cost paths, the hard case for tie-breaking
    cost[rng.random(shape) < density] = np.inf
    return CostGrid(GridSpec((float(rng.uniform(-3, 3)), float(rng.uniform(-3, 3))), res, shape), cost)
