"""One Bayes update of the probability map M_p on 100 x 100 cells, side by side with a loop over cells.

Run: .venv/bin/python benchmarks/bench_search.py [--repeats N] [--cells N]
Prints the median microseconds of one update for: the local search's negative detection (constant
alpha, beta), the global search's colour peak (growing beta over the whole grid), and the same Eqs.
(1)-(3) written as a Python loop over cells (the readable peer the tests compare against), and the ratio.
"""

import argparse
import statistics
import time

import numpy as np

from lab.navigation import GridSpec
from lab.search.probability_map import update, update_global


def loop_update(P, cell, y, alpha, beta):
    """Eqs. (1)-(3) cell by cell, as written in the paper."""
    nx, ny = P.shape

    def lik(i, j):
        if (i, j) == cell:
            return beta if y == 0 else 1.0 - beta
        return 1.0 - alpha if y == 0 else alpha

    evidence = 0.0
    for m in range(nx):
        for n in range(ny):
            evidence += lik(m, n) * P[m, n]
    out = np.empty_like(P)
    for i in range(nx):
        for j in range(ny):
            out[i, j] = lik(i, j) * P[i, j] / evidence
    return out


def median_us(fn, repeats):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e6 * statistics.median(times)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=200)
    ap.add_argument("--cells", type=int, default=100)
    args = ap.parse_args()
    n = args.cells
    spec = GridSpec((0.0, 0.0), 0.2, (n, n))
    rng = np.random.default_rng(0)
    P = rng.random((n, n))
    P /= P.sum()
    cell = (n // 2, n // 3)
    t_local = median_us(lambda: update(P, cell, 0, 0.05, 0.1), args.repeats)
    t_global = median_us(lambda: update_global(P, spec, cell, 0.9, 0.05, 0.2), args.repeats)
    t_loop = median_us(lambda: loop_update(P, cell, 0, 0.05, 0.1), max(3, args.repeats // 40))
    np.testing.assert_allclose(update(P, cell, 0, 0.05, 0.1), loop_update(P, cell, 0, 0.05, 0.1), rtol=1e-12)
    print(f"M_p update on {n} x {n} cells, median of {args.repeats} runs:")
    print(f"  local search miss (constant alpha, beta), vectorised: {t_local:9.1f} us")
    print(f"  global colour peak (growing beta),        vectorised: {t_global:9.1f} us")
    print(
        f"  local search miss, Python loop over cells:            {t_loop:9.1f} us ({t_loop / t_local:.0f}x)"
    )


if __name__ == "__main__":
    main()
