"""astar returns the right path with a total cost of NaN (issue 48: it passed every A* test).

Base: reference
Fails: astar_valid_path, astar_optimal, astar_no_path, astar_large_map
"""

_right_astar = astar  # noqa: F821  (the reference's, defined above in the graded module)


def astar(cost, start, goal):
    path, total = _right_astar(cost, start, goal)
    return path, (total if len(path) == 0 else float("nan"))
