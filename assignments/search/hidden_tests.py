"""Graded tests of assignment 3 (probability map and A*). Never released to students.

The map update is checked against Eqs. (1)-(3) written out here; A* against networkx's Dijkstra on
the same graph (8-connected, a step into ``v`` costs ``length * cost[v]``, no corner cutting) on fixed
maps and seeded random ones.
"""

import hashlib
import math

import networkx as nx
import numpy as np

from lab.grading.suite import TestSuite, as_array, as_float, check_close, fail

suite = TestSuite("search")

ALPHA, BETA = 0.05, 0.2  # false alarm, missed detection: different, so a swap shows
INF = math.inf


# ------------------------------------------------------------------------------------------ oracles
def likelihood_ref(shape, cell, detected, alpha=ALPHA, beta=BETA):
    here = np.zeros(shape, bool)
    here[cell] = True
    p_detect = np.where(here, 1 - beta, alpha)  # Eq. (2)
    return p_detect if detected else 1 - p_detect


def update_ref(P, cell, detected, alpha=ALPHA, beta=BETA):
    num = likelihood_ref(P.shape, cell, detected, alpha, beta) * P
    return num / num.sum()


def _random_map(rng, shape):
    P = rng.gamma(2.0, 1.0, shape)
    return P / P.sum()


def graph_of(cost):
    """The costmap's graph: directed edges u -> v weighted length * cost[v], no corner cutting."""
    G = nx.DiGraph()
    nx_, ny_ = cost.shape
    free = np.isfinite(cost)
    for i in range(nx_):
        for j in range(ny_):
            if not free[i, j]:
                continue
            G.add_node((i, j))
            for di in (-1, 0, 1):
                for dj in (-1, 0, 1):
                    a, b = i + di, j + dj
                    if (di, dj) == (0, 0) or a not in range(nx_) or b not in range(ny_) or not free[a, b]:
                        continue
                    if di and dj and not (free[i + di, j] and free[i, j + dj]):
                        continue
                    G.add_edge((i, j), (a, b), weight=(math.sqrt(2) if di and dj else 1.0) * cost[a, b])
    return G


_BEST: dict = {}  # (map digest, shape, start, goal) -> cheapest cost: the maps are fixed or seeded


def best_cost(cost, start, goal):
    """The cheapest cost from ``start`` to ``goal`` (networkx's Dijkstra), remembered per map and pair:
    several tests and every student of a class ask for the same ones."""
    cost = np.ascontiguousarray(cost, dtype=float)
    key = (hashlib.sha256(cost.tobytes()).hexdigest(), cost.shape, tuple(start), tuple(goal))
    if key not in _BEST:
        try:
            _BEST[key] = nx.dijkstra_path_length(graph_of(cost), tuple(start), tuple(goal))
        except (nx.NetworkXNoPath, nx.NodeNotFound):
            _BEST[key] = INF
    return _BEST[key]


# --------------------------------------------------------------------------------------------- maps
def map_open():
    return np.ones((24, 18)), (2, 3), (20, 15)


def map_wall_gap():
    c = np.ones((30, 30))
    c[15, :26] = INF  # a wall with a gap at the top
    return c, (3, 5), (27, 5)


def map_u_trap():
    """A U open towards the start with the goal behind it: heuristics that overestimate walk in."""
    c = np.ones((32, 32))
    c[10:22, 20] = INF  # the bottom of the U, between start and goal
    c[10, 10:21] = INF
    c[21, 10:21] = INF
    return c, (16, 4), (16, 28)


def map_weighted():
    """Unknown cells (cost 4) across the middle, a cheap corridor round one end, grown obstacles (2)."""
    c = np.ones((28, 28))
    c[:, 10:18] = 4.0
    c[:5, 10:18] = 1.0  # a corridor of known floor
    c[14:17, 12:16] = INF
    c[13:18, 11:17][~np.isinf(c[13:18, 11:17])] = 2.0
    return c, (20, 2), (22, 26)


def map_corner():
    """Diagonal gaps between obstacles: a path that cuts the corner is shorter, and not allowed."""
    c = np.ones((12, 12))
    for k in range(1, 11):
        c[k, 11 - k] = INF  # an anti-diagonal wall: only corner-cutting steps cross it ...
    c[0, 11] = 1.0
    c[11, 0] = 1.0  # ... apart from going round its ends
    return c, (2, 2), (9, 9)


