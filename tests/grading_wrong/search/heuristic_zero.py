"""octile_heuristic returns 0: admissible and consistent, and A* with it is Dijkstra (still optimal),
but it is not the octile distance.

Base: reference
Fails: heuristic_octile, heuristic_admissible
"""


def octile_heuristic(cell, goal, min_cost):
    return 0.0
