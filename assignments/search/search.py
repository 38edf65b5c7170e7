r"""Assignment 3: the probability map's Bayes update and A* on the costmap.

The object-search paper keeps a grid *probability map* ``P`` over the floor: ``P[i, j]`` is the
probability that the object is in cell ``c_{i,j}`` (the map sums to 1). Every detection attempt on
one cell ``(u, v)`` returns ``y = 1`` (detected) or ``y = 0`` and updates the whole map by Bayes'
rule (Eqs. (1)-(3)), with the sensor's error rates

* ``alpha``: false-alarm probability, ``P(y = 1 | the object is elsewhere)``;
* ``beta``: missed-detection probability, ``P(y = 0 | the object is in the cell looked at)``.

The robot then drives to the next peak on a *costmap*: A* over an 8-connected grid (Sec. III-D).

Cells are ``(i, j)`` index pairs into ``(nx, ny)`` arrays (docs/conventions.md, "Grid maps").
Write the functions below with NumPy and the standard library (``heapq``); no ``lab`` imports. Run the
public tests with ``python -m pytest test_search.py``.
"""

import heapq
import math

import numpy as np


def detection_likelihood(shape, cell, detected: bool, alpha: float, beta: float) -> np.ndarray:
    r"""The detection model of Eq. (2): ``P(y_{u,v} = detected | h_{i,j} = 1)`` for every cell ``(i, j)``.

    .. math::

        P(y_{u,v} = 1 \mid h_{i,j} = 1) = \begin{cases} 1 - \beta & (i, j) = (u, v) \\
                                                        \alpha & (i, j) \ne (u, v) \end{cases}
        \qquad P(y_{u,v} = 0 \mid h_{i,j} = 1) = 1 - P(y_{u,v} = 1 \mid h_{i,j} = 1)

    Parameters
    ----------
    shape : (int, int)
        ``(nx, ny)``, the map's shape.
    cell : (int, int)
        ``(u, v)``, the cell that was looked at.
    detected : bool
        The measurement ``y_{u,v}``.
    alpha : float
        False-alarm probability, in (0, 1).
    beta : float
        Missed-detection probability, in (0, 1).

    Returns
    -------
    ndarray, shape (nx, ny)
        Entry ``(i, j)`` is the probability of this measurement if the object were in ``c_{i,j}``.
    """
    ### BEGIN SOLUTION
    u, v = (int(c) for c in cell)
    if detected:
        lik = np.full(shape, alpha, dtype=float)  # a false alarm: the object is elsewhere
        lik[u, v] = 1.0 - beta  # a true detection
    else:
        lik = np.full(shape, 1.0 - alpha, dtype=float)  # correctly nothing
        lik[u, v] = beta  # a missed detection
    return lik
    ### END SOLUTION


def update_probability_map(P, cell, detected: bool, alpha: float, beta: float) -> np.ndarray:
    r"""One Bayes update of the probability map, Eqs. (1)-(3) of the object-search paper.

    .. math::

        P(h_{i,j} = 1 \mid \mathbf{Y}_{1:k}) =
        \frac{P(y_{u,v}^k \mid h_{i,j} = 1)\, P(h_{i,j} = 1 \mid \mathbf{Y}_{1:k-1})}
             {\sum_{m,n} P(y_{u,v}^k \mid h_{m,n} = 1)\, P(h_{m,n} = 1 \mid \mathbf{Y}_{1:k-1})}

    A miss moves probability mass from the cell looked at to all the others; a detection the other way.

    Parameters
    ----------
    P : array_like, shape (nx, ny)
        The prior map, non-negative, summing to 1.
    cell : (int, int)
    detected : bool
    alpha, beta : float
        As in :func:`detection_likelihood`.

    Returns
    -------
    ndarray, shape (nx, ny)
        The posterior map, summing to 1 (a new array; ``P`` is not modified).
    """
    ### BEGIN SOLUTION
    P = np.asarray(P, dtype=float)
    numerator = detection_likelihood(P.shape, cell, detected, alpha, beta) * P  # Eq. (1)'s numerator
    return numerator / numerator.sum()  # Eq. (3): the sum over all cells
    ### END SOLUTION


