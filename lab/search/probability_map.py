r"""The probability map M_p of the search paper (Sec. III-A): where the object is, cell by cell.

A grid over the floor (a :class:`~lab.navigation.GridSpec`, 20 cm cells by default, cell ``(i, j)``
along W's x and y as in ``docs/conventions.md``) holds ``P[i, j] = P(h_ij = 1 | Y_1:k)``, the belief
that the object stands in cell ``c_ij``. The object is somewhere on the map, so ``P`` sums to 1.

A measurement ``y_uv`` in {0, 1} is a negative or positive detection of the object *in cell (u, v)*.
Bayes' rule, the paper's Eq. (1), with the stationary-object prior ``P(h_ij^k | Y_1:k-1) = P^{k-1}_ij``:

.. math::

    P(h_{ij} = 1 \mid Y_{1:k}) = \frac{P(y_{uv} \mid h_{ij} = 1)\; P(h_{ij} = 1 \mid Y_{1:k-1})}
                                      {P(y_{uv} \mid Y_{1:k-1})}                                  \quad (1)

    P(y_{uv} \mid Y_{1:k-1}) = \sum_{m,n} P(y_{uv} \mid h_{mn} = 1)\; P(h_{mn} = 1 \mid Y_{1:k-1})   \quad (3)

The detection model, Eq. (2), with false-alarm probability ``alpha`` and missed-detection probability
``beta``:

.. math::

    P(y_{uv} = 0 \mid h_{ij} = 1) = \beta,     \quad P(y_{uv} = 1 \mid h_{ij} = 1) = 1 - \beta
        \qquad (u, v) = (i, j)

    P(y_{uv} = 0 \mid h_{ij} = 1) = 1 - \alpha, \quad P(y_{uv} = 1 \mid h_{ij} = 1) = \alpha
        \qquad (u, v) \ne (i, j)                                                          \quad (2)

**The beta field.** Both cases of Eq. (2) are one expression if we write, for every cell,
``B[i, j] = P(y_uv = 0 | h_ij = 1)``: ``B = beta`` on the measured cell and ``B = 1 - alpha``
elsewhere. Then ``P(y = 0 | h_ij = 1) = B[i, j]`` and ``P(y = 1 | h_ij = 1) = 1 - B[i, j]``
(:func:`detection_likelihood`). The local search uses this constant-beta field
(:func:`constant_beta_field`).

**The global search's variable beta** (Sec. III-B and Fig. 2, bottom right): a colour peak of
strength ``P'_n`` is a positive detection of the cell ``c_uv`` it projects into, with
``P(y_uv = 1 | h_uv = 1) = P'_n``, i.e. ``beta_0 = 1 - P'_n``, and beta "increased exponentially for
neighbouring cells". Our growth law (:func:`growing_beta_field`), with ``d`` the distance [m] between
the centres of ``c_ij`` and ``c_uv`` and ``lambda`` the growth length [m]:

.. math::

    \beta(d) = \min\left(1 - \alpha,\; \beta_0\, e^{d / \lambda}\right)

so ``P(y = 1 | h_ij = 1) = 1 - beta(d)`` falls from ``P'_n`` at the measured cell to the false-alarm
rate ``alpha`` at ``d = lambda ln((1 - alpha) / beta_0)`` and stays there: beyond that radius the field
*is* Eq. (2)'s "other cell" case, and inside it the detection spreads over the neighbourhood (a
strong peak, small ``beta_0``, spreads farther than a weak one). With the global search's defaults
(``alpha = 0.05``, ``lambda = 0.2`` m, ``P'_n <= 0.9``) the strongest peak reaches
``0.2 ln(0.95 / 0.1) = 0.45`` m, two cells out; a peak of ``P'_n = 0.3`` only its own cell. Stereo
range error of the coarse search (10-40 cm at 3-5 m) is what the spread absorbs.

Everything is vectorised over the whole grid (one ``(nx, ny)`` array per operation); the tests check
it against a loop over cells written straight from Eqs. (1)-(3).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from lab.errors import ConfigError
from lab.navigation.grid import GridSpec

__all__ = [
    "ColourPeakDetection",
    "DetectionModel",
    "LocalSearchDetection",
    "ProbabilityMap",
    "bayes_update",
    "cells_within",
    "constant_beta_field",
    "detection_likelihood",
    "growing_beta_field",
    "map_peaks",
    "observe",
    "region_prior",
    "uniform_prior",
    "update",
    "update_global",
]


@dataclass(frozen=True)
class DetectionModel:
    """Error probabilities of a detector, Eq. (2), and how far one detection reaches.

    The local search's detector has a constant ``beta`` and answers for a neighbourhood of
    ``neighbour_radius_m``; the global search's colour peaks have a variable beta that grows with the
    distance from the measured cell every ``growth_m`` metres (:func:`growing_beta_field`), floored at
    ``beta``.

    Attributes
    ----------
    alpha : float
        False alarm: ``P(y_uv = 1 | object in another cell)``.
    beta : float
        Missed detection: ``P(y_uv = 0 | object in c_uv)``. With ``growth_m`` (a colour peak of
        strength ``P'_n``): the smallest missed-detection probability at the peak's cell, ``beta_0 =
        max(beta, 1 - P'_n)`` (a peak never claims certainty).
    neighbour_radius_m : float [m]
        A detection is one of the measured cell *and* of every cell whose centre lies within this
        distance of the measured cell's (one Bayes update per cell, the measured cell first); 0: the
        measured cell alone.
    growth_m : float or None [m]
        The growth length ``lambda`` of the variable beta; None: the constant beta of Eq. (2).
    """

    alpha: float
    beta: float
    neighbour_radius_m: float = 0.0
    growth_m: float | None = None

    def __post_init__(self):
        _check_alpha_beta(self.alpha, self.beta)
        if not self.neighbour_radius_m >= 0:
            raise ConfigError(f"neighbour_radius_m must be >= 0 m, got {self.neighbour_radius_m!r}")
        if self.growth_m is not None and not (math.isfinite(self.growth_m) and self.growth_m > 0):
            raise ConfigError(f"growth_m must be a finite number > 0 m or None, got {self.growth_m!r}")


@dataclass(frozen=True)
class ColourPeakDetection:
    """A global search's colour peak of strength ``P'_n`` projected into ``cell``: a positive detection
    (``y = 1``) with the growing beta of ``model`` (:func:`update_global`)."""

    cell: tuple[int, int]
    strength: float
    model: DetectionModel


@dataclass(frozen=True)
class LocalSearchDetection:
    """A local search facing ``cell``: ``y = 0`` searched and not found, ``y = 1`` found; with the
    constant ``alpha``, ``beta`` of ``model``, for ``cell`` and its neighbours within
    ``model.neighbour_radius_m`` (:meth:`cells`)."""

    cell: tuple[int, int]
    y: int
    model: DetectionModel

    def cells(self, spec: GridSpec) -> list[tuple[int, int]]:
        """The cells this detection measures (:func:`cells_within`)."""
        return cells_within(spec, self.cell, self.model.neighbour_radius_m)


def _check_alpha_beta(alpha: float, beta: float) -> None:
    if not (0.0 < alpha < 1.0 and 0.0 < beta < 1.0):
        raise ConfigError(f"alpha and beta must be within (0, 1), got alpha={alpha}, beta={beta}")
    if not alpha + beta < 1.0:
        # a detector with alpha + beta >= 1 says "yes" at least as often for an empty cell as for the
        # object's: a positive detection would lower the measured cell's probability
        raise ConfigError(f"alpha + beta must be < 1 (an informative detector), got {alpha} + {beta}")


def _check_cell(shape, cell) -> tuple[int, int]:
    i, j = (int(c) for c in cell)
    if not (0 <= i < shape[0] and 0 <= j < shape[1]):
        raise ConfigError(f"cell ({i}, {j}) is outside the map of {shape[0]} x {shape[1]} cells")
    return i, j


# --- priors P_0 (Sec. IV) ---------------------------------------------------------------------------


def uniform_prior(spec: GridSpec) -> np.ndarray:
    """``P_0 = 1 / (nx ny)`` in every cell, shape ``spec.shape`` (the paper's choice for one room)."""
    return np.full(spec.shape, 1.0 / spec.n_cells)


def region_prior(
    spec: GridSpec,
    regions: Sequence[tuple[tuple[float, float, float, float], float]],
    background: float = 1.0,
) -> np.ndarray:
    """A prior weighted by region (Sec. IV): more mass where the object is more likely to be.

    Parameters
    ----------
    spec : GridSpec
    regions : sequence of ``((x_min, y_min, x_max, y_max), weight)``
        World rectangles [m] and their relative weight (>= 0); a cell whose centre lies in several
        takes the largest.
    background : float
        Relative weight of the cells in no region (>= 0).

    Returns
    -------
    ndarray, shape spec.shape
        Normalised to sum to 1.
    """
    if background < 0:
        raise ConfigError(f"background weight must be >= 0, got {background}")
    X, Y = spec.cell_centers()
    w_region = np.full(spec.shape, -np.inf)
    for (x0, y0, x1, y1), weight in regions:
        if weight < 0:
            raise ConfigError(f"region weights must be >= 0, got {weight}")
        inside = (X >= x0) & (X < x1) & (Y >= y0) & (Y < y1)
        w_region[inside] = np.maximum(w_region[inside], weight)
    w = np.where(np.isfinite(w_region), w_region, float(background))
    total = w.sum()
    if not total > 0:
        raise ConfigError("the prior has no mass: every weight is 0")
    return w / total


# --- Eq. (2): the detection model as a beta field -------------------------------------------------


def constant_beta_field(shape: tuple[int, int], cell, alpha: float, beta: float) -> np.ndarray:
    """``B[i, j] = P(y_uv = 0 | h_ij = 1)`` of Eq. (2) with constant ``alpha``, ``beta``.

    ``beta`` on the measured cell ``(u, v) = cell``, ``1 - alpha`` on every other cell.
    """
    _check_alpha_beta(alpha, beta)
    u, v = _check_cell(shape, cell)
    B = np.full(shape, 1.0 - alpha)  # (u, v) != (i, j): P(y = 0 | h_ij = 1) = 1 - alpha
    B[u, v] = beta  # (u, v) == (i, j): P(y = 0 | h_uv = 1) = beta
    return B


def growing_beta_field(spec: GridSpec, cell, alpha: float, beta0: float, growth_m: float) -> np.ndarray:
    r"""The global search's variable beta: ``beta0`` on the measured cell, growing exponentially with
    the distance ``d`` [m] from it, capped at ``1 - alpha``:

    .. math:: B_{ij} = \min\left(1 - \alpha,\; \beta_0\, e^{d_{ij} / \lambda}\right)

    Parameters
    ----------
    spec : GridSpec
    cell : (u, v)
        The measured cell.
    alpha : float
        False-alarm probability (sets the cap).
    beta0 : float
        Missed-detection probability at the measured cell (``1 - P'_n``), within ``(0, 1 - alpha)``.
    growth_m : float [m]
        The growth length ``lambda``: beta is multiplied by ``e`` every ``lambda`` metres.

    Returns
    -------
    ndarray, shape spec.shape
    """
    _check_alpha_beta(alpha, beta0)
    if not (math.isfinite(growth_m) and growth_m > 0):
        raise ConfigError(f"growth_m must be a finite number > 0 m, got {growth_m!r}")
    u, v = _check_cell(spec.shape, cell)
    X, Y = spec.cell_centers()
    xu, yv = spec.cell_to_world(u, v)
    d = np.hypot(X - xu, Y - yv)  # distance of every cell centre from the measured cell's [m]
    cap = math.log((1.0 - alpha) / beta0)  # beta reaches 1 - alpha at d = lambda * cap
    return np.minimum(1.0 - alpha, beta0 * np.exp(np.minimum(d / growth_m, cap)))


def detection_likelihood(y: int, B: np.ndarray) -> np.ndarray:
    """Eq. (2) for every cell: ``P(y_uv = y | h_ij = 1)`` from the beta field ``B``.

    ``P(y = 0 | h_ij = 1) = B[i, j]`` and ``P(y = 1 | h_ij = 1) = 1 - B[i, j]``.
    """
    if y not in (0, 1):
        raise ConfigError(f"a detection y must be 0 or 1, got {y!r}")
    return B if y == 0 else 1.0 - B


# --- Eqs. (1) and (3): the Bayes update -----------------------------------------------------------


def bayes_update(P: np.ndarray, L: np.ndarray) -> np.ndarray:
    """Eq. (1) for every cell at once, with the denominator Eq. (3).

    Parameters
    ----------
    P : ndarray, shape (nx, ny)
        ``P(h_ij = 1 | Y_1:k-1)``, the map before the measurement (sums to 1).
    L : ndarray, shape (nx, ny)
        ``P(y_uv | h_ij = 1)``, the detection likelihood of the measurement (:func:`detection_likelihood`).

    Returns
    -------
    ndarray, shape (nx, ny)
        ``P(h_ij = 1 | Y_1:k)`` (a new array; sums to 1).
    """
    joint = L * P  # numerator of Eq. (1): P(y_uv | h_ij = 1) P(h_ij = 1 | Y_1:k-1)
    evidence = joint.sum()  # Eq. (3): P(y_uv | Y_1:k-1) = sum_mn P(y_uv | h_mn = 1) P(h_mn = 1 | Y_1:k-1)
    if not evidence > 0:
        raise ConfigError("the measurement has zero probability under the map (check alpha, beta and P)")
    return joint / evidence  # Eq. (1)


def update(P: np.ndarray, cell, y: int, alpha: float, beta: float) -> np.ndarray:
    """One detection ``y`` of cell ``(u, v)`` with constant ``alpha``, ``beta``: Eqs. (1)-(3).

    The local search's update: ``y = 0`` (searched, not found) moves mass from ``c_uv`` to every
    other cell in proportion to what they hold.
    """
    return bayes_update(P, detection_likelihood(y, constant_beta_field(P.shape, cell, alpha, beta)))


def update_global(
    P: np.ndarray,
    spec: GridSpec,
    cell,
    P_n: float,
    alpha: float,
    growth_m: float,
    beta_min: float = 0.1,
) -> np.ndarray:
    """A colour peak of strength ``P'_n`` projected into ``cell``: a positive detection (``y = 1``)
    with ``beta_0 = 1 - P'_n`` growing over the neighbourhood (:func:`growing_beta_field`).

    ``beta_0`` is clipped to ``[beta_min, 1 - alpha)``: a peak never claims certainty, and one no
    stronger than a false alarm changes nothing (it is skipped).
    """
    if P.shape != spec.shape:
        raise ConfigError(f"map shape {P.shape} does not match the GridSpec {spec.shape}")
    beta0 = max(float(beta_min), 1.0 - float(P_n))
    if beta0 >= 1.0 - alpha:  # P'_n <= alpha: the "detection" is as likely as a false alarm
        return P.copy()
    B = growing_beta_field(spec, cell, alpha, beta0, growth_m)
    return bayes_update(P, detection_likelihood(1, B))


def cells_within(spec: GridSpec, cell, radius_m: float) -> list[tuple[int, int]]:
    """The cell first, then the cells whose centres lie within ``radius_m`` [m] of its centre (C order)."""
    X, Y = spec.cell_centers()
    cx, cy = spec.cell_to_world(*cell)
    near = np.argwhere(np.hypot(X - cx, Y - cy) <= radius_m + 1e-9)
    return [tuple(cell)] + [(int(i), int(j)) for i, j in near if (i, j) != tuple(cell)]


def observe(P: np.ndarray, spec: GridSpec, detection) -> np.ndarray:
    """The map ``P`` after one detection (a new array); see :meth:`ProbabilityMap.observe`."""
    m = detection.model
    if isinstance(detection, ColourPeakDetection):
        return update_global(P, spec, detection.cell, detection.strength, m.alpha, m.growth_m, m.beta)
    if isinstance(detection, LocalSearchDetection):
        for c in detection.cells(spec):
            P = update(P, c, detection.y, m.alpha, m.beta)
        return P
    raise ConfigError(f"not a detection the map knows: {type(detection).__name__}")


def map_peaks(P: np.ndarray, n: int | None = None) -> list[tuple[int, int]]:
    """Local maxima of the map (cells at least as probable as their 8 neighbours and above the
    smallest value), most probable first: the places a search would visit, in order.

    A plateau of equal neighbouring maxima counts once (its first cell in C order). ``n`` limits the list.
    """
    nx, ny = P.shape
    padded = np.pad(P, 1, constant_values=-np.inf)
    shifted = [padded[1 + di : 1 + di + nx, 1 + dj : 1 + dj + ny] for di in (-1, 0, 1) for dj in (-1, 0, 1)]
    is_peak = (P >= np.max(shifted, axis=0)) & (P > P.min())
    cells = np.argwhere(is_peak)
    cells = cells[np.argsort(-P[is_peak], kind="stable")]
    out: list[tuple[int, int]] = []
    for i, j in cells:
        if any(max(abs(i - a), abs(j - b)) <= 1 and P[a, b] == P[i, j] for a, b in out):
            continue  # the same plateau as a peak already listed
        out.append((int(i), int(j)))
        if n is not None and len(out) >= n:
            break
    return out


# --- the map -------------------------------------------------------------------------------------


class ProbabilityMap:
    """The search paper's ``M_p``: a :class:`GridSpec` and the cell probabilities ``P`` over it.

    Parameters
    ----------
    spec : GridSpec
        Map extent and resolution (the paper: 20 cm cells).
    prior : ndarray, shape spec.shape, optional
        ``P_0``; uniform if omitted (normalised here).
    """

    def __init__(self, spec: GridSpec, prior: np.ndarray | None = None):
        self.spec = spec
        P = uniform_prior(spec) if prior is None else np.array(prior, dtype=float)
        if P.shape != spec.shape:
            raise ConfigError(f"prior shape {P.shape} does not match the GridSpec {spec.shape}")
        if not (np.all(np.isfinite(P)) and np.all(P >= 0) and P.sum() > 0):
            raise ConfigError("a prior must be finite, non-negative and have some mass")
        self.P = P / P.sum()

    @classmethod
    def over(cls, x_min: float, y_min: float, x_max: float, y_max: float, resolution: float = 0.2):
        """A uniform map over a floor rectangle [m]."""
        return cls(GridSpec.from_bounds(x_min, y_min, x_max, y_max, resolution))

    # -- reading ---------------------------------------------------------------------------------
    @property
    def max(self) -> float:
        return float(self.P.max())

    def peak(self, exclude: np.ndarray | None = None, near_xy=None) -> tuple[int, int] | None:
        """The cell of highest probability (ties: the one nearest ``near_xy``, then the lowest index).

        ``exclude`` (bool, spec.shape) removes cells from the choice; None when every cell is excluded.
        """
        P = self.P if exclude is None else np.where(exclude, -1.0, self.P)
        m = float(P.max())
        if m < 0:
            return None
        ties = np.argwhere(P >= m * (1.0 - 1e-9))
        if len(ties) > 1 and near_xy is not None:
            c = self.spec.centers_of(ties)
            k = int(np.argmin(np.hypot(c[:, 0] - near_xy[0], c[:, 1] - near_xy[1])))
        else:
            k = 0
        return int(ties[k, 0]), int(ties[k, 1])

    def cell_of(self, x: float, y: float) -> tuple[int, int]:
        return self.spec.world_to_cell(x, y)

    def centre(self, cell) -> tuple[float, float]:
        return self.spec.cell_to_world(*cell)

    def copy(self) -> ProbabilityMap:
        return ProbabilityMap(self.spec, self.P.copy())

    # -- writing ---------------------------------------------------------------------------------
    def observe(self, detection: ColourPeakDetection | LocalSearchDetection) -> None:
        r"""Update the map with one detection of either search: Eq. (1) with the denominator Eq. (3),

        .. math::

            P(h_{ij} = 1 \mid Y_{1:k}) = \frac{P(y_{uv} \mid h_{ij} = 1)\; P(h_{ij} = 1 \mid Y_{1:k-1})}
                {\sum_{m,n} P(y_{uv} \mid h_{mn} = 1)\; P(h_{mn} = 1 \mid Y_{1:k-1})}

        and the detection model of Eq. (2), ``P(y_uv = 0 | h_ij = 1) = B_ij``,
        ``P(y_uv = 1 | h_ij = 1) = 1 - B_ij``, with the beta field ``B`` of the detection's
        :class:`DetectionModel`:

        * a :class:`LocalSearchDetection` ``y`` of cell ``(u, v)``: ``B_uv = beta`` and ``B_ij = 1 -
          alpha`` on every other cell (:func:`constant_beta_field`); one such update for the cell and
          then for each of its neighbours within ``neighbour_radius_m`` (:meth:`LocalSearchDetection.cells`);
        * a :class:`ColourPeakDetection` of strength ``P'_n`` in cell ``(u, v)``: ``y = 1`` with
          ``B_ij = min(1 - alpha, beta_0 e^{d_ij / lambda})``, ``beta_0 = max(beta, 1 - P'_n)`` and
          ``lambda = growth_m`` (:func:`update_global`; a peak no stronger than a false alarm changes
          nothing).
        """
        self.P = observe(self.P, self.spec, detection)