def map_random(seed, shape=(40, 40), density=0.25):
    rng = np.random.default_rng(seed)
    c = rng.choice([1.0, 1.0, 1.0, 1.5, 3.0], size=shape)
    c[rng.random(shape) < density] = INF
    free = np.argwhere(np.isfinite(c))
    pairs = [
        [tuple(int(v) for v in free[k]) for k in rng.choice(len(free), 2, replace=False)] for _ in range(4)
    ]
    return c, pairs


# ---------------------------------------------------------------------------------- the map update
@suite.test(
    "detection_likelihood: the detection model of Eq. (2) for y = 1 and y = 0",
    points=1,
    target="detection_likelihood",
    visibility="visible",
)
def detection_likelihood_eq2(sub):
    shape, cell = (6, 5), (2, 3)
    for detected in (True, False):
        got = as_array(
            sub.detection_likelihood(shape, cell, detected, ALPHA, BETA),
            f"detection_likelihood(shape, cell, detected={detected}, alpha, beta)",
            shape,
        )
        want = likelihood_ref(shape, cell, detected)
        if np.allclose(got, likelihood_ref(shape, cell, detected, alpha=BETA, beta=ALPHA)):
            fail(
                f"detection_likelihood(detected={detected}) has alpha and beta swapped: alpha = {ALPHA} is "
                "the "
                f"false-alarm rate (y = 1 with the object elsewhere), beta = {BETA} the missed-detection "
                "rate "
                "(y = 0 with the object in the cell looked at)"
            )
        check_close(
            got,
            want,
            f"detection_likelihood(detected={detected})",
            atol=1e-12,
            hint="In the cell looked at: P(y=1) = 1 - beta, P(y=0) = beta; elsewhere P(y=1) = alpha.",
        )


def _updated(sub, P, cell, detected):
    what = f"update_probability_map(P, cell={cell}, detected={detected}, alpha, beta)"
    Q = as_array(sub.update_probability_map(P, cell, detected, ALPHA, BETA), what, P.shape)
    if not abs(Q.sum() - 1) <= 1e-9:
        fail(f"{what} sums to {Q.sum():.6g}, not 1: divide by Eq. (3)'s sum over all cells")
    if not Q.min() >= 0:
        fail(f"{what} has a negative probability {Q.min():.3g}")
    return Q


def _check_bayes(Q, P, cell, detected):
    """``Q`` equals Eq. (1) written out here (a map returned unchanged or moved the wrong way fails)."""
    check_close(
        Q,
        update_ref(P, cell, detected),
        f"update_probability_map(P, cell={cell}, detected={detected}, alpha, beta)",
        rtol=1e-9,
        atol=1e-14,
        hint="Eq. (1): the likelihood of Eq. (2) times the prior, divided by its sum over all cells "
        "(Eq. (3))." + _swap_hint(Q, P, cell, detected),
    )


def _swap_hint(Q, P, cell, detected):
    if np.allclose(Q, update_ref(P, cell, detected, alpha=BETA, beta=ALPHA), atol=1e-12):
        return (
            f"\nThat is exactly what alpha and beta swapped give: alpha = {ALPHA} is the false-alarm rate, "
            f"beta = {BETA} the missed-detection rate."
        )
    return ""


@suite.test(
    "update_probability_map returns a probability map (shape kept, non-negative, sums to 1): Bayes' rule",
    points=1,
    target="update_probability_map",
    uses=("detection_likelihood",),
    visibility="visible",
)
def map_update_normalised(sub):
    rng = np.random.default_rng(51)
    for detected in (True, False):
        P = _random_map(rng, (9, 7))
        _check_bayes(_updated(sub, P, (4, 2), detected), P, (4, 2), detected)


@suite.test(
    "update_probability_map after a miss: the cell looked at loses exactly Bayes' share",
    points=2,
    target="update_probability_map",
    uses=("detection_likelihood",),
)
def map_update_miss(sub):
    rng = np.random.default_rng(52)
    P = _random_map(rng, (10, 8))
    cell = tuple(int(v) for v in np.unravel_index(np.argmax(P), P.shape))
    Q = _updated(sub, P, cell, False)
    want = update_ref(P, cell, False)
    if not np.allclose(Q, want, rtol=1e-9, atol=1e-14):
        fail(
            f"after a miss at the peak {cell} (prior {P[cell]:.4f}) its probability should be "
            f"{want[cell]:.6f} = "
            f"beta P / (beta P + (1 - alpha)(1 - P)); got {Q[cell]:.6f}" + _swap_hint(Q, P, cell, False)
        )