def octile_heuristic(cell, goal, min_cost: float) -> float:
    r"""A*'s heuristic on the 8-connected costmap: the octile distance times the smallest cell cost.

    .. math:: h = m_{min} \left( \max(\Delta_i, \Delta_j) + (\sqrt 2 - 1) \min(\Delta_i, \Delta_j) \right)

    with ``Delta_i = |i - i_goal|``, ``Delta_j = |j - j_goal|``: the exact cost of the cheapest path
    on an obstacle-free map whose cells all cost ``m_min``, so it never overestimates (admissible).

    Parameters
    ----------
    cell, goal : (int, int)
    min_cost : float
        The smallest cost multiplier on the map (>= 1).

    Returns
    -------
    float [cells]
    """
    ### BEGIN SOLUTION
    di, dj = abs(int(cell[0]) - int(goal[0])), abs(int(cell[1]) - int(goal[1]))
    return min_cost * (max(di, dj) + (math.sqrt(2.0) - 1.0) * min(di, dj))
    ### END SOLUTION


def astar(cost, start, goal):
    r"""The cheapest path on a costmap, by A* with :func:`octile_heuristic`.

    The graph: every cell is a node; from a cell you may step to its 8 neighbours. A step into cell
    ``v`` costs ``length * cost[v]`` with ``length`` 1 (edge neighbour) or ``sqrt(2)`` (diagonal), in
    cells. Cells with ``cost = inf`` are obstacles: never entered, and a diagonal step may not cut past
    one (both cells it passes between must be free). A path's cost is the sum of its steps' costs.

    Stop when the goal is taken off the open list (not when it is first seen): only then is its cost
    final.

    Parameters
    ----------
    cost : array_like, shape (nx, ny)
        Cost multiplier of each cell, ``>= 1`` or ``inf`` (obstacle).
    start, goal : (int, int)
        Cells inside the map.

    Returns
    -------
    path : ndarray of int, shape (k, 2)
        The cells from ``start`` to ``goal`` inclusive (``[start]`` when they are equal), or shape (0, 2)
        when there is no path (the goal is unreachable, or the start or the goal is an obstacle).
    total : float
        The path's cost, ``inf`` without a path.
    """
    ### BEGIN SOLUTION
    cost = np.asarray(cost, dtype=float)
    nx, ny = cost.shape
    start = (int(start[0]), int(start[1]))
    goal = (int(goal[0]), int(goal[1]))
    no_path = (np.zeros((0, 2), dtype=int), math.inf)
    if not (math.isfinite(cost[start]) and math.isfinite(cost[goal])):
        return no_path
    m_min = float(cost[np.isfinite(cost)].min())
    g = {start: 0.0}
    parent = {start: None}
    closed = set()
    open_list = [(octile_heuristic(start, goal, m_min), 0.0, start)]  # (f = g + h, g, cell)
    while open_list:
        _, g_u, u = heapq.heappop(open_list)
        if u in closed:
            continue  # an outdated entry: u was reached more cheaply later
        if u == goal:
            path = [u]
            while parent[path[-1]] is not None:
                path.append(parent[path[-1]])
            return np.array(path[::-1], dtype=int), g_u
        closed.add(u)
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                v = (u[0] + di, u[1] + dj)
                if (di == 0 and dj == 0) or not (0 <= v[0] < nx and 0 <= v[1] < ny) or v in closed:
                    continue
                if not math.isfinite(cost[v]):
                    continue
                if (
                    di
                    and dj
                    and not (math.isfinite(cost[u[0] + di, u[1]]) and math.isfinite(cost[u[0], u[1] + dj]))
                ):
                    continue  # no cutting corners past an obstacle
                g_v = g_u + (math.sqrt(2.0) if di and dj else 1.0) * cost[v]
                if g_v < g.get(v, math.inf):
                    g[v] = g_v
                    parent[v] = u
                    heapq.heappush(open_list, (g_v + octile_heuristic(v, goal, m_min), g_v, v))
    return no_path
    ### END SOLUTION
