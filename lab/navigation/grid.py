"""Grid geometry shared by the costmap and the planner: world ``(x, y)`` [m] <-> cell ``(i, j)``.

A grid covers the axis-aligned rectangle ``[x0, x0 + nx * res) x [y0, y0 + ny * res)`` of the floor in
the world frame W (``docs/conventions.md``). Cell ``(i, j)`` is the square whose lower-left corner is
``(x0 + i * res, y0 + j * res)``: ``i`` counts along W's x axis and ``j`` along W's y axis, so an
array ``a`` of ``shape == (nx, ny)`` is indexed ``a[i, j]`` (to show it as a map, plot ``a.T`` with
``origin="lower"``). The intervals are half-open: a point on the upper edge of the map is outside.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lab.errors import ConfigError, LabError
from lab.scene import Scene

__all__ = ["GridSpec", "OutsideMap", "check_finite_xy", "room_bounds"]


class OutsideMap(LabError, ValueError):
    """A world point or a cell lies outside the grid (the message gives the map's extent)."""


def room_bounds(scene: Scene) -> tuple[float, float, float, float]:
    """``(x_min, y_min, x_max, y_max)`` [m] of a scene's floor: its ``[room] size`` centred on W's origin.

    The lab room (``worlds/lab_room.toml``, 6 x 8 m) gives ``(-3.0, -4.0, 3.0, 4.0)``.

    Raises
    ------
    ConfigError
        The scene has no ``[room]`` (then the workspace must be given explicitly).
    """
    if scene.room is None:
        raise ConfigError(f"scene {scene.name!r} has no [room]: give the workspace bounds explicitly")
    sx, sy = (float(v) for v in scene.room.size)
    return (-sx / 2, -sy / 2, sx / 2, sy / 2)


def check_finite_xy(name: str, xy) -> tuple[float, float]:
    """``(x, y)`` [m] of a point or a :class:`~lab.geometry.Pose2D`; refuses NaN/inf, naming ``name``.

    Raises
    ------
    ValueError
        A coordinate is NaN or infinite, or ``xy`` does not hold two numbers.
    """
    if hasattr(xy, "x") and hasattr(xy, "y"):
        vals = (xy.x, xy.y, getattr(xy, "theta", 0.0))
    else:
        vals = tuple(np.asarray(xy, dtype=float).ravel())
        if len(vals) not in (2, 3):
            raise ValueError(f"{name} must be (x, y) [m] or a Pose2D, got {xy!r}")
    if not all(math.isfinite(float(v)) for v in vals):
        raise ValueError(f"{name} must be finite, got {xy!r}")
    return float(vals[0]), float(vals[1])


@dataclass(frozen=True)
class GridSpec:
    """Where a grid lies on the floor and how fine it is.

    Attributes
    ----------
    origin_xy : tuple of 2 floats [m]
        World ``(x, y)`` of the lower-left corner of cell ``(0, 0)``.
    resolution : float [m]
        Cell side length (the object-search paper's costmap uses 0.10 m).
    shape : tuple of 2 ints
        ``(nx, ny)``: number of cells along W's x and y axes.
    """

    origin_xy: tuple[float, float]
    resolution: float
    shape: tuple[int, int]

    def __post_init__(self):
        ox, oy = (float(v) for v in self.origin_xy)
        if not (math.isfinite(ox) and math.isfinite(oy)):
            raise ConfigError(f"grid origin_xy must be finite, got {self.origin_xy!r}")
        res = float(self.resolution)
        if not (math.isfinite(res) and res > 0):
            raise ConfigError(f"grid resolution must be a finite number > 0 m, got {self.resolution!r}")
        nx, ny = (int(v) for v in self.shape)
        if nx < 1 or ny < 1 or (nx, ny) != tuple(self.shape):
            raise ConfigError(f"grid shape must be two integers >= 1, got {self.shape!r}")
        object.__setattr__(self, "origin_xy", (ox, oy))
        object.__setattr__(self, "resolution", res)
        object.__setattr__(self, "shape", (nx, ny))

    @classmethod
    def from_bounds(cls, x_min: float, y_min: float, x_max: float, y_max: float, resolution: float = 0.1):
        """The smallest grid of ``resolution`` [m] cells anchored at ``(x_min, y_min)`` covering the box."""
        if not (x_max > x_min and y_max > y_min):
            raise ConfigError(f"empty map bounds x [{x_min}, {x_max}], y [{y_min}, {y_max}] m")
        if not resolution > 0:
            raise ConfigError(f"grid resolution must be > 0 m, got {resolution!r}")
        nx = max(1, math.ceil((x_max - x_min) / resolution - 1e-9))
        ny = max(1, math.ceil((y_max - y_min) / resolution - 1e-9))
        return cls((x_min, y_min), resolution, (nx, ny))

    @property
    def n_cells(self) -> int:
        return self.shape[0] * self.shape[1]

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """``(x_min, x_max, y_min, y_max)`` [m] of the covered rectangle (upper edges excluded)."""
        (ox, oy), r, (nx, ny) = self.origin_xy, self.resolution, self.shape
        return ox, ox + nx * r, oy, oy + ny * r

    def _outside_msg(self, what: str) -> str:
        x0, x1, y0, y1 = self.extent
        return f"{what} is outside the map x [{x0:.2f}, {x1:.2f}), y [{y0:.2f}, {y1:.2f}) m"

    # -- vectorised forms ------------------------------------------------------------------------
    def cells_of(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Cells of many world points, without raising.

        Parameters
        ----------
        xy : ndarray, shape (n, 2) or (n, k >= 2) [m]
            World points; only the first two columns are used.

        Returns
        -------
        ij : ndarray, shape (n, 2), int64
            Cell indices (meaningless where ``inside`` is False).
        inside : ndarray, shape (n,), bool
            Whether each point lies on the map (NaN points are outside).
        """
        xy = np.asarray(xy, dtype=float)
        q = (xy[:, :2] - np.asarray(self.origin_xy)) / self.resolution
        finite = np.isfinite(q).all(axis=1)
        q = np.where(finite[:, None], q, -1.0)
        ij = np.floor(q).astype(np.int64)
        inside = finite & (ij[:, 0] >= 0) & (ij[:, 1] >= 0)
        inside &= (ij[:, 0] < self.shape[0]) & (ij[:, 1] < self.shape[1])
        return ij, inside

    def centers_of(self, ij: np.ndarray) -> np.ndarray:
        """World ``(x, y)`` [m] of cell centres, ``ij`` shape (n, 2) -> (n, 2) (no bounds check)."""
        ij = np.asarray(ij, dtype=float).reshape(-1, 2)
        return np.asarray(self.origin_xy) + (ij + 0.5) * self.resolution

    def flat(self, ij: np.ndarray) -> np.ndarray:
        """Flat (C-order) index ``i * ny + j`` of cells, shape (n, 2) -> (n,)."""
        ij = np.asarray(ij, dtype=np.int64).reshape(-1, 2)
        return ij[:, 0] * self.shape[1] + ij[:, 1]

    def unflat(self, k: np.ndarray) -> np.ndarray:
        """Cells ``(i, j)`` of flat indices, shape (n,) -> (n, 2)."""
        k = np.asarray(k, dtype=np.int64).ravel()
        return np.stack(np.divmod(k, self.shape[1]), axis=1)

    def cell_centers(self) -> tuple[np.ndarray, np.ndarray]:
        """World coordinates of all cell centres: ``(X, Y)``, each shape ``(nx, ny)`` [m]."""
        (ox, oy), r, (nx, ny) = self.origin_xy, self.resolution, self.shape
        return np.meshgrid(ox + (np.arange(nx) + 0.5) * r, oy + (np.arange(ny) + 0.5) * r, indexing="ij")

    # -- single values, raising ------------------------------------------------------------------
    def contains_xy(self, x: float, y: float) -> bool:
        _, inside = self.cells_of(np.array([[x, y]], dtype=float))
        return bool(inside[0])

    def contains_cell(self, i: int, j: int) -> bool:
        return 0 <= i < self.shape[0] and 0 <= j < self.shape[1]

    def world_to_cell(self, x: float, y: float) -> tuple[int, int]:
        """Cell ``(i, j)`` holding the world point ``(x, y)`` [m].

        Raises
        ------
        ValueError
            ``x`` or ``y`` is NaN or infinite.
        OutsideMap
            The point is not on the map.
        """
        x, y = check_finite_xy("point", (x, y))
        ij, inside = self.cells_of(np.array([[x, y]]))
        if not inside[0]:
            raise OutsideMap(self._outside_msg(f"point ({x:.3f}, {y:.3f}) m"))
        return int(ij[0, 0]), int(ij[0, 1])

    def cell_to_world(self, i: int, j: int) -> tuple[float, float]:
        """World ``(x, y)`` [m] of the centre of cell ``(i, j)``; raises :class:`OutsideMap` off the map."""
        if not self.contains_cell(i, j):
            raise OutsideMap(f"cell ({i}, {j}) is outside the map of {self.shape[0]} x {self.shape[1]} cells")
        c = self.centers_of(np.array([[i, j]]))[0]
        return float(c[0]), float(c[1])