@suite.test(
    "update_probability_map after a detection: the cell looked at gains exactly Bayes' share",
    points=2,
    target="update_probability_map",
    uses=("detection_likelihood",),
)
def map_update_hit(sub):
    rng = np.random.default_rng(53)
    P = _random_map(rng, (10, 8))
    cell = (7, 1)
    Q = _updated(sub, P, cell, True)
    want = update_ref(P, cell, True)
    if not np.allclose(Q, want, rtol=1e-9, atol=1e-14):
        fail(
            f"after a detection at {cell} (prior {P[cell]:.4f}) its probability should be {want[cell]:.6f} = "
            f"(1 - beta) P / ((1 - beta) P + alpha (1 - P)); got {Q[cell]:.6f}" + _swap_hint(Q, P, cell, True)
        )


@suite.test(
    "update_probability_map leaves the ratios between the other cells unchanged, scaled by Bayes' factor",
    points=1,
    target="update_probability_map",
    uses=("detection_likelihood",),
)
def map_update_other_cells(sub):
    rng = np.random.default_rng(54)
    for detected in (True, False):
        P = _random_map(rng, (8, 8))
        cell = (3, 3)
        Q = _updated(sub, P, cell, detected)
        others = np.ones(P.shape, bool)
        others[cell] = False
        ratio = Q[others] / P[others]
        if not np.ptp(ratio) <= 1e-9 * ratio.mean():
            fail(
                f"after {'a detection' if detected else 'a miss'} at {cell} the other cells were rescaled "
                f"unevenly (Q/P ranges over [{ratio.min():.4g}, {ratio.max():.4g}]): every cell other than "
                "the "
                "one looked at has the same likelihood, so they all scale by the same factor"
            )
        _check_bayes(Q, P, cell, detected)


@suite.test(
    "update_probability_map over 40 seeded looks equals the recursion of Eq. (1)",
    points=1,
    target="update_probability_map",
    uses=("detection_likelihood",),
)
def map_update_sequence(sub):
    rng = np.random.default_rng(55)
    shape, true_cell = (7, 6), (5, 4)
    P = np.full(shape, 1.0 / np.prod(shape))
    want = P.copy()
    for k in range(40):
        cell = tuple(int(v) for v in rng.integers(0, shape))
        p_detect = 1 - BETA if cell == true_cell else ALPHA
        detected = bool(rng.random() < p_detect)
        prior = want
        P = _updated(sub, P, cell, detected)
        want = update_ref(prior, cell, detected)
        if not np.allclose(P, want, rtol=1e-8, atol=1e-14):
            fail(
                f"after look {k + 1} ({'detected' if detected else 'missed'} at {cell}) the map differs from "
                f"Bayes' rule (largest error {np.abs(P - want).max():.3g})"
                + _swap_hint(P, prior, cell, detected)
            )
    return f"the true cell ends with probability {P[true_cell]:.3f}"


# -------------------------------------------------------------------------------------------- A*
def _path(out, what):
    if not (isinstance(out, list) and len(out) == 2):
        fail(f"{what} must return a pair (path, total); it returned {type(out).__name__}")
    raw, total = out
    total = as_float(total, f"the total cost from {what}", finite=False)
    if raw is None or np.asarray(raw).size == 0:
        return None, total
    path = as_array(raw, f"the path from {what}", (None, 2))
    if not np.all(path == np.round(path)):
        fail(f"the path from {what} holds non-integer cells")
    return [tuple(int(v) for v in p) for p in path], total


def _check_valid(path, total, cost, start, goal, what):
    if path is None:
        fail(f"{what} found no path, but there is one (of cost {best_cost(cost, start, goal):.4f})")
    if path[0] != tuple(start) or path[-1] != tuple(goal):
        fail(
            f"the path from {what} runs from {path[0]} to {path[-1]}, not from {tuple(start)} to "
            f"{tuple(goal)}"
        )
    acc = 0.0
    for a, b in zip(path[:-1], path[1:], strict=True):
        di, dj = b[0] - a[0], b[1] - a[1]
        if max(abs(di), abs(dj)) != 1:
            fail(f"the path from {what} jumps from {a} to {b}: consecutive cells must be 8-neighbours")
        if not (0 <= b[0] < cost.shape[0] and 0 <= b[1] < cost.shape[1]) or not math.isfinite(cost[b]):
            fail(f"the path from {what} enters the obstacle {b}")
        if di and dj and not (math.isfinite(cost[a[0] + di, a[1]]) and math.isfinite(cost[a[0], a[1] + dj])):
            fail(
                f"the path from {what} cuts a corner from {a} to {b} past an obstacle: a diagonal step "
                "needs both "
                f"{(a[0] + di, a[1])} and {(a[0], a[1] + dj)} free"
            )
        acc += (math.sqrt(2) if di and dj else 1.0) * cost[b]
    if not abs(acc - total) <= 1e-9 * max(1.0, acc):  # written so that a NaN total fails
        fail(
            f"{what} reports a total cost of {total:.6g}, but its path's steps add up to {acc:.6g} (a step "
            "into v "
            "costs length * cost[v], length 1 or sqrt(2))"
        )
    return acc


