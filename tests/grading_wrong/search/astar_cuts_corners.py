"""astar lets a diagonal step pass between two obstacles (corner cutting).

Base: reference
Fails: astar_valid_path, astar_optimal, astar_no_path, astar_large_map
"""

import heapq
import math

import numpy as np


def astar(cost, start, goal):
    cost = np.asarray(cost, dtype=float)
    nx, ny = cost.shape
    start, goal = (int(start[0]), int(start[1])), (int(goal[0]), int(goal[1]))
    if not (math.isfinite(cost[start]) and math.isfinite(cost[goal])):
        return np.zeros((0, 2), dtype=int), math.inf
    m_min = float(cost[np.isfinite(cost)].min())
    g, parent, closed = {start: 0.0}, {start: None}, set()
    open_list = [(octile_heuristic(start, goal, m_min), 0.0, start)]  # noqa: F821
    while open_list:
        _, g_u, u = heapq.heappop(open_list)
        if u in closed:
            continue
        if u == goal:
            path = [u]
            while parent[path[-1]] is not None:
                path.append(parent[path[-1]])
            return np.array(path[::-1], dtype=int), g_u
        closed.add(u)
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                v = (u[0] + di, u[1] + dj)
                if (di, dj) == (0, 0) or not (0 <= v[0] < nx and 0 <= v[1] < ny) or v in closed:
                    continue
                if not math.isfinite(cost[v]):
                    continue
                g_v = g_u + (math.sqrt(2.0) if di and dj else 1.0) * cost[v]
                if g_v < g.get(v, math.inf):
                    g[v], parent[v] = g_v, u
                    heapq.heappush(open_list, (g_v + octile_heuristic(v, goal, m_min), g_v, v))  # noqa: F821
    return np.zeros((0, 2), dtype=int), math.inf
