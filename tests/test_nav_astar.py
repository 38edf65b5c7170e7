"""A* against networkx on the same weighted 8-connected graph (an independent peer), and its contract.

The peer graph is built here from the cost grid with the rules written in ``lab.navigation.astar``:
a step into cell v costs ``(1 or sqrt 2) * resolution * cost[v]``, blocked (inf) cells are never
entered, and a diagonal step needs both cells it passes between to be unblocked.
"""

import math
import time

import networkx as nx
import numpy as np
import pytest
from nav_scenes import random_grid

from lab.geometry import Pose2D
from lab.navigation.astar import PathStatus, astar, astar_cells, astar_to_region, heading_towards
from lab.navigation.costmap import CostGrid
from lab.navigation.grid import GridSpec, OutsideMap

SQ2 = math.sqrt(2.0)


def peer_graph(grid: CostGrid) -> nx.DiGraph:
    c, res = grid.cost, grid.spec.resolution
    nx_, ny_ = c.shape
    ok = np.isfinite(c)
    G = nx.DiGraph()
    G.add_nodes_from((int(i), int(j)) for i, j in np.argwhere(ok))
    for i, j in np.argwhere(ok):
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                a, b = i + di, j + dj
                if (di, dj) == (0, 0) or not (0 <= a < nx_ and 0 <= b < ny_) or not ok[a, b]:
                    continue
                if di and dj and not (ok[i + di, j] and ok[i, j + dj]):
                    continue
                w = (SQ2 if di and dj else 1.0) * res * c[a, b]
                G.add_edge((int(i), int(j)), (int(a), int(b)), weight=w)
    return G


def assert_valid_path(grid: CostGrid, r, start, goal=None):
    cells = r.cells
    assert tuple(cells[0]) == tuple(start)
    if goal is not None:
        assert tuple(cells[-1]) == tuple(goal)
    assert np.isfinite(grid.cost[cells[:, 0], cells[:, 1]]).all(), "path enters a blocked cell"
    steps = np.diff(cells, axis=0)
    assert (np.abs(steps).max(axis=1) == 1).all(), "path is not 8-connected step by step"
    total = 0.0
    for (i, j), (di, dj) in zip(cells[:-1], steps, strict=True):
        if di and dj:
            assert np.isfinite(grid.cost[i + di, j]) and np.isfinite(grid.cost[i, j + dj]), "corner cut"
        a, b = i + di, j + dj
        total += (SQ2 if di and dj else 1.0) * grid.spec.resolution * grid.cost[a, b]
    assert total == pytest.approx(r.cost, rel=1e-12, abs=1e-12)
    np.testing.assert_allclose(r.points_xy, grid.spec.centers_of(cells))


def test_costs_equal_networkx_on_random_grids_including_unreachable():
    rng = np.random.default_rng(20240501)
    n_found = n_unreachable = n_blocked = 0
    for _ in range(150):
        grid = random_grid(rng)
        G = peer_graph(grid)
        nx_, ny_ = grid.spec.shape
        for _ in range(3):
            s = (int(rng.integers(nx_)), int(rng.integers(ny_)))
            g = (int(rng.integers(nx_)), int(rng.integers(ny_)))
            r = astar_cells(grid, s, g)
            if not np.isfinite(grid.cost[s]):
                assert r.status is PathStatus.START_IN_OBSTACLE
                n_blocked += 1
                continue
            if not np.isfinite(grid.cost[g]):
                assert r.status is PathStatus.GOAL_IN_OBSTACLE
                n_blocked += 1
                continue
            try:
                expected = nx.dijkstra_path_length(G, s, g, weight="weight")
            except nx.NetworkXNoPath:
                assert r.status is PathStatus.UNREACHABLE and r.reason == "UNREACHABLE"
                assert math.isinf(r.cost) and len(r.cells) == 0
                n_unreachable += 1
                continue
            assert r.found, (s, g, r.status)
            assert r.cost == pytest.approx(expected, rel=1e-9, abs=1e-12)
            assert_valid_path(grid, r, s, g)
            n_found += 1
    # the sample covers all three outcomes in numbers
    assert n_found >= 200 and n_unreachable >= 20 and n_blocked >= 20, (n_found, n_unreachable, n_blocked)


