"""The navigation costmap ``M_c`` of the object-search paper (Sec. III-D) and its inflated cost grid.

    "Each navigation map cell is classified as *free*, *unknown*, or *obstacle* by comparing points in
    the cell with the estimated ground plane. [...] We take a conservative approach and give priority
    to *obstacle* if two types of points are projected into the same cell. Furthermore, when applying
    the A* search algorithm, obstacles are grown on the map to account for the size of the robot."

Labelling a point by its height ``h`` above the estimated :class:`~lab.navigation.ground.GroundPlane`
(bands of :class:`CostmapConfig`)::

    h < -drop_depth                               OBSTACLE  (a hole or a step down: negative obstacle)
    -drop_depth <= h < -free_band                 ignored   (stereo noise below the floor)
    |h| <= free_band                              FREE      (floor)
    free_band < h < obstacle_min_height           ignored   (too low to tell from floor noise)
    obstacle_min_height <= h <= obstacle_max_height  OBSTACLE  (something the robot would hit)
    h > obstacle_max_height                       ignored   (overhangs above the robot: ceiling, lamps)

``obstacle_max_height = robot_height + height_margin``. The robot carries its stereo head at about
0.8 m, so with the default ``robot_height = 0.95`` m a table top at 0.75 m *is* an obstacle (the head
would hit it) as are the table's legs; a shelf board at 1.2 m is not, its uprights are.

A view's vote for a cell: OBSTACLE if at least ``min_obstacle_points`` obstacle points fell in it, else
FREE if at least ``min_free_points`` floor points did, else none (obstacle priority, as the paper). The
few-points threshold keeps a single stray stereo mismatch from planting an obstacle; it does not undo
the priority: a cell of floor with three points of a chair leg in it is an obstacle.

Stereo range noise smears a surface along the viewing rays (``sigma_Z = Z^2 sigma_d / (f b)``: about
2 cm at 1.5 m and 10 cm at 3.5 m for 0.2 px disparity noise, a 12 cm baseline and f = 208 px), so an
obstacle's edge often spills into the neighbouring cell; this is the conservative side, and inflation
by the robot radius dwarfs it. Points farther than ``max_range`` from the camera are not used at all
when the camera position is given.

Accumulation over views (the evidence rule): each cell carries an integer evidence ``e``, 0 at the
start. An obstacle vote adds ``hit``, a free vote subtracts ``miss``; ``e`` is clamped to
``[-free_floor, obstacle_ceiling]``. A cell never voted on is UNKNOWN; otherwise it is OBSTACLE when
``e > 0`` and FREE when ``e <= 0``. With the defaults (hit 4, miss 1, floor 2, ceiling 12):

* conservative: however often a cell was seen free, one obstacle vote makes it OBSTACLE
  (``-2 + 4 > 0``);
* clearing: an obstacle seen once is cleared by 2 to 4 free votes (2 after a free history, 4 on a
  fresh cell), one seen three or more times by 12 (a person who walked away, a door that opened):
  a dynamic obstacle does not block the map forever, while a view or two of stereo noise cannot
  clear a solid obstacle.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import IntEnum
from functools import cached_property

import numpy as np

from lab.errors import ConfigError
from lab.navigation.grid import GridSpec, check_finite_xy
from lab.navigation.ground import GroundPlane, as_points3

__all__ = ["CellState", "CostmapConfig", "CostmapUpdate", "Costmap", "CostGrid", "grow_obstacles"]


class CellState(IntEnum):
    """Label of a costmap cell (the paper's free / unknown / obstacle)."""

    UNKNOWN = 0
    FREE = 1
    OBSTACLE = 2


@dataclass(frozen=True)
class CostmapConfig:
    """Height bands [m] for labelling points and the evidence rule (see the module docstring).

    Attributes
    ----------
    free_band : float [m]
        Points with ``|h| <= free_band`` are floor.
    obstacle_min_height : float [m]
        Lowest height of an obstacle point (lower: floor noise, cables, rugs).
    robot_height, height_margin : float [m]
        Points up to ``robot_height + height_margin`` are obstacles; above, the robot passes under.
    drop_depth : float [m] or None
        Points deeper than this below the floor are obstacles (a step down); None ignores them.
    min_obstacle_points, min_free_points : int
        Points of a kind a view needs in a cell to vote for it.
    max_range : float [m]
        Points farther from the camera (when its position is given) are ignored.
    hit, miss, free_floor, obstacle_ceiling : int
        The evidence rule: an obstacle vote adds ``hit``, a free vote subtracts ``miss``, evidence is
        clamped to ``[-free_floor, obstacle_ceiling]``, and a seen cell is OBSTACLE while it is > 0.
    """

    free_band: float = 0.03
    obstacle_min_height: float = 0.05
    robot_height: float = 0.95
    height_margin: float = 0.10
    drop_depth: float | None = 0.10
    min_obstacle_points: int = 3
    min_free_points: int = 2
    max_range: float = 4.0
    hit: int = 4
    miss: int = 1
    free_floor: int = 2
    obstacle_ceiling: int = 12

    def __post_init__(self):
        if not 0 < self.free_band < self.obstacle_min_height < self.obstacle_max_height:
            raise ConfigError(
                "costmap bands need 0 < free_band < obstacle_min_height < robot_height + height_margin, "
                f"got {self.free_band}, {self.obstacle_min_height}, {self.obstacle_max_height} m"
            )
        if self.drop_depth is not None and not self.drop_depth >= self.free_band:
            raise ConfigError(f"drop_depth must be >= free_band ({self.free_band} m) or None")
        if min(self.hit, self.miss, self.free_floor, self.obstacle_ceiling) < 0 or self.hit <= 0:
            raise ConfigError("costmap evidence increments and bounds must be >= 0 (hit > 0)")
        if self.min_obstacle_points < 1 or self.min_free_points < 1:
            raise ConfigError("min_obstacle_points and min_free_points must be >= 1")
        if not self.max_range > 0:
            raise ConfigError(f"max_range must be > 0 m, got {self.max_range}")

    @property
    def obstacle_max_height(self) -> float:
        return self.robot_height + self.height_margin


@dataclass(frozen=True, eq=False)
class CostmapUpdate:
    """What one view did to the costmap.

    Attributes
    ----------
    n_points : int
        Points given.
    n_used : int
        Finite points on the map (and within ``max_range`` of the sensor when it was given).
    n_free_points, n_obstacle_points : int
        Used points labelled floor / obstacle.
    free_votes, obstacle_votes : int
        Cells this view voted FREE / OBSTACLE.
    new_obstacles : ndarray, shape (k, 2), int
        Cells ``(i, j)`` that are OBSTACLE now and were not before the view (replanning looks here).
    cleared : ndarray, shape (k, 2), int
        Cells that were OBSTACLE and are FREE now.
    """

    n_points: int
    n_used: int
    n_free_points: int
    n_obstacle_points: int
    free_votes: int
    obstacle_votes: int
    new_obstacles: np.ndarray = field(repr=False)
    cleared: np.ndarray = field(repr=False)


@dataclass(frozen=True, eq=False)
class CostGrid:
    """Traversal cost multipliers per cell, what A* searches.

    ``cost[i, j]`` multiplies the length [m] of a step *into* cell ``(i, j)``: 1 for free floor,
    ``unknown_cost`` for unknown cells, up to ``1 + clearance_cost`` close to obstacles, and ``inf`` for
    cells the robot's centre must not enter (obstacles grown by ``radius``).

    Attributes
    ----------
    spec : GridSpec
    cost : ndarray, shape spec.shape, float64, read-only
        Multipliers >= 1, or ``inf`` (blocked).
    radius : float [m]
        Obstacles were grown by this radius (0 for a grid built directly from costs).
    unknown_cost : float
        Multiplier of unknown cells (``inf``: unknown space is not entered).
    obstacle_distance : ndarray, shape spec.shape [m], or None
        Distance from each cell centre to the nearest obstacle cell centre, exact up to
        ``radius + clearance`` and ``inf`` beyond.
    """

    spec: GridSpec
    cost: np.ndarray = field(repr=False)
    radius: float = 0.0
    unknown_cost: float = 1.0
    obstacle_distance: np.ndarray | None = field(default=None, repr=False)

    def __post_init__(self):
        c = np.array(self.cost, dtype=np.float64)
        if c.shape != self.spec.shape:
            raise ConfigError(f"cost grid shape {c.shape} does not match the GridSpec {self.spec.shape}")
        if np.isnan(c).any() or (c < 1.0).any():
            raise ConfigError("cost multipliers must be >= 1 (or inf for blocked cells), without NaN")
        c.flags.writeable = False
        object.__setattr__(self, "cost", c)

    @property
    def blocked(self) -> np.ndarray:
        """Cells the robot's centre must not enter, shape spec.shape, bool."""
        return ~np.isfinite(self.cost)

    @cached_property
    def padded_step_costs(self) -> list[float]:
        """``cost * resolution`` [m per unit step] padded by one ring of ``inf``, flattened (C order).

        A Python list, because the A* inner loop indexes it one cell at a time (list indexing is several
        times faster than NumPy scalar indexing); cell ``(i, j)`` is at ``(i + 1) * (ny + 2) + j + 1``.
        Computed once per grid (the grid is immutable).
        """
        return np.pad(self.cost * self.spec.resolution, 1, constant_values=np.inf).ravel().tolist()

    @cached_property
    def padded_step_costs_array(self) -> np.ndarray:
        """:attr:`padded_step_costs` as a read-only float64 array, for the compiled A*."""
        a = np.pad(self.cost * self.spec.resolution, 1, constant_values=np.inf).ravel()
        a.flags.writeable = False
        return a

    @cached_property
    def min_cost(self) -> float:
        """Smallest finite multiplier (1 when every cell is blocked): scales A*'s heuristic."""
        finite = self.cost[np.isfinite(self.cost)]
        return float(finite.min()) if finite.size else 1.0

    def cost_at(self, x: float, y: float) -> float:
        """Multiplier of the cell under the world point ``(x, y)`` [m] (raises OutsideMap off the map)."""
        i, j = self.spec.world_to_cell(x, y)
        return float(self.cost[i, j])


def _disk_offsets(r_cells: float) -> tuple[np.ndarray, np.ndarray]:
    """Integer offsets ``(di, dj)`` with ``di^2 + dj^2 <= r_cells^2``, shape (k, 2), and their lengths."""
    K = int(math.floor(r_cells + 1e-9))
    di, dj = np.mgrid[-K : K + 1, -K : K + 1]
    d = np.hypot(di, dj).ravel()
    keep = d <= r_cells + 1e-9
    return np.stack([di.ravel()[keep], dj.ravel()[keep]], axis=1), d[keep]


def grow_obstacles(obstacle: np.ndarray, resolution: float, reach: float) -> np.ndarray:
    """Distance [m] from every cell centre to the nearest obstacle cell centre, up to ``reach``.

    A bounded distance transform with a precomputed disk kernel: each offset ``(di, dj)`` in the disk of
    radius ``reach`` contributes its length wherever the shifted obstacle mask is set.

    Parameters
    ----------
    obstacle : ndarray, shape (nx, ny), bool
    resolution : float [m]
    reach : float [m]

    Returns
    -------
    ndarray, shape (nx, ny) [m]
        0 on obstacle cells, the exact Euclidean centre-to-centre distance where it is ``<= reach``,
        ``inf`` elsewhere.
    """
    obstacle = np.asarray(obstacle, dtype=bool)
    nx, ny = obstacle.shape
    out = np.full(obstacle.shape, np.inf)
    if not obstacle.any():
        return out
    offsets, lengths = _disk_offsets(max(0.0, reach) / resolution)
    K = int(np.abs(offsets).max()) if len(offsets) else 0
    padded = np.pad(obstacle, K)
    for (di, dj), length in zip(offsets, lengths, strict=True):
        shifted = padded[K + di : K + di + nx, K + dj : K + dj + ny]
        np.minimum(out, np.where(shifted, length * resolution, np.inf), out=out)
    return out


class Costmap:
    """The paper's navigation costmap ``M_c``: free / unknown / obstacle cells from stereo points.

    Parameters
    ----------
    spec : GridSpec
        Map extent and resolution (the paper uses 0.10 m cells).
    config : CostmapConfig
        Height bands and the evidence rule.

    Examples
    --------
    >>> cm = Costmap(GridSpec.from_bounds(-5, -5, 5, 5, 0.1))
    >>> plane = fit_ground_plane(points_W, rng=0)            # doctest: +SKIP
    >>> cm.integrate(points_W, plane, sensor_origin_xy=(pose.x, pose.y))  # doctest: +SKIP
    >>> grid = cm.inflated(radius=0.25)                       # doctest: +SKIP
    """

    def __init__(self, spec: GridSpec, config: CostmapConfig | None = None):
        self.spec = spec
        self.config = config if config is not None else CostmapConfig()
        self._evidence = np.zeros(spec.shape, dtype=np.int32)
        self._seen = np.zeros(spec.shape, dtype=bool)

    @classmethod
    def from_occupancy(
        cls, spec: GridSpec, obstacle: np.ndarray, known: np.ndarray | None = None, config=None
    ) -> Costmap:
        """A costmap from a known map: ``obstacle`` cells OBSTACLE (full evidence), other ``known`` FREE.

        ``known`` defaults to every cell. Useful for prior maps, tests and benchmarks.
        """
        cm = cls(spec, config)
        obstacle = np.asarray(obstacle, dtype=bool)
        known = np.ones(spec.shape, dtype=bool) if known is None else np.asarray(known, dtype=bool)
        if obstacle.shape != spec.shape or known.shape != spec.shape:
            raise ConfigError(f"occupancy shape {obstacle.shape} does not match the GridSpec {spec.shape}")
        cm._seen = known | obstacle
        cm._evidence = np.where(
            obstacle, cm.config.obstacle_ceiling, np.where(known, -cm.config.free_floor, 0)
        ).astype(np.int32)
        return cm

    # -- reading ---------------------------------------------------------------------------------
    @property
    def state(self) -> np.ndarray:
        """Cell labels, shape spec.shape, int8 values of :class:`CellState`."""
        s = np.full(self.spec.shape, CellState.UNKNOWN, dtype=np.int8)
        s[self._seen] = CellState.FREE
        s[self._seen & (self._evidence > 0)] = CellState.OBSTACLE
        return s

    @property
    def evidence(self) -> np.ndarray:
        """The integer evidence per cell (a copy), shape spec.shape."""
        return self._evidence.copy()

    @property
    def obstacle(self) -> np.ndarray:
        """OBSTACLE cells, shape spec.shape, bool."""
        return self._seen & (self._evidence > 0)

    # -- writing ---------------------------------------------------------------------------------
    def label_points(self, points_W: np.ndarray, plane: GroundPlane) -> np.ndarray:
        """Label each point by its height above ``plane``: CellState value per point, shape (n,).

        UNKNOWN marks points that are ignored (see the bands in the module docstring).
        """
        cfg = self.config
        h = plane.height(points_W)
        lab = np.full(h.shape, CellState.UNKNOWN, dtype=np.int8)
        lab[np.abs(h) <= cfg.free_band] = CellState.FREE
        lab[(h >= cfg.obstacle_min_height) & (h <= cfg.obstacle_max_height)] = CellState.OBSTACLE
        if cfg.drop_depth is not None:
            lab[h < -cfg.drop_depth] = CellState.OBSTACLE
        return lab

    def integrate(self, points_W: np.ndarray, plane: GroundPlane, sensor_origin_xy=None) -> CostmapUpdate:
        """Add one view's stereo points to the map (vectorised: one ``bincount`` per label).

        Parameters
        ----------
        points_W : ndarray, shape (n, 3) [m]
            Triangulated points in the world frame W (non-finite rows are ignored).
        plane : GroundPlane
            The estimated floor (from :func:`~lab.navigation.ground.fit_ground_plane`).
        sensor_origin_xy : (x, y) [m] or Pose2D, optional
            Where the camera stood. When given, points farther than ``config.max_range`` from it on the
            floor are ignored: stereo depth error grows with the square of the range.

        Returns
        -------
        CostmapUpdate
        """
        cfg, spec = self.config, self.spec
        P = as_points3(points_W)
        n_points = len(P)
        ij, use = spec.cells_of(P[:, :2])
        use &= np.isfinite(P[:, 2])
        if sensor_origin_xy is not None:
            sx, sy = check_finite_xy("sensor_origin_xy", sensor_origin_xy)
            use &= np.hypot(P[:, 0] - sx, P[:, 1] - sy) <= cfg.max_range
        lab = self.label_points(np.where(use[:, None], P, 0.0), plane)
        k = spec.flat(ij[use])
        lab = lab[use]
        n_cells = spec.n_cells
        n_free = np.bincount(k[lab == CellState.FREE], minlength=n_cells).reshape(spec.shape)
        n_obst = np.bincount(k[lab == CellState.OBSTACLE], minlength=n_cells).reshape(spec.shape)

        vote_obst = n_obst >= cfg.min_obstacle_points  # obstacle priority (Sec. III-D)
        vote_free = ~vote_obst & (n_free >= cfg.min_free_points)

        before = self.obstacle
        e = self._evidence
        e[vote_obst] = np.minimum(e[vote_obst] + cfg.hit, cfg.obstacle_ceiling)
        e[vote_free] = np.maximum(e[vote_free] - cfg.miss, -cfg.free_floor)
        self._seen |= vote_obst | vote_free
        after = self.obstacle
        return CostmapUpdate(
            n_points=n_points,
            n_used=int(use.sum()),
            n_free_points=int((lab == CellState.FREE).sum()),
            n_obstacle_points=int((lab == CellState.OBSTACLE).sum()),
            free_votes=int(vote_free.sum()),
            obstacle_votes=int(vote_obst.sum()),
            new_obstacles=np.argwhere(after & ~before),
            cleared=np.argwhere(before & ~after),
        )

    def clear_disc(self, xy, radius: float) -> int:
        """Mark the cells whose centres lie within ``radius`` [m] of ``xy`` [m] free (full free
        evidence): where the robot stands there is no obstacle. Returns how many OBSTACLE cells this
        cleared (stale marks, or marks a pose correction moved under the robot)."""
        disc, n = self._disc(xy, radius)
        self._evidence[disc] = -self.config.free_floor
        self._seen |= disc
        return n

    def forget_disc(self, xy, radius: float) -> int:
        """Forget what the map holds within ``radius`` [m] of ``xy`` [m]: the cells are unknown again, with
        no evidence either way, so that the next views decide them afresh. Unlike :meth:`clear_disc`, it
        does not claim them free: the planner keeps its unknown cost there until a view has seen them.
        Returns how many OBSTACLE cells it forgot."""
        disc, n = self._disc(xy, radius)
        self._evidence[disc] = 0.0
        self._seen &= ~disc
        return n

    def _disc(self, xy, radius: float) -> tuple[np.ndarray, int]:
        """The cells whose centres lie within ``radius`` [m] of ``xy`` [m], and how many are OBSTACLE."""
        x, y = check_finite_xy("xy", xy)
        if not (math.isfinite(radius) and radius >= 0):
            raise ConfigError(f"radius must be a finite number >= 0 m, got {radius!r}")
        X, Y = self.spec.cell_centers()
        disc = np.hypot(X - x, Y - y) <= radius
        return disc, int((disc & self.obstacle).sum())

    # -- planning grid ---------------------------------------------------------------------------
    def inflated(
        self,
        radius: float,
        *,
        unknown_cost: float = 2.0,
        clearance: float = 0.2,
        clearance_cost: float = 2.0,
    ) -> CostGrid:
        """The cost grid A* searches: obstacles grown by ``radius``, unknown and near-obstacle costs.

        Parameters
        ----------
        radius : float [m]
            A cell is blocked when its centre is within ``radius`` of an obstacle cell's centre. Pass
            the robot's footprint radius plus a margin: an obstacle may lie anywhere in its cell, up to
            ``resolution / sqrt(2)`` from the centre, so ``BaseLimits.radius + resolution`` keeps the
            footprint off obstacle cells with some room for tracking error.
        unknown_cost : float
            Multiplier (>= 1) of unknown cells. The default 2 lets the robot plan through space it has
            not seen yet (the map fills in as it drives and it replans) while preferring known floor;
            ``inf`` forbids unknown space.
        clearance : float [m]
            Width of the band beyond ``radius`` in which cells cost more, so paths keep off walls.
        clearance_cost : float
            Extra multiplier at the blocked edge, falling linearly to 0 at ``radius + clearance``.

        Returns
        -------
        CostGrid
        """
        if not (math.isfinite(radius) and radius >= 0):
            raise ConfigError(f"inflation radius must be a finite number >= 0 m, got {radius!r}")
        if not unknown_cost >= 1:
            raise ConfigError(f"unknown_cost must be >= 1 (or inf), got {unknown_cost!r}")
        if not (clearance >= 0 and clearance_cost >= 0):
            raise ConfigError("clearance and clearance_cost must be >= 0")
        state = self.state
        dist = grow_obstacles(state == CellState.OBSTACLE, self.spec.resolution, radius + clearance)
        cost = np.where(state == CellState.UNKNOWN, float(unknown_cost), 1.0)
        if clearance > 0 and clearance_cost > 0:
            band = (dist > radius) & (dist < radius + clearance)
            extra = np.zeros_like(cost)
            extra[band] = clearance_cost * (1.0 - (dist[band] - radius) / clearance)
            cost = cost + extra
        cost[dist <= radius + 1e-9] = np.inf
        return CostGrid(self.spec, cost, float(radius), float(unknown_cost), dist)
