"""Where the search agent looks next (:class:`lab.search.agent.SearchAgent`): four target strategies.

:attr:`Strategy.PAPER` (:class:`MapPeakStrategy`): the probability map's peak, with a global colour
search whenever the map holds no peak worth visiting (``global_threshold / n_cells``), from a new vantage
point when the last scan stood near.

:attr:`Strategy.RATE` (:class:`MapPeakStrategy` too) is the paper's loop with one change: the next cell is
not the map's maximum but, among the map's peaks worth a visit (local maxima above ``global_threshold /
n_cells``), the one that buys the most probability per second of driving there and looking
(:func:`detection_rates`; the saccadic-search idea of Chung and Burdick): a nearby peak of half the
height can come before a far one.

Two baselines use the same navigation and local search but choose where to look without the colour
search: :attr:`Strategy.LAWNMOWER` (:class:`LawnmowerStrategy`) visits a boustrophedon lattice of points
covering the map (:func:`lawnmower_targets`), and :attr:`Strategy.FRONTIER` (:class:`FrontierStrategy`)
goes to the nearest cell on the border of the area its local searches have covered (:func:`frontier_cells`,
nearest-frontier exploration). Both still update ``M_p`` after each failed local search.

A strategy's ``next_target(state, pose)`` reads the run through :class:`SearchState` (the agent) and
returns a :class:`Target` or None (nothing left to search); :func:`make_strategy` picks it from the
config.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum
from typing import TYPE_CHECKING, Protocol

import numpy as np
from scipy.ndimage import maximum_filter

from lab.errors import ConfigError
from lab.geometry import Pose2D

if TYPE_CHECKING:
    from lab.robot import Robot
    from lab.search.config import SearchAgentConfig
    from lab.search.probability_map import ProbabilityMap

__all__ = [
    "FrontierStrategy",
    "LawnmowerStrategy",
    "MapPeakStrategy",
    "SearchState",
    "Strategy",
    "Target",
    "TargetStrategy",
    "detection_rates",
    "frontier_cells",
    "lawnmower_targets",
    "make_strategy",
]


class Strategy(Enum):
    """How the agent picks the next place to look."""

    PAPER = "paper"  # the probability map's peak, global colour search when the map is flat
    RATE = "rate"  # the map's peak that gives the most detection probability per second of travel and look
    LAWNMOWER = "lawnmower"  # boustrophedon coverage of the map
    FRONTIER = "frontier"  # nearest border of the area already searched

    @classmethod
    def parse(cls, value) -> Strategy:
        if isinstance(value, Strategy):
            return value
        try:
            return cls(str(value))
        except ValueError:
            raise ConfigError(
                f"unknown strategy {value!r}; strategies: {', '.join(s.value for s in cls)}"
            ) from None


@dataclass(frozen=True)
class Target:
    """Where to go next: a cell to search, or (``vantage``) a place to scan from."""

    cell: tuple[int, int]
    xy: tuple[float, float]
    vantage: bool = False


def detection_rates(
    P: np.ndarray,
    centres: np.ndarray,
    robot_xy: tuple[float, float],
    standoff_m: float,
    speed_m_s: float,
    look_time_s: float,
) -> np.ndarray:
    """Probability of finding the object per second spent, for searching each of some cells next.

    With fixed costs, searching cells in decreasing order of ``P_i / t_i`` minimises the expected time
    to find the object (the classic result of optimal search; the local search's detection probability
    ``1 - beta`` is the same for every cell, so it drops out of the order). Here the cost of cell ``i``
    is the drive to its local-search band plus the look (``c_i`` its centre, ``r`` the robot)::

        t_i = max(0, |c_i - r| - standoff_m) / speed_m_s + look_time_s

    Parameters
    ----------
    P : ndarray, shape (k,)
        The cells' probabilities.
    centres : ndarray, shape (k, 2) [m]
        Their centres.
    robot_xy : (x, y) [m]
        Where the robot stands.
    standoff_m : float [m]
        How far from a cell the local search stands (the middle of its band).
    speed_m_s : float [m/s]; look_time_s : float [s]
        The speed a drive makes good, and a local search's duration.

    Returns
    -------
    ndarray, shape (k,) [1/s]
        ``P_i / t_i``.
    """
    P = np.asarray(P, float)
    c = np.asarray(centres, float).reshape(-1, 2)
    if P.shape != (len(c),):
        raise ValueError(f"P has shape {P.shape} but there are {len(c)} centres")
    d = np.hypot(c[:, 0] - robot_xy[0], c[:, 1] - robot_xy[1])
    t = np.maximum(0.0, d - standoff_m) / speed_m_s + look_time_s
    return P / t


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


class SearchState(Protocol):
    """What a strategy reads of the run (the agent provides it)."""

    robot: Robot
    pmap: ProbabilityMap
    global_searches: int  # global searches so far
    local_since_global: int  # local searches since the last global search
    scan_points: list[tuple[float, float]]  # where the global searches stood [m]
    vantage_failed: np.ndarray  # (nx, ny) bool: cells near a vantage point the robot did not reach
    searched: np.ndarray  # (nx, ny) bool: cells the local searches covered (the frontier baseline's)

    @property
    def excluded(self) -> np.ndarray:
        """(nx, ny) bool: cells not to search now."""

    @property
    def excluded_for_good(self) -> np.ndarray:
        """(nx, ny) bool: cells not to search for the rest of the run."""

    def global_search(self) -> None:
        """Run a global search from where the robot stands and update the map."""


class TargetStrategy(Protocol):
    def next_target(self, state: SearchState, pose: Pose2D) -> Target | None: ...


class MapPeakStrategy:
    """:attr:`Strategy.PAPER` and :attr:`Strategy.RATE`: the probability map's peaks (module docstring)."""

    def __init__(self, config: SearchAgentConfig):
        self.config = config
        self.relocating: Target | None = None  # the vantage point driven to; the scan comes next turn
        self.vantage_drives = 0  # vantage points tried in a row for the coming scan

    def next_target(self, state: SearchState, pose: Pose2D) -> Target | None:
        """The map's peak (rate: the best peak per second, :meth:`rate_cell`), after a global search
        when the map is flat; first a drive to a new vantage point when the robot stands near an
        earlier scan point, and another one when that one was not reached (up to ``max_nav_failures``
        drives)."""
        spec = state.pmap.spec
        threshold = self.config.global_threshold / spec.n_cells
        selectable = ~state.excluded
        flat = not selectable.any() or float(state.pmap.P[selectable].max()) < threshold
        if state.global_searches == 0 or (flat and state.local_since_global > 0):
            last = self.relocating
            missed = last is not None and bool(state.vantage_failed[last.cell])
            may_drive = last is None or (missed and self.vantage_drives < self.config.max_nav_failures)
            if may_drive and self.near_scan_point(state, pose):
                vantage = self.new_vantage_point(state)
                if vantage is not None:
                    self.relocating = vantage  # drive there first; the scan comes on the next turn
                    self.vantage_drives += 1
                    return vantage
            self.relocating, self.vantage_drives = None, 0
            state.global_search()
        cell = None
        if self.config.strategy is Strategy.RATE:
            cell = self.rate_cell(state, state.robot.odometry())
        if cell is None:
            cell = state.pmap.peak(exclude=state.excluded, near_xy=(pose.x, pose.y))
        if cell is None:
            return None
        return Target(cell, state.pmap.centre(cell))

    def rate_cell(self, state: SearchState, pose: Pose2D) -> tuple[int, int] | None:
        """The rate strategy's next cell: among the map's peaks worth a visit (local maxima within the
        local search's ``detection.neighbour_radius_m``, not excluded, at least ``global_threshold /
        n_cells``), the one with the most probability per second it costs (:func:`detection_rates`);
        None when there is no such peak (the caller takes the map's maximum)."""
        lc = self.config.local_search
        spec = state.pmap.spec
        P = np.where(state.excluded, -1.0, state.pmap.P)
        r_cells = max(1, int(round(lc.detection.neighbour_radius_m / spec.resolution)))
        peak = P >= maximum_filter(P, size=2 * r_cells + 1, mode="constant", cval=-1.0)
        peak &= P >= self.config.global_threshold / spec.n_cells
        cells = np.argwhere(peak)
        if len(cells) == 0:
            return None
        standoff = 0.5 * (lc.min_distance_m + lc.max_distance_m)
        rate = detection_rates(
            P[peak],
            spec.centers_of(cells),
            (pose.x, pose.y),
            standoff,
            self.config.travel_speed_m_s,
            self.config.look_time_s,
        )
        k = int(np.argmax(rate))
        return int(cells[k, 0]), int(cells[k, 1])

    def near_scan_point(self, state: SearchState, pose: Pose2D) -> bool:
        """Whether an earlier global search stood within ``rescan_distance_m`` of ``pose``."""
        d = self.config.rescan_distance_m
        return any(math.hypot(pose.x - x, pose.y - y) < d for x, y in state.scan_points)

    def new_vantage_point(self, state: SearchState) -> Target | None:
        """The cell farthest from every earlier scan point, at least ``vantage_margin_m`` inside the map
        and not near a vantage point the robot failed to reach (ties: nearest the robot); None when
        there is none left."""
        spec = state.pmap.spec
        X, Y = spec.cell_centers()
        x0, x1, y0, y1 = spec.extent
        m = self.config.vantage_margin_m
        ok = (X >= x0 + m) & (X <= x1 - m) & (Y >= y0 + m) & (Y <= y1 - m)
        ok &= ~state.excluded & ~state.vantage_failed
        if not ok.any():
            return None
        d = np.min([np.hypot(X - x, Y - y) for x, y in state.scan_points], axis=0)
        score = np.where(ok, d, -1.0)
        i, j = np.unravel_index(int(np.argmax(score)), score.shape)
        return Target((int(i), int(j)), state.pmap.centre((int(i), int(j))), vantage=True)