def _check_optimal(sub, cost, start, goal, name):
    what = f"astar on the {name} map from {start} to {goal}"
    path, total = _path(sub.astar(cost, start, goal), what)
    got = _check_valid(path, total, cost, start, goal, what)
    want = best_cost(cost, start, goal)
    if not got <= want + 1e-9 * want:
        fail(
            f"{what} found a path of cost {got:.4f}; the cheapest costs {want:.4f} (networkx's Dijkstra). "
            "A* returns an optimal path only if its heuristic never overestimates (admissible) and it stops "
            "when the goal is popped from the open list."
        )
    if not got >= want - 1e-9 * want:
        fail(f"{what} claims a path of cost {got:.4f}, cheaper than the cheapest possible, {want:.4f}")
    if not abs(total - want) <= 1e-9 * max(1.0, want):
        fail(f"{what} reports a total cost of {total:.6g}; the cheapest path costs {want:.6g}")


@suite.test("octile_heuristic: min_cost times the octile distance", points=1, target="octile_heuristic")
def heuristic_octile(sub):
    rng = np.random.default_rng(61)
    for _ in range(20):
        a, b = tuple(int(v) for v in rng.integers(0, 50, 2)), tuple(int(v) for v in rng.integers(0, 50, 2))
        m = float(rng.choice([1.0, 1.5]))
        di, dj = abs(a[0] - b[0]), abs(a[1] - b[1])
        want = m * (max(di, dj) + (math.sqrt(2) - 1) * min(di, dj))
        got = as_float(sub.octile_heuristic(a, b, m), "octile_heuristic(cell, goal, min_cost)")
        if not abs(got - want) <= 1e-9 * max(1, want):
            extra = ""
            if math.isclose(got, m * (di + dj), rel_tol=1e-9, abs_tol=1e-9) and min(di, dj) > 0:
                extra = (
                    " That is the Manhattan distance, which overestimates on an 8-connected grid (a "
                    "diagonal step"
                    " costs sqrt(2), not 2), so A* is no longer guaranteed to find the cheapest path."
                )
            fail(f"octile_heuristic({a}, {b}, {m}) is {got:.6g}, expected {want:.6g}.{extra}")


@suite.test(
    "octile_heuristic is admissible and consistent on maps with walls (never above the true cost to the "
    "goal) and exact on open floor (networkx's cheapest costs)",
    points=1,
    target="octile_heuristic",
)
def heuristic_admissible(sub):
    rng = np.random.default_rng(62)
    for make in (map_wall_gap, map_weighted):
        cost, _, goal = make()
        G = graph_of(cost)
        to_goal = nx.single_source_dijkstra_path_length(G.reverse(copy=False), goal)
        m = float(cost[np.isfinite(cost)].min())
        cells = list(to_goal)
        for k in rng.choice(len(cells), min(150, len(cells)), replace=False):
            n = cells[k]
            h = as_float(sub.octile_heuristic(n, goal, m), "octile_heuristic(cell, goal, min_cost)")
            if not h <= to_goal[n] + 1e-9:
                fail(
                    f"octile_heuristic({n}, {goal}, {m:g}) = {h:.4f} overestimates: the cheapest path from "
                    f"{n} to "
                    f"{goal} on the {make.__name__[4:]} map costs {to_goal[n]:.4f}. An overestimating "
                    "heuristic "
                    "makes A* return paths that are not the cheapest."
                )
            for v in list(G.successors(n))[:3]:
                hv = as_float(sub.octile_heuristic(v, goal, m), "octile_heuristic(cell, goal, min_cost)")
                if not h <= G[n][v]["weight"] + hv + 1e-9:
                    fail(
                        f"octile_heuristic is not consistent: h{n} = {h:.4f} > cost({n} -> {v}) + h{v} = "
                        f"{G[n][v]['weight'] + hv:.4f}"
                    )
    _heuristic_exact_on_open_floor(sub, rng)