def test_compiled_and_python_searches_are_the_same_search():
    """The numba kernel and the readable Python version expand the same cells and return the same path."""
    rng = np.random.default_rng(11)
    for _ in range(40):
        grid = random_grid(rng)
        free = np.argwhere(np.isfinite(grid.cost))
        if len(free) < 2:
            continue
        for _ in range(3):
            s, g = (tuple(free[k]) for k in rng.integers(0, len(free), 2))
            a, b = astar_cells(grid, s, g, backend="compiled"), astar_cells(grid, s, g, backend="python")
            assert a.status == b.status and a.expanded == b.expanded
            np.testing.assert_array_equal(a.cells, b.cells)
            assert a.cost == b.cost
        target = grid.spec.centers_of(free[rng.integers(0, len(free), 1)])[0]
        a = astar_to_region(grid, grid.spec.centers_of(free[:1])[0], target, 0.5, 0.2, backend="compiled")
        b = astar_to_region(grid, grid.spec.centers_of(free[:1])[0], target, 0.5, 0.2, backend="python")
        assert a.status == b.status and a.cost == b.cost
        np.testing.assert_array_equal(a.cells, b.cells)
    with pytest.raises(ValueError, match="backend must be"):
        astar_cells(grid, s, g, backend="cuda")


def test_same_query_gives_the_same_path_bit_for_bit():
    rng = np.random.default_rng(3)
    grid = random_grid(rng, shape=(40, 40), res=0.1)
    free = np.argwhere(np.isfinite(grid.cost))
    s, g = tuple(free[0]), tuple(free[-1])
    a, b = astar_cells(grid, s, g), astar_cells(grid, s, g)
    assert a.status == b.status
    np.testing.assert_array_equal(a.cells, b.cells)
    assert a.cost == b.cost and a.expanded == b.expanded


def test_open_grid_path_is_the_octile_distance_and_expands_only_along_it():
    spec = GridSpec((0.0, 0.0), 0.1, (60, 40))
    grid = CostGrid(spec, np.ones(spec.shape))
    r = astar_cells(grid, (2, 3), (50, 30))
    dx, dy = 48, 27
    assert r.cost == pytest.approx(0.1 * (dx + dy + (SQ2 - 2) * min(dx, dy)), rel=1e-12)
    # the heuristic is exact on an open grid and ties go to the smaller h: no detours are expanded
    assert r.expanded == len(r.cells)


def test_world_point_queries_and_poses():
    spec = GridSpec((-1.0, -2.0), 0.1, (30, 30))
    cost = np.ones(spec.shape)
    cost[10:12, 0:25] = np.inf  # a wall with a gap at the top
    grid = CostGrid(spec, cost)
    r = astar(grid, Pose2D(-0.95, -1.95, 0.3), (0.85, -1.95))
    assert r.found and r.goal_cell == spec.world_to_cell(0.85, -1.95)
    assert_valid_path(grid, r, spec.world_to_cell(-0.95, -1.95))
    assert r.length >= r.cost - 1e-12  # all multipliers are 1 here: the cost is the length
    assert r.length == pytest.approx(r.cost)


def test_region_goal_costs_equal_networkx_with_a_super_goal():
    rng = np.random.default_rng(11)
    checked = 0
    for _ in range(60):
        grid = random_grid(rng, res=0.1)
        G = peer_graph(grid)
        nx_, ny_ = grid.spec.shape
        free = np.argwhere(np.isfinite(grid.cost))
        if len(free) == 0:
            continue
        s = tuple(int(v) for v in free[rng.integers(len(free))])
        x0, x1, y0, y1 = grid.spec.extent
        target = (rng.uniform(x0, x1), rng.uniform(y0, y1))
        rmin, rmax = sorted(rng.uniform(0.0, 0.8, size=2))
        r = astar_to_region(grid, grid.spec.centers_of([s])[0], target, rmax, rmin)
        X, Y = grid.spec.cell_centers()
        d = np.hypot(X - target[0], Y - target[1])
        goals = [
            tuple(int(v) for v in c) for c in np.argwhere((d >= rmin) & (d <= rmax) & np.isfinite(grid.cost))
        ]
        if not ((d >= rmin) & (d <= rmax)).any():
            assert r.status is PathStatus.GOAL_OUTSIDE_MAP
            continue
        if not goals:
            assert r.status is PathStatus.GOAL_IN_OBSTACLE
            continue
        G.add_node("GOAL")
        for c in goals:
            G.add_edge(c, "GOAL", weight=0.0)
        try:
            expected = nx.dijkstra_path_length(G, s, "GOAL", weight="weight")
        except nx.NetworkXNoPath:
            assert r.status is PathStatus.UNREACHABLE
            continue
        assert r.found and r.cost == pytest.approx(expected, rel=1e-9, abs=1e-12)
        assert tuple(r.cells[-1]) in set(goals)
        assert_valid_path(grid, r, s)
        checked += 1
    assert checked >= 25


def test_heading_towards_faces_the_target():
    assert heading_towards((0.0, 0.0), (0.0, 2.0)) == pytest.approx(math.pi / 2)
    assert heading_towards(Pose2D(1.0, 1.0, 0.0), (0.0, 1.0)) == pytest.approx(math.pi)


