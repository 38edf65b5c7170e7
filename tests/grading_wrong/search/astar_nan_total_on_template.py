"""The issue's attack as it came (issue 48: it scored 7/17): the released template with only astar
written, Dijkstra's search giving the right path, and a total cost of NaN.

Base: template
Fails: *
"""

import heapq
import math

import numpy as np


def astar(cost, start, goal):
    cost = np.asarray(cost, dtype=float)
    nx, ny = cost.shape
    start, goal = (int(start[0]), int(start[1])), (int(goal[0]), int(goal[1]))
    if not (np.isfinite(cost[start]) and np.isfinite(cost[goal])):
        return np.zeros((0, 2), dtype=int), math.inf
    best, came, todo = {start: 0.0}, {}, [(0.0, start)]
    while todo:
        g, u = heapq.heappop(todo)
        if u == goal:
            path = [u]
            while path[-1] in came:
                path.append(came[path[-1]])
            return np.array(path[::-1], dtype=int), float("nan")
        if g > best[u]:
            continue
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                v = (u[0] + di, u[1] + dj)
                if (di, dj) == (0, 0) or v[0] not in range(nx) or v[1] not in range(ny):
                    continue
                free = np.isfinite(cost[v])
                if di and dj:  # no corner cutting
                    free = free and np.isfinite(cost[u[0] + di, u[1]]) and np.isfinite(cost[u[0], u[1] + dj])
                if not free:
                    continue
                gv = g + (math.sqrt(2) if di and dj else 1.0) * cost[v]
                if gv < best.get(v, math.inf):
                    best[v], came[v] = gv, u
                    heapq.heappush(todo, (gv, v))
    return np.zeros((0, 2), dtype=int), math.inf