class LawnmowerStrategy:
    """:attr:`Strategy.LAWNMOWER`: a boustrophedon lattice over the map (:func:`lawnmower_targets`)."""

    def __init__(self, config: SearchAgentConfig):
        self.config = config
        self.targets: list[tuple[float, float]] | None = None  # the lattice points still to visit [m]

    def next_target(self, state: SearchState, pose: Pose2D) -> Target | None:
        """The next lattice point whose cell is not excluded for good (a new lattice, starting near
        ``pose``, once the last is used up)."""
        if not self.targets:
            self.targets = lawnmower_targets(
                state.pmap.spec, self.config.lawnmower_spacing_m, (pose.x, pose.y)
            )
        for _ in range(len(self.targets)):
            xy = self.targets.pop(0)
            cell = state.pmap.cell_of(*xy)
            if not state.excluded_for_good[cell]:
                return Target(cell, state.pmap.centre(cell))
        return None


class FrontierStrategy:
    """:attr:`Strategy.FRONTIER`: the nearest border of the area already searched (:func:`frontier_cells`)."""

    def __init__(self, config: SearchAgentConfig):
        self.config = config

    def next_target(self, state: SearchState, pose: Pose2D) -> Target | None:
        """The nearest frontier cell not excluded and not right under the robot; a second sweep once
        everything has been searched."""
        cand = frontier_cells(state.searched)
        cand = cand[~state.excluded[cand[:, 0], cand[:, 1]]] if len(cand) else cand
        if len(cand) == 0:
            if state.searched.all():
                state.searched[:] = False  # everything seen once: start a second sweep
                return self.next_target(state, pose)
            return None
        c = state.pmap.spec.centers_of(cand)
        d = np.hypot(c[:, 0] - pose.x, c[:, 1] - pose.y)
        # the nearest frontier cell that is not right under the robot (it must stand back to look)
        d = np.where(d < self.config.local_search.min_distance_m, d + 1e3, d)
        k = int(np.argmin(d))
        cell = (int(cand[k, 0]), int(cand[k, 1]))
        return Target(cell, state.pmap.centre(cell))


def make_strategy(config: SearchAgentConfig) -> TargetStrategy:
    """The target strategy of ``config.strategy``."""
    s = config.strategy
    if s is Strategy.PAPER or s is Strategy.RATE:
        return MapPeakStrategy(config)
    if s is Strategy.LAWNMOWER:
        return LawnmowerStrategy(config)
    return FrontierStrategy(config)
