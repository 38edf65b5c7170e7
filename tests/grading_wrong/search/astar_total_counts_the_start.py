"""astar adds the start cell's cost to the total (an off-by-one over the path's cells).

Base: reference
Fails: astar_valid_path, astar_optimal, astar_no_path, astar_large_map
"""

_right_astar = astar  # noqa: F821  (the reference's, defined above in the graded module)


def astar(cost, start, goal):
    path, total = _right_astar(cost, start, goal)
    if len(path) == 0:
        return path, total
    return path, total + float(cost[tuple(path[0])])