class TestBadInput:
    def setup_method(self):
        spec = GridSpec((0.0, 0.0), 0.1, (200, 200))
        cost = np.ones(spec.shape)
        cost[100, :] = np.inf  # a wall across the whole map: the top half is unreachable
        cost[50:60, 50:60] = np.inf
        self.grid = CostGrid(spec, cost)

    def test_goal_outside_map(self):
        r = astar(self.grid, (1.0, 1.0), (25.0, 1.0))
        assert r.status is PathStatus.GOAL_OUTSIDE_MAP and r.expanded == 0 and not r.found
        assert astar(self.grid, (-1.0, 1.0), (1.0, 1.0)).status is PathStatus.START_OUTSIDE_MAP
        # the upper edge of the map is outside (half-open cells)
        assert astar(self.grid, (1.0, 1.0), (20.0, 1.0)).status is PathStatus.GOAL_OUTSIDE_MAP

    def test_goal_and_start_in_obstacle(self):
        assert astar(self.grid, (1.0, 1.0), (5.55, 5.55)).reason == "GOAL_IN_OBSTACLE"
        assert astar(self.grid, (5.55, 5.55), (1.0, 1.0)).reason == "START_IN_OBSTACLE"

    def test_unreachable_is_a_result_not_a_hang(self):
        t0 = time.perf_counter()
        r = astar(self.grid, (1.0, 1.0), (15.0, 15.0))
        assert time.perf_counter() - t0 < 10.0  # a generous bound, not a benchmark: it must terminate
        assert r.status is PathStatus.UNREACHABLE
        # it searched the whole reachable half and nothing else
        assert r.expanded == int(np.isfinite(self.grid.cost[:100]).sum())

    @pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
    def test_non_finite_poses_raise_naming_the_argument(self, bad):
        with pytest.raises(ValueError, match="start"):
            astar(self.grid, (bad, 1.0), (1.0, 1.0))
        with pytest.raises(ValueError, match="goal"):
            astar(self.grid, (1.0, 1.0), Pose2D(1.0, bad, 0.0))
        with pytest.raises(ValueError, match="goal"):
            astar(self.grid, (1.0, 1.0), Pose2D(1.0, 1.0, bad))
        with pytest.raises(ValueError, match="target_xy"):
            astar_to_region(self.grid, (1.0, 1.0), (bad, 2.0), 1.0)


class TestGridSpec:
    def test_round_trip_and_half_open_cells(self):
        spec = GridSpec((-2.0, 1.0), 0.1, (50, 30))
        rng = np.random.default_rng(0)
        for _ in range(200):
            i, j = int(rng.integers(50)), int(rng.integers(30))
            x, y = spec.cell_to_world(i, j)
            assert spec.world_to_cell(x, y) == (i, j)
        assert spec.world_to_cell(-2.0, 1.0) == (0, 0)
        x0, x1, y0, y1 = spec.extent
        assert (x1, y1) == pytest.approx((3.0, 4.0))
        with pytest.raises(OutsideMap, match="outside the map"):
            spec.world_to_cell(x1, 2.0)
        with pytest.raises(OutsideMap):
            spec.world_to_cell(0.0, y0 - 1e-9)
        with pytest.raises(OutsideMap, match="cell"):
            spec.cell_to_world(50, 0)
        with pytest.raises(ValueError, match="finite"):
            spec.world_to_cell(math.nan, 2.0)

    def test_vectorised_cells_match_the_scalar_form(self):
        spec = GridSpec.from_bounds(-1.0, -1.0, 2.0, 1.5, 0.1)
        assert spec.shape == (30, 25)
        rng = np.random.default_rng(1)
        xy = rng.uniform(-1.5, 2.5, size=(500, 2))
        xy[0] = np.nan
        ij, inside = spec.cells_of(xy)
        assert not inside[0]
        for k in range(1, 500):
            if inside[k]:
                assert spec.world_to_cell(*xy[k]) == tuple(ij[k])
            else:
                with pytest.raises(OutsideMap):
                    spec.world_to_cell(*xy[k])
        np.testing.assert_array_equal(spec.unflat(spec.flat(ij[inside])), ij[inside])

    @pytest.mark.parametrize(
        "args",
        [((0, 0), 0.0, (3, 3)), ((0, 0), -1.0, (3, 3)), ((0, math.nan), 0.1, (3, 3)), ((0, 0), 0.1, (0, 3))],
    )
    def test_bad_specs_are_refused(self, args):
        with pytest.raises(ValueError):
            GridSpec(*args)
