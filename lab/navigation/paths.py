"""Paths on the cost grid: line-of-sight simplification, blockage checks and replanning.

The object-search paper replans as the robot drives: "path planning is executed repeatedly during
navigation mode [...] the initial planned path is subject to change should an obstacle appear later in
that path" (Sec. IV, Fig. 4). :class:`Replanner` does that: after each costmap update it checks whether
the part of the path still ahead crosses a newly blocked (grown-obstacle) cell and, if so, plans again
from the robot's current pose.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from lab.navigation.astar import PathResult, PathStatus
from lab.navigation.costmap import CostGrid
from lab.navigation.grid import check_finite_xy

__all__ = [
    "segment_cells",
    "segment_is_clear",
    "simplify_path",
    "first_blocked_index",
    "nearest_index",
    "point_ahead",
    "ReplanDecision",
    "Replanner",
]


def segment_cells(grid: CostGrid, a_xy, b_xy, step_fraction: float = 0.125) -> tuple[np.ndarray, bool]:
    """Cells a straight segment passes over, by sampling it every ``step_fraction`` of a cell.

    Sampling can miss a cell the segment only grazes (by less than a sample step, 1.25 cm for 10 cm
    cells); the planner's inflation margin is far larger.

    Returns
    -------
    ij : ndarray, shape (k, 2), int
        Cells of the samples that lie on the map (consecutive duplicates kept).
    on_map : bool
        Whether every sample lies on the map.
    """
    a = np.asarray(a_xy, dtype=float)[:2]
    b = np.asarray(b_xy, dtype=float)[:2]
    n = max(2, math.ceil(np.linalg.norm(b - a) / (step_fraction * grid.spec.resolution)) + 1)
    s = np.linspace(0.0, 1.0, n)[:, None]
    ij, inside = grid.spec.cells_of(a + s * (b - a))
    return ij[inside], bool(inside.all())


def segment_is_clear(grid: CostGrid, a_xy, b_xy, max_cost: float = math.inf) -> bool:
    """Whether the segment stays on the map, off blocked cells and on cells costing at most ``max_cost``."""
    ij, on_map = segment_cells(grid, a_xy, b_xy)
    if not on_map:
        return False
    c = grid.cost[ij[:, 0], ij[:, 1]]
    return bool(np.isfinite(c).all() and (c <= max_cost).all())


def simplify_path(path: PathResult, grid: CostGrid) -> np.ndarray:
    """Waypoints of a grid path with the staircase removed, by greedy line-of-sight shortcuts.

    From each kept point, the path is followed as far as a straight segment to it stays clear; a
    shortcut may not cross cells that cost more than the most expensive cell of the stretch it
    replaces, so it never goes nearer to obstacles or deeper into unknown space than the A* path did.

    Parameters
    ----------
    path : PathResult
        A found path on ``grid`` (or on a grid it is checked against).
    grid : CostGrid

    Returns
    -------
    ndarray, shape (m, 2) [m]
        World waypoints, the first and the last cell centres of the path included; empty (0, 2) when
        the path was not found.
    """
    if not path.found:
        return np.zeros((0, 2))
    P, cells = path.points_xy, path.cells
    c = grid.cost[cells[:, 0], cells[:, 1]]
    keep = [0]
    anchor = 0
    j = 1
    while j < len(P) - 1:
        # try to reach j + 1 straight from the anchor; if not, j is a waypoint
        if segment_is_clear(grid, P[anchor], P[j + 1], max_cost=float(c[anchor : j + 2].max())):
            j += 1
        else:
            keep.append(j)
            anchor = j
            j += 1
    if len(P) > 1:
        keep.append(len(P) - 1)
    return P[keep].copy()


def first_blocked_index(waypoints_xy: np.ndarray, grid: CostGrid, start: int = 0) -> int | None:
    """Index of the first segment ``(k, k + 1)`` at or after ``start`` that crosses a blocked cell.

    Returns ``k``, or ``len - 1`` when only the last point is blocked, or None when the path ahead is
    clear. Points off the map count as blocked.
    """
    W = np.asarray(waypoints_xy, dtype=float).reshape(-1, 2)
    if len(W) == 0:
        return None
    if len(W) == 1:
        return None if segment_is_clear(grid, W[0], W[0]) else 0
    for k in range(max(0, start), len(W) - 1):
        if not segment_is_clear(grid, W[k], W[k + 1]):
            return k
    return None


def nearest_index(waypoints_xy: np.ndarray, xy) -> int:
    """Index of the segment ``(k, k + 1)`` of a polyline nearest to the point ``xy``."""
    W = np.asarray(waypoints_xy, dtype=float).reshape(-1, 2)
    p = np.asarray(check_finite_xy("xy", xy))
    if len(W) < 2:
        return 0
    a, b = W[:-1], W[1:]
    ab = b - a
    L2 = np.einsum("ij,ij->i", ab, ab)
    t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.where(L2 > 0, L2, 1.0), 0.0, 1.0)
    d = np.linalg.norm(a + t[:, None] * ab - p, axis=1)
    return int(np.argmin(d))


def point_ahead(waypoints_xy: np.ndarray, xy, dist: float) -> np.ndarray:
    """The point ``dist`` [m] along the polyline from the projection of ``xy`` on it (the end if nearer).

    ``waypoints_xy`` is a float array of shape (n, 2) [m], n >= 1; returns shape (2,) [m].
    """
    W = waypoints_xy
    if len(W) == 1:
        return W[0].copy()
    k = nearest_index(W, xy)
    a, b = W[k], W[k + 1]
    ab = b - a
    L2 = float(ab @ ab)
    t = 0.0 if L2 == 0 else min(1.0, max(0.0, float((np.asarray(xy) - a) @ ab) / L2))
    p = a + t * ab
    left = dist
    for q in W[k + 1 :]:
        seg = float(np.hypot(*(q - p)))
        if seg >= left:
            return p + (q - p) * (left / seg)
        left -= seg
        p = q
    return W[-1].copy()


@dataclass(frozen=True, eq=False)
class ReplanDecision:
    """What :meth:`Replanner.update` decided.

    Attributes
    ----------
    replanned : bool
        A new path was planned in this update.
    reason : str
        ``"initial"`` (first plan), ``"retry"`` (the previous plan had failed), ``"blocked"`` (the path
        ahead crossed a blocked cell), ``"clear"`` (path kept), or ``"escape"`` (the robot stood in a
        grown obstacle and planned from the nearest free cell).
    path : PathResult
        The current A* result (``path.found`` is False when planning failed; ``path.reason`` says why).
    waypoints : ndarray, shape (m, 2) [m]
        What the follower should drive along (empty when there is no path).
    blocked_index : int or None
        The blocked segment of the previous waypoints that triggered replanning.
    """

    replanned: bool
    reason: str
    path: PathResult
    waypoints: np.ndarray = field(repr=False)
    blocked_index: int | None = None


class Replanner:
    """Keeps a path to a goal valid as the costmap changes (plan, check, replan from the current pose).

    Parameters
    ----------
    plan : callable ``(grid, start_xy) -> PathResult``
        The planner, with the goal bound in, e.g. ``lambda g, s: astar(g, s, goal_xy)`` or
        ``lambda g, s: astar_to_region(g, s, target_xy, 1.0)``.
    simplify : bool
        Follow line-of-sight waypoints (:func:`simplify_path`) rather than every cell centre.
    escape_radius : float [m]
        When the robot's own cell is blocked (it drifted into a grown obstacle, or an obstacle was seen
        next to it), plan from the nearest unblocked cell within this distance that a straight,
        obstacle-free line reaches, and drive there first. 0 disables it.
    """

    def __init__(
        self,
        plan: Callable[[CostGrid, tuple[float, float]], PathResult],
        *,
        simplify: bool = True,
        escape_radius: float = 0.5,
    ):
        self._plan = plan
        self.simplify = simplify
        self.escape_radius = float(escape_radius)
        self.path: PathResult | None = None
        self.waypoints = np.zeros((0, 2))

    def _plan_from(self, grid: CostGrid, xy: tuple[float, float]) -> tuple[PathResult, np.ndarray, bool]:
        result = self._plan(grid, xy)
        escaped = False
        if result.status is PathStatus.START_IN_OBSTACLE and self.escape_radius > 0:
            alt = self._escape_cell(grid, xy)
            if alt is not None:
                result = self._plan(grid, alt)
                escaped = result.found
        if not result.found:
            return result, np.zeros((0, 2)), False
        wp = simplify_path(result, grid) if self.simplify else result.points_xy.copy()
        if escaped:
            wp = np.vstack([np.asarray(xy)[None, :], wp])
        return result, wp, escaped

    def _escape_cell(self, grid: CostGrid, xy) -> tuple[float, float] | None:
        X, Y = grid.spec.cell_centers()
        d = np.hypot(X - xy[0], Y - xy[1])
        cand = np.isfinite(grid.cost) & (d <= self.escape_radius)
        lethal = grid.obstacle_distance == 0 if grid.obstacle_distance is not None else grid.blocked
        for k in np.argsort(np.where(cand, d, np.inf), axis=None)[: int(cand.sum())]:
            i, j = np.unravel_index(k, d.shape)
            target = (float(X[i, j]), float(Y[i, j]))
            ij, _ = segment_cells(grid, xy, target)
            if not lethal[ij[:, 0], ij[:, 1]].any():
                return target
        return None

    def update(self, grid: CostGrid, pose) -> ReplanDecision:
        """Check the path ahead of ``pose`` on ``grid``; replan from ``pose`` if it is blocked or missing.

        Raises
        ------
        ValueError
            ``pose`` has a NaN or infinite coordinate.
        """
        xy = check_finite_xy("pose", pose)
        if self.path is None or not self.path.found or len(self.waypoints) == 0:
            reason = "initial" if self.path is None else "retry"
            result, wp, escaped = self._plan_from(grid, xy)
            self.path, self.waypoints = result, wp
            return ReplanDecision(True, "escape" if escaped else reason, result, wp)
        blocked = self._blocked_ahead(grid, xy)
        if blocked is None:
            return ReplanDecision(False, "clear", self.path, self.waypoints)
        result, wp, escaped = self._plan_from(grid, xy)
        self.path, self.waypoints = result, wp
        return ReplanDecision(True, "escape" if escaped else "blocked", result, wp, blocked)

    def _blocked_ahead(self, grid: CostGrid, xy: tuple[float, float]) -> int | None:
        """First blocked segment of the waypoints from the robot's projection on the path onwards.

        When the robot itself stands in a blocked cell (it is escaping a grown obstacle), blocked cells
        within ``escape_radius`` of it count only if they are obstacle cells themselves.
        """
        W = self.waypoints
        k0 = nearest_index(W, xy)
        ahead = W[k0:].copy()
        if len(ahead) >= 2:  # start from the robot's projection on segment k0
            a, b = ahead[0], ahead[1]
            ab = b - a
            L2 = float(ab @ ab)
            t = 0.0 if L2 == 0 else min(1.0, max(0.0, float((np.asarray(xy) - a) @ ab) / L2))
            ahead[0] = a + t * ab
        spec = grid.spec
        i, j = spec.cells_of(np.array([xy]))[0][0]
        inside = spec.contains_xy(*xy)
        escaping = inside and not math.isfinite(grid.cost[i, j])
        for k in range(len(ahead) - 1 if len(ahead) > 1 else 1):
            b = ahead[k + 1] if len(ahead) > 1 else ahead[k]
            ij, on_map = segment_cells(grid, ahead[k], b)
            if not on_map:
                return k0 + k
            bad = ~np.isfinite(grid.cost[ij[:, 0], ij[:, 1]])
            if escaping and grid.obstacle_distance is not None:
                centres = spec.centers_of(ij)
                near = np.hypot(centres[:, 0] - xy[0], centres[:, 1] - xy[1]) <= self.escape_radius
                bad &= ~near | (grid.obstacle_distance[ij[:, 0], ij[:, 1]] == 0)
            if bad.any():
                return k0 + k
        return None