def _heuristic_exact_on_open_floor(sub, rng):
    """Without obstacles, on cells that all cost m, the octile distance times m is the cheapest cost:
    a heuristic that is admissible but loose (0, Euclidean) is not the one asked for."""
    for m in (1.0, 1.5):
        cost = np.full((20, 16), m)
        goal = (13, 4)
        to_goal = nx.single_source_dijkstra_path_length(graph_of(cost).reverse(copy=False), goal)
        for k in rng.choice(cost.size, 40, replace=False):
            n = tuple(int(v) for v in np.unravel_index(k, cost.shape))
            h = as_float(sub.octile_heuristic(n, goal, m), "octile_heuristic(cell, goal, min_cost)")
            if not abs(h - to_goal[n]) <= 1e-9 * max(1.0, to_goal[n]):
                fail(
                    f"octile_heuristic({n}, {goal}, {m:g}) = {h:.4f}; on open floor whose cells all cost "
                    f"{m:g} the cheapest path costs {to_goal[n]:.4f} (networkx), and the octile distance "
                    "times min_cost equals it. A smaller heuristic is admissible but makes A* search more "
                    "cells."
                )


@suite.test(
    "astar returns a valid path: 8-connected, no obstacles, no corner cutting, its cost summed right",
    points=2,
    target="astar",
    uses=("octile_heuristic",),
    visibility="visible",
)
def astar_valid_path(sub):
    for make in (map_open, map_wall_gap, map_corner):
        cost, start, goal = make()
        what = f"astar on the {make.__name__[4:]} map"
        path, total = _path(sub.astar(cost, start, goal), what)
        _check_valid(path, total, cost, start, goal, what)


@suite.test(
    "astar finds the cheapest path (networkx's Dijkstra) on fixed and seeded maps",
    points=3,
    target="astar",
    uses=("octile_heuristic",),
    timeout_s=8,
)
def astar_optimal(sub):
    for make in (map_open, map_wall_gap, map_u_trap, map_weighted, map_corner):
        cost, start, goal = make()
        _check_optimal(sub, cost, start, goal, make.__name__[4:].replace("_", " "))
    for seed in (71, 72, 73):
        cost, pairs = map_random(seed)
        for start, goal in pairs:
            if math.isfinite(best_cost(cost, start, goal)):
                _check_optimal(sub, cost, start, goal, f"random (seed {seed})")
    return "5 fixed maps and 3 seeded 40 x 40 maps"


@suite.test(
    "astar without a path (an enclosed goal, a blocked start); with one round the box; and start == goal",
    points=1,
    target="astar",
    uses=("octile_heuristic",),
)
def astar_no_path(sub):
    cost = np.ones((15, 15))
    cost[8:13, 8] = cost[8:13, 12] = cost[8, 8:13] = cost[12, 8:13] = INF  # a closed box around (10, 10)
    for start, goal, why in (
        ((1, 1), (10, 10), "the goal is enclosed"),
        ((8, 8), (1, 1), "the start is an obstacle"),
    ):
        path, total = _path(sub.astar(cost, start, goal), f"astar from {start} to {goal} ({why})")
        if path is not None or total != INF:
            fail(
                f"astar from {start} to {goal}, where {why}, must return an empty path and inf; got a path "
                "of "
                f"{0 if path is None else len(path)} cells and total {total}"
            )
    path, total = _path(sub.astar(cost, (3, 4), (3, 4)), "astar from (3, 4) to itself")
    if path != [(3, 4)] or total != 0.0:
        fail(f"astar from a cell to itself must return [(3, 4)] and 0; got {path} and {total}")
    _check_optimal(sub, cost, (1, 1), (13, 10), "boxed-in")  # beside the box: there is a way round


@suite.test(
    "astar on a 120 x 120 seeded map: optimal within the time limit",
    points=1,
    target="astar",
    uses=("octile_heuristic",),
    timeout_s=10,
)
def astar_large_map(sub):
    cost, _ = map_random(74, shape=(120, 120), density=0.2)
    rng = np.random.default_rng(75)
    free = np.argwhere(np.isfinite(cost))
    far = free[np.argsort(free.sum(axis=1))]
    start, goal = tuple(int(v) for v in far[0]), tuple(int(v) for v in far[-1])
    if not math.isfinite(best_cost(cost, start, goal)):  # pragma: no cover - the seed is fixed
        start, goal = tuple(int(v) for v in free[rng.integers(len(free))]), tuple(int(v) for v in free[0])
    _check_optimal(sub, cost, start, goal, "120 x 120 random")
    return f"from {start} to {goal}"
