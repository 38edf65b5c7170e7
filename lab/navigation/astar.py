r"""A* on the inflated costmap (object-search paper, Sec. III-D: "searched via the A* algorithm").

The graph is the 8-connected grid of a :class:`~lab.navigation.costmap.CostGrid`. A step from cell ``u``
into a neighbour ``v`` costs

.. math:: c(u, v) = \ell(u, v) \, m(v), \qquad \ell = r \text{ (edge) or } \sqrt{2}\, r \text{ (diagonal)}

with ``r`` the resolution [m] and ``m(v) >= 1`` the cost multiplier of the cell entered (1 on known
floor, more for unknown cells and near obstacles, ``inf`` for blocked cells, which are never entered).
A path's cost is thus a weighted length in metres. Diagonal steps may not cut corners: a diagonal step
is allowed only when both cells it passes between are unblocked.

The heuristic is the octile distance times the smallest multiplier ``m_min`` on the grid,

.. math:: h(n) = m_{min}\, r \left(\Delta_{max} + (\sqrt{2} - 1)\,\Delta_{min}\right),

the exact cost of an obstacle-free path, so it is admissible and consistent and A* returns an optimal
path. Ties in ``f = g + h`` go to the smaller ``h`` (closer to the goal), then to the smaller flat cell
index, so the same grid gives the same path, always.

Two implementations of the same search: ``_search`` in plain Python (the one to read) and
``_search_compiled``, the same lines compiled by numba (the default: the planner replans often, and
pure-Python A* is only about 2x faster than networkx's). Tests check that both give the same paths.

Implementation notes: cells are flat integer indices into
a grid padded with one ring of blocked cells (no bounds checks), the eight neighbour offsets and step
lengths are precomputed, ``g``, the parents and the closed set are flat lists / a ``bytearray``, and the
open list is a ``heapq`` of plain tuples with lazy deletion (stale entries are skipped when popped).
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass, field
from enum import Enum

import numba
import numpy as np

from lab.navigation.costmap import CostGrid
from lab.navigation.grid import GridSpec, check_finite_xy

__all__ = ["PathStatus", "PathResult", "astar", "astar_cells", "astar_to_region", "heading_towards"]

_SQRT2 = math.sqrt(2.0)
# Largest ratio of the octile to the Euclidean length of a vector: sqrt(4 - 2 sqrt 2), at 22.5 deg.
_OCTILE_PER_EUCLID = math.sqrt(4.0 - 2.0 * _SQRT2) * (1.0 + 1e-12)


class PathStatus(Enum):
    """Outcome of a search: FOUND, or why there is no path."""

    FOUND = "found"
    START_OUTSIDE_MAP = "start outside the map"
    GOAL_OUTSIDE_MAP = "goal outside the map"
    START_IN_OBSTACLE = "start in a blocked (grown obstacle) cell"
    GOAL_IN_OBSTACLE = "goal in a blocked (grown obstacle) cell"
    UNREACHABLE = "goal unreachable: no obstacle-free path"


@dataclass(frozen=True, eq=False)
class PathResult:
    """A planned path, or the reason there is none.

    Attributes
    ----------
    status : PathStatus
    cells : ndarray, shape (k, 2), int
        Cells ``(i, j)`` from the start cell to the goal cell, 8-connected; empty (0, 2) without a path.
    points_xy : ndarray, shape (k, 2) [m]
        World coordinates of the cell centres of ``cells``.
    cost : float [m]
        Sum of the step costs ``length * multiplier`` along the path; ``inf`` without a path.
    expanded : int
        Cells taken off the open list and expanded (0 when the query was refused before searching).
    spec : GridSpec
        The grid the path lives on.
    """

    status: PathStatus
    cells: np.ndarray = field(repr=False)
    points_xy: np.ndarray = field(repr=False)
    cost: float
    expanded: int
    spec: GridSpec = field(repr=False)

    @property
    def found(self) -> bool:
        return self.status is PathStatus.FOUND

    @property
    def reason(self) -> str | None:
        """Why there is no path (the status name, e.g. ``"UNREACHABLE"``), or None when found."""
        return None if self.found else self.status.name

    @property
    def length(self) -> float:
        """Geometric length [m] of the cell-centre polyline (0 for a one-cell path, inf without a path)."""
        if not self.found:
            return math.inf
        return float(np.linalg.norm(np.diff(self.points_xy, axis=0), axis=1).sum())

    @property
    def goal_cell(self) -> tuple[int, int] | None:
        return None if not self.found else (int(self.cells[-1, 0]), int(self.cells[-1, 1]))


def heading_towards(from_xy, to_xy) -> float:
    """Heading [rad] of the direction from ``from_xy`` to ``to_xy`` (to face a target cell at the goal)."""
    fx, fy = check_finite_xy("from_xy", from_xy)
    tx, ty = check_finite_xy("to_xy", to_xy)
    return math.atan2(ty - fy, tx - fx)


def _no_path(status: PathStatus, spec: GridSpec, expanded: int = 0) -> PathResult:
    empty = np.zeros((0, 2), dtype=np.int64)
    return PathResult(status, empty, np.zeros((0, 2)), math.inf, expanded, spec)


def _search(cost: list, W: int, start: int, is_goal: bytearray, ta: float, tb: float, R: float, s: float):
    """A* over the padded flat grid (see the module docstring).

    ``cost`` holds metres per unit step (``inf``: blocked), ``W`` is the padded row length. The
    heuristic of a cell ``(a, b)`` (padded indices) is ``s * max(0, octile((a, b), (ta, tb)) - R)``:
    the octile distance to the goal cell for a single goal (``R = 0``), or to a target point minus the
    goal region's reach for :func:`astar_to_region`.

    Returns
    -------
    goal : int
        Padded index of the goal cell reached, or -1.
    parent, g : list
        Parents and path costs [m] by padded index.
    expanded : int
    """
    INF = math.inf
    k = _SQRT2 - 2.0
    n = len(cost)
    g = [INF] * n
    parent = [-1] * n
    closed = bytearray(n)
    # (offset, step length factor, the two orthogonal cells a diagonal passes between, or 0, 0)
    nbrs = (
        (1, 1.0, 0, 0),
        (-1, 1.0, 0, 0),
        (W, 1.0, 0, 0),
        (-W, 1.0, 0, 0),
        (W + 1, _SQRT2, W, 1),
        (W - 1, _SQRT2, W, -1),
        (-W + 1, _SQRT2, -W, 1),
        (-W - 1, _SQRT2, -W, -1),
    )
    g[start] = 0.0
    # Open list entries (f in nanometres, h, cell): ties in f go to the smaller h, then the smaller
    # index. f is truncated to whole nanometres so that float rounding in g (a sum of many steps) does
    # not break the ties of equally long paths: on open floor there are many, and the h tie-break then
    # walks straight along one of them instead of expanding the parallelogram between them. Ordering
    # by f to within 1 nm costs at most ~1 nm of optimality; g itself stays exact.
    heap = [(0, 0.0, start)]
    pop, push = heapq.heappop, heapq.heappush
    expanded = 0
    while heap:
        u = pop(heap)[2]
        if closed[u]:
            continue  # a stale entry: u was reached more cheaply after it was pushed
        closed[u] = 1
        expanded += 1
        if is_goal[u]:
            return u, parent, g, expanded
        gu = g[u]
        for off, step, oa, ob in nbrs:
            v = u + off
            if closed[v]:
                continue
            c = cost[v]
            if c == INF:
                continue
            if oa and (cost[u + oa] == INF or cost[u + ob] == INF):
                continue  # no corner cutting past a blocked cell
            ng = gu + step * c  # g(v) = g(u) + l(u, v) m(v)
            if ng < g[v]:
                g[v] = ng
                parent[v] = u
                a, b = divmod(v, W)  # the heuristic, inlined (a function call per push costs ~15 %)
                dx = a - ta if a > ta else ta - a
                dy = b - tb if b > tb else tb - b
                h = dx + dy + k * (dx if dx < dy else dy) - R
                h = h * s if h > 0.0 else 0.0
                push(heap, (int((ng + h) * 1e9), h, v))
    return -1, parent, g, expanded


@numba.njit(cache=True, nogil=True)
def _search_compiled(cost, W, start, is_goal, ta, tb, R, s):  # pragma: no cover - compiled
    """:func:`_search`, line for line, compiled by numba (the same order of expansion, the same path).

    ``cost`` and ``is_goal`` are NumPy arrays here; ``parent`` and ``g`` come back as arrays.
    """
    INF = np.inf
    k = _SQRT2 - 2.0
    n = cost.shape[0]
    g = np.full(n, INF)
    parent = np.full(n, -1, np.int64)
    closed = np.zeros(n, np.uint8)
    offs = np.array([1, -1, W, -W, W + 1, W - 1, -W + 1, -W - 1], np.int64)
    steps = np.array([1.0, 1.0, 1.0, 1.0, _SQRT2, _SQRT2, _SQRT2, _SQRT2])
    oas = np.array([0, 0, 0, 0, W, W, -W, -W], np.int64)
    obs = np.array([0, 0, 0, 0, 1, -1, 1, -1], np.int64)
    g[start] = 0.0
    heap = [(np.int64(0), 0.0, np.int64(start))]
    expanded = 0
    while len(heap) > 0:
        u = heapq.heappop(heap)[2]
        if closed[u]:
            continue
        closed[u] = 1
        expanded += 1
        if is_goal[u]:
            return u, parent, g, expanded
        gu = g[u]
        for t in range(8):
            v = u + offs[t]
            if closed[v]:
                continue
            c = cost[v]
            if c == INF:
                continue
            if oas[t] != 0 and (cost[u + oas[t]] == INF or cost[u + obs[t]] == INF):
                continue
            ng = gu + steps[t] * c
            if ng < g[v]:
                g[v] = ng
                parent[v] = u
                a, b = v // W, v % W
                dx = a - ta if a > ta else ta - a
                dy = b - tb if b > tb else tb - b
                h = dx + dy + k * (dx if dx < dy else dy) - R
                h = h * s if h > 0.0 else 0.0
                heapq.heappush(heap, (np.int64((ng + h) * 1e9), h, np.int64(v)))
    return -1, parent, g, expanded


def _run(grid: CostGrid, W, start, is_goal, ta, tb, R, s, backend):
    if backend == "python":
        return _search(grid.padded_step_costs, W, start, is_goal, ta, tb, R, s)
    if backend != "compiled":
        raise ValueError(f"backend must be 'compiled' or 'python', got {backend!r}")
    return _search_compiled(
        grid.padded_step_costs_array,
        np.int64(W),
        np.int64(start),
        np.frombuffer(is_goal, np.uint8),
        float(ta),
        float(tb),
        float(R),
        float(s),
    )


def _build_result(grid: CostGrid, goal: int, parent: list, g: list, expanded: int) -> PathResult:
    W = grid.spec.shape[1] + 2
    chain = [goal]
    while parent[chain[-1]] != -1:
        chain.append(parent[chain[-1]])
    chain.reverse()
    cells = np.array([divmod(p, W) for p in chain], dtype=np.int64).reshape(-1, 2) - 1
    points = grid.spec.centers_of(cells)
    return PathResult(PathStatus.FOUND, cells, points, float(g[goal]), expanded, grid.spec)


def astar_cells(grid: CostGrid, start_ij, goal_ij, backend: str = "compiled") -> PathResult:
    """A* between two cells of a cost grid (see the module docstring for the cost model).

    Parameters
    ----------
    grid : CostGrid
    start_ij, goal_ij : (int, int)
        Cells ``(i, j)``.

    Returns
    -------
    PathResult
        FOUND with an optimal path, or START/GOAL_OUTSIDE_MAP, START/GOAL_IN_OBSTACLE, UNREACHABLE.
        Never raises for a goal it cannot reach.
    """
    spec = grid.spec
    si, sj = (int(v) for v in start_ij)
    gi, gj = (int(v) for v in goal_ij)
    if not spec.contains_cell(si, sj):
        return _no_path(PathStatus.START_OUTSIDE_MAP, spec)
    if not spec.contains_cell(gi, gj):
        return _no_path(PathStatus.GOAL_OUTSIDE_MAP, spec)
    if not math.isfinite(grid.cost[si, sj]):
        return _no_path(PathStatus.START_IN_OBSTACLE, spec)
    if not math.isfinite(grid.cost[gi, gj]):
        return _no_path(PathStatus.GOAL_IN_OBSTACLE, spec)
    W = spec.shape[1] + 2
    is_goal = bytearray((spec.shape[0] + 2) * W)
    is_goal[(gi + 1) * W + gj + 1] = 1
    s = grid.min_cost * spec.resolution
    found, parent, g, expanded = _run(
        grid, W, (si + 1) * W + sj + 1, is_goal, gi + 1, gj + 1, 0.0, s, backend
    )
    if found < 0:
        return _no_path(PathStatus.UNREACHABLE, spec, expanded)
    return _build_result(grid, found, parent, g, expanded)


def astar(grid: CostGrid, start, goal, backend: str = "compiled") -> PathResult:
    """A* between two world points (or :class:`~lab.geometry.Pose2D`), via the cells holding them.

    Parameters
    ----------
    grid : CostGrid
    start, goal : (x, y) [m] or Pose2D
        World positions; a pose's heading is ignored.

    Returns
    -------
    PathResult
        See :func:`astar_cells`; points off the map give START/GOAL_OUTSIDE_MAP.

    Raises
    ------
    ValueError
        ``start`` or ``goal`` has a NaN or infinite coordinate (the message names which).
    """
    sxy = check_finite_xy("start", start)
    gxy = check_finite_xy("goal", goal)
    ij, inside = grid.spec.cells_of(np.array([sxy, gxy]))
    if not inside[0]:
        return _no_path(PathStatus.START_OUTSIDE_MAP, grid.spec)
    if not inside[1]:
        return _no_path(PathStatus.GOAL_OUTSIDE_MAP, grid.spec)
    return astar_cells(grid, ij[0], ij[1], backend)


def astar_to_region(
    grid: CostGrid,
    start,
    target_xy,
    max_distance: float,
    min_distance: float = 0.0,
    backend: str = "compiled",
) -> PathResult:
    """A* to the cheapest-to-reach cell whose centre is within ``[min_distance, max_distance]`` of a target.

    The search robot must stand facing a probability-map cell within local-search range, not on it
    (the cell may hold a table). Any unblocked cell in the ring around ``target_xy`` is a goal. The
    heuristic ``m_min * r * max(0, octile(n, target) - 1.0824 * max_distance / r)`` is admissible and
    consistent (1.0824 = sqrt(4 - 2 sqrt 2) is the largest octile-to-Euclidean length ratio, so no goal
    cell is farther than that in octile distance), so the path found is optimal over the whole ring.
    Face the target at the end with ``heading_towards(result.points_xy[-1], target_xy)``.

    Parameters
    ----------
    grid : CostGrid
    start : (x, y) [m] or Pose2D
    target_xy : (x, y) [m]
        The point to approach (it may be off the map or inside an obstacle).
    max_distance, min_distance : float [m]

    Returns
    -------
    PathResult
        GOAL_OUTSIDE_MAP when no cell of the ring is on the map, GOAL_IN_OBSTACLE when all of its cells
        are blocked, otherwise as :func:`astar_cells`.

    Raises
    ------
    ValueError
        NaN / infinite ``start`` or ``target_xy``, or a distance band that is empty or not finite.
    """
    sxy = check_finite_xy("start", start)
    tx, ty = check_finite_xy("target_xy", target_xy)
    if not (math.isfinite(max_distance) and 0 <= min_distance <= max_distance):
        raise ValueError(f"need 0 <= min_distance <= max_distance < inf, got {min_distance}, {max_distance}")
    spec = grid.spec
    ij, inside = spec.cells_of(np.array([sxy]))
    if not inside[0]:
        return _no_path(PathStatus.START_OUTSIDE_MAP, spec)
    si, sj = int(ij[0, 0]), int(ij[0, 1])
    X, Y = spec.cell_centers()
    d = np.hypot(X - tx, Y - ty)
    ring = (d >= min_distance) & (d <= max_distance)
    if not ring.any():
        return _no_path(PathStatus.GOAL_OUTSIDE_MAP, spec)
    if not math.isfinite(grid.cost[si, sj]):
        return _no_path(PathStatus.START_IN_OBSTACLE, spec)
    goals = ring & np.isfinite(grid.cost)
    if not goals.any():
        return _no_path(PathStatus.GOAL_IN_OBSTACLE, spec)

    W = spec.shape[1] + 2
    res = spec.resolution
    is_goal = bytearray(np.pad(goals, 1).astype(np.uint8).tobytes())
    # The target in padded-cell units: the centre of padded cell a lies at origin + (a - 0.5) * res.
    ta = (tx - spec.origin_xy[0]) / res + 0.5
    tb = (ty - spec.origin_xy[1]) / res + 0.5
    # A goal cell lies within max_distance of the target, so within _OCTILE_PER_EUCLID * max_distance
    # in octile distance: subtracting that keeps the heuristic a lower bound, and 1-Lipschitz (consistent).
    R = _OCTILE_PER_EUCLID * max_distance / res
    s = grid.min_cost * res
    found, parent, g, expanded = _run(grid, W, (si + 1) * W + sj + 1, is_goal, ta, tb, R, s, backend)
    if found < 0:
        return _no_path(PathStatus.UNREACHABLE, spec, expanded)
    return _build_result(grid, found, parent, g, expanded)
