"""Ground truth of a simulated world: true poses, collisions, occupancy, depth and segmentation.

For tests and evaluation only; the algorithms see the world through :class:`lab.sim.SimRobot`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from lab.errors import ConfigError
from lab.geometry import Pose2D, quat_xyzw_to_R, se3
from lab.sim.client import pybullet

if TYPE_CHECKING:
    from lab.sim.world import SimWorld

__all__ = ["BodyShape", "Truth"]

_SOLIDS = (pybullet.GEOM_BOX, pybullet.GEOM_CYLINDER)


@dataclass(frozen=True)
class BodyShape:
    """One solid of a simulated body, for display: ``shape`` "box" (``size`` = full extents x, y, z [m])
    or "cylinder" (``size`` = (radius, height) [m], along its z axis); ``G_W`` its centre's pose in the
    world; ``rgba`` its colour in [0, 1] (white for a textured body)."""

    name: str
    shape: str
    size: tuple[float, ...]
    G_W: np.ndarray = field(repr=False)
    rgba: tuple[float, float, float, float] = (0.7, 0.7, 0.7, 1.0)


class Truth:
    """Ground truth of a :class:`SimWorld`, for tests and evaluation only (never for the algorithms)."""

    def __init__(self, world: SimWorld):
        self._w = world

    def G_W(self, name: str) -> np.ndarray:
        """World pose (4x4) of a body's frame by name (its centre for scene bodies and boxes)."""
        pos, q = self._w.p.getBasePositionAndOrientation(self._w.body_id(name))
        return se3(quat_xyzw_to_R(q), pos)

    def robot_pose(self) -> Pose2D:
        r = self._w.robot
        if r is None:
            raise ConfigError("this world has no robot")
        return r.truth.pose()

    def G_WC(self) -> np.ndarray:
        """True pose of the robot's left camera frame C in the world (the pan-tilt axes' true angles)."""
        r = self._w.robot
        if r is None:
            raise ConfigError("this world has no robot")
        return r.truth.G_WC()

    def G_WC_exposed(self) -> np.ndarray:
        """True pose of the left camera when an image captured now was exposed (the camera latency
        before now; :meth:`G_WC` without one): the camera the frame's image shows the world from."""
        r = self._w.robot
        if r is None:
            raise ConfigError("this world has no robot")
        return r.truth.G_WC_exposed()

    @property
    def sensing(self):
        """The robot's sensing draws of this episode (:class:`lab.sim.sensing.EpisodeSensing`): the
        cameras the renderer uses, the light, the odometry's systematic errors, the pan-tilt's zeros."""
        r = self._w.robot
        if r is None:
            raise ConfigError("this world has no robot")
        return r.truth.sensing

    @property
    def collisions(self) -> int:
        r = self._w.robot
        return 0 if r is None else r.truth.collisions

    def shapes(self) -> list[BodyShape]:
        """Every body of the world as simple solids with their true poses (for display only: the
        recorded 3D view, :mod:`lab.viz.view3d`). A body's collision shape gives its solid (the visual
        shape where it has none, e.g. the robot's mast); textured bodies report white."""
        p, out = self._w.p, []
        for k in range(p.getNumBodies()):
            bid = p.getBodyUniqueId(k)
            name = self._w.body_name(bid) or f"body{bid}"
            pos, q = p.getBasePositionAndOrientation(bid)
            G_W = se3(quat_xyzw_to_R(q), pos)
            vis = p.getVisualShapeData(bid)
            rgba = tuple(float(c) for c in vis[0][7]) if vis else (0.7, 0.7, 0.7, 1.0)
            col = [c for c in p.getCollisionShapeData(bid, -1) if c[2] in _SOLIDS]
            # (type, dimensions, local position, local orientation) of the collision or the visual shape
            parts = [(c[2], c[3], c[5], c[6]) for c in col] or [
                (v[2], v[3], v[5], v[6]) for v in vis if v[1] == -1 and v[2] in _SOLIDS
            ]
            for j, (kind, dims, lp, lq) in enumerate(parts):
                G_local = se3(quat_xyzw_to_R(lq), lp)
                if kind == pybullet.GEOM_BOX:
                    size = (float(dims[0]), float(dims[1]), float(dims[2]))
                    shape = "box"
                else:  # a cylinder: (height, radius) from a collision shape, (length, radius) from a visual
                    size = (float(dims[1]), float(dims[0]))
                    shape = "cylinder"
                part = name if len(parts) == 1 else f"{name}#{j}"
                out.append(BodyShape(part, shape, size, G_W @ G_local, rgba))
        return out

    def occupancy(self, spec, z_min: float, z_max: float, exclude=("floor", "robot")) -> np.ndarray:
        """True occupancy of a floor grid: cells that a body's footprint overlaps within a height band.

        A cell is occupied when the footprint (the vertical projection) of a body whose vertical extent
        overlaps ``[z_min, z_max]`` overlaps the cell's square by more than a micrometre (bodies that
        merely touch a cell's edge do not occupy it). Bodies are read from PyBullet's collision shapes
        at their current poses, so moved bodies, added boxes, walls, each table's top and legs and the
        carriers all count. Boxes must stand upright (rotated about z only); cylinders are upright.

        Parameters
        ----------
        spec : lab.navigation.GridSpec
            Or anything with ``origin_xy``, ``resolution`` and ``shape`` (see ``docs/conventions.md``).
        z_min, z_max : float [m]
            The height band, e.g. ``CostmapConfig.obstacle_min_height`` and ``obstacle_max_height``.
        exclude : iterable of str
            Body names left out (the floor, the robot).

        Returns
        -------
        ndarray, shape spec.shape, bool
        """
        w = self._w
        (ox, oy), r, (nx, ny) = spec.origin_xy, float(spec.resolution), spec.shape
        X, Y = np.meshgrid(ox + (np.arange(nx) + 0.5) * r, oy + (np.arange(ny) + 0.5) * r, indexing="ij")
        h = 0.5 * r
        eps = 1e-6
        occ = np.zeros((nx, ny), dtype=bool)
        ids = w.body_ids
        skip = {ids[n] for n in exclude if n in ids}
        for body in sorted(set(ids.values()) - skip):
            pos, q = w.p.getBasePositionAndOrientation(body)
            R = quat_xyzw_to_R(q)
            for shape in w.p.getCollisionShapeData(body, -1):
                geom, dims, local_pos = shape[2], shape[3], shape[5]
                c = np.asarray(pos) + R @ np.asarray(local_pos)
                if geom == pybullet.GEOM_BOX:
                    if abs(R[2, 2] - 1.0) > 1e-6:
                        raise ConfigError(f"body {w.body_name(body)!r} is not upright")
                    a, b, hz = 0.5 * dims[0], 0.5 * dims[1], 0.5 * dims[2]
                    if c[2] + hz < z_min or c[2] - hz > z_max:
                        continue
                    cs, sn = R[0, 0], R[1, 0]
                    dx, dy = X - c[0], Y - c[1]
                    # separating axes: the cell's x and y axes and the box's own axes u, v
                    sep = np.abs(dx) >= h + a * abs(cs) + b * abs(sn) - eps
                    sep |= np.abs(dy) >= h + a * abs(sn) + b * abs(cs) - eps
                    proj = h * (abs(cs) + abs(sn))
                    sep |= np.abs(dx * cs + dy * sn) >= a + proj - eps
                    sep |= np.abs(-dx * sn + dy * cs) >= b + proj - eps
                    occ |= ~sep
                elif geom == pybullet.GEOM_CYLINDER:
                    height, radius = dims[0], dims[1]
                    if c[2] + height / 2 < z_min or c[2] - height / 2 > z_max:
                        continue
                    # distance from the circle's centre to the nearest point of each cell's square
                    ddx = np.maximum(np.abs(X - c[0]) - h, 0.0)
                    ddy = np.maximum(np.abs(Y - c[1]) - h, 0.0)
                    occ |= np.hypot(ddx, ddy) < radius - eps
                else:
                    raise ConfigError(f"body {w.body_name(body)!r}: collision shape {geom} is not supported")
        return occ

    def depth(self, G_WC: np.ndarray, camera) -> np.ndarray:
        """Metric depth along the optical axis (H, W) [m] seen from ``G_WC`` (rendered at 1x)."""
        _, depth, _ = self._w.render(G_WC, camera, want_depth=True, supersample=1)
        return depth

    def segmentation(self, G_WC: np.ndarray, camera) -> np.ndarray:
        """Body id per pixel (H, W) seen from ``G_WC`` (rendered at 1x); -1 for background."""
        _, _, seg = self._w.render(G_WC, camera, want_seg=True, supersample=1)
        return seg
