"""Where the two baselines of the search look next, without the colour search (see :mod:`lab.search.agent`).

:attr:`~lab.search.agent.Strategy.LAWNMOWER` visits a boustrophedon lattice of points covering the map
(:func:`lawnmower_targets`); :attr:`~lab.search.agent.Strategy.FRONTIER` goes to the nearest cell on the
border of the area its local searches have covered (:func:`frontier_cells`, nearest-frontier
exploration).
"""

from __future__ import annotations

import numpy as np

__all__ = ["frontier_cells", "lawnmower_targets"]


def lawnmower_targets(spec, spacing_m: float, start_xy) -> list[tuple[float, float]]:
    """A boustrophedon lattice over the map: rows along x, ``spacing_m`` apart, starting with the row
    and the end nearest ``start_xy`` [m]."""
    x0, x1, y0, y1 = spec.extent
    nx = max(1, int(round((x1 - x0) / spacing_m)))
    ny = max(1, int(round((y1 - y0) / spacing_m)))
    xs = x0 + (np.arange(nx) + 0.5) * (x1 - x0) / nx
    ys = y0 + (np.arange(ny) + 0.5) * (y1 - y0) / ny
    if abs(ys[-1] - start_xy[1]) < abs(ys[0] - start_xy[1]):
        ys = ys[::-1]
    first_reversed = abs(xs[-1] - start_xy[0]) < abs(xs[0] - start_xy[0])
    out = []
    for k, y in enumerate(ys):
        row = xs[::-1] if (k % 2 == 0) == first_reversed else xs
        out.extend((float(x), float(y)) for x in row)
    return out


def frontier_cells(searched: np.ndarray) -> np.ndarray:
    """Unsearched cells with a searched 8-neighbour, shape (k, 2) (all cells when nothing is searched)."""
    if not searched.any():
        return np.argwhere(~searched)
    p = np.pad(searched, 1)
    nx, ny = searched.shape
    near = np.zeros_like(searched)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            if di or dj:
                near |= p[1 + di : 1 + di + nx, 1 + dj : 1 + dj + ny]
    return np.argwhere(near & ~searched)
