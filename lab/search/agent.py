"""The closed search loop (the search paper's Fig. 4): global search, navigate to a peak, local search,
update the map, repeat; with navigation injected and a time budget that always ends the run.

The paper's strategy (:attr:`Strategy.PAPER`)::

    loop until found or out of time:
        if the map's maximum (over cells not excluded) < global_threshold / n_cells
           (always at the start; afterwards only once a local search ran since the last global one):
            if an earlier scan stood within rescan_distance_m: drive to a new vantage point first
            global search from where the robot stands                  (global_search.py)
        cell = the most probable cell (ties: the one nearest the robot)
        navigate(cell centre, local-search range)                     (injected: costmap + A*)
                                 (a cell a search answered for before: from another side,
                                  revisit_turns_deg round from where the robot stood for that
                                  search, one way or, when that side is out of reach, the other)
        if it did not arrive: exclude the cell (until the next global search; for good after
                              max_nav_failures failures) and go on -- no observation, no Bayes update
        local search facing the cell                                   (local_search.py)
        found -> done
        a miss that saw the object's colours near the cell (its second look aimed at them):
                 step side_look_deg round the strongest colour peak, one way and then the other,
                 and look at the peaks again from there (the side look); found -> done
                 (or a whole second local search from another side: second_side, off by default)
        otherwise Eqs. (1)-(3) with y = 0 and the local search's constant alpha, beta
                 for the cell (and its neighbours within neighbour_radius_m, see LocalSearchConfig),
                 and a map snapshot (the paper's Fig. 6); a cell max_local_misses such searches
                 answered for is excluded for good (a distractor's colour peak comes back at every scan)

The rate strategy (:attr:`Strategy.RATE`) is the paper's loop with one change: the next cell is not
the map's maximum but, among the map's peaks worth a visit (local maxima above ``global_threshold /
n_cells``), the one that buys the most probability per second of driving there and looking
(:func:`detection_rates`; the saccadic-search idea of Chung and Burdick): a nearby peak of half the
height can come before a far one.

Two baselines use the same navigation and local search but choose where to look without the colour
search: :attr:`Strategy.LAWNMOWER` visits a boustrophedon lattice of points covering the map, and
:attr:`Strategy.FRONTIER` goes to the nearest cell on the border of the area its local searches have
covered (nearest-frontier exploration). Both still update ``M_p`` after each failed local search.

**Navigation** is any callable ``navigate(target_xy, min_distance, max_distance)`` that drives the
robot to a pose whose distance to ``target_xy`` [m] is within the band, facing it, and returns an
object with ``arrived`` (bool), ``reason`` (str) and ``pose`` (:class:`~lab.geometry.Pose2D`), like
:class:`NavigationResult` (an optional ``path_xy`` is kept for the figures). It must bound its own run
time. (Not :class:`lab.navigation.NavOutcome`, the navigator's enum of how a request ended.)

**The budget.** :class:`~lab.search.budget.BudgetedRobot` wraps the robot: once its clock passes the
deadline, the next ``step`` raises :class:`~lab.search.budget.SearchBudgetExceeded` -- inside the
navigator, a pan-tilt wait or a drive -- and the agent ends the run there ("time budget").

**A run that ends without the object** says why in its reason: how it ended ("time budget of 300 s used
up"), then what its local searches saw at best (database matches, a RANSAC start's inliers or a track
that was not confirmed, against what a pose needs), and, for an object whose database is too thin
for a pose from one view (the glossy cup, the paper's penguin cup), that this is the cause.

The baselines' target choice (:func:`~lab.search.baselines.lawnmower_targets`,
:func:`~lab.search.baselines.frontier_cells`) is in :mod:`lab.search.baselines`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum
from typing import Protocol

import numpy as np
from scipy.ndimage import maximum_filter

from lab.errors import (
    CommandRejected,
    ConfigError,
    ConnectionLost,
    DeviceTimeout,
    EStopActive,
    LabError,
    NotEnabled,
    ProtocolError,
    SafetyStop,
)
from lab.geometry import Pose2D, wrap_angle
from lab.robot import Robot
from lab.search.baselines import frontier_cells, lawnmower_targets
from lab.search.budget import SearchBudgetExceeded
from lab.search.global_search import GlobalSearchConfig, GlobalSearchResult, global_search
from lab.search.local_search import (
    LocalSearchConfig,
    LocalSearchResult,
    ViewRecord,
    local_search,
    look_at_points,
    make_matcher,
)
from lab.search.probability_map import ProbabilityMap
from lab.vision.database import FeatureDatabase

__all__ = [
    "AgentConfig",
    "AgentResult",
    "INTERRUPTED",
    "MapSnapshot",
    "NavigationResult",
    "Navigate",
    "SearchAgent",
    "SearchEvent",
    "Strategy",
    "detection_rates",
]


#: The reason of a run ended by Ctrl-C (SIGINT, a notebook's "interrupt kernel"): the robot is stopped and
#: the record so far returned, as for any other end.
INTERRUPTED = "interrupted"

#: A view sees roughly a third of an object's features (one to three faces of a box, half of a cup), so
#: a database with fewer than this many times ``min_matches`` features cannot give a pose from one view:
#: a not-found run says so in its reason.
THIN_DATABASE_VIEWS = 3

#: How many navigation requests in a row may fail with the robot's own cell blocked (START_IN_OBSTACLE:
#: the navigator cleared its footprint and could not drive out of the grown obstacles round it) before
#: the run ends as stuck; each tries another cell, and none can be reached from where it stands.
MAX_STUCK = 3


#: How near [m] the side look asks the navigator to come to its spot: it stops at the near edge of
#: that disc, which at the band's 0.75 m from the peak turns the step by up to 8 degrees.
SIDE_LOOK_TOLERANCE_M = 0.1


class _Stuck(Exception):
    """The robot cannot leave where it stands (raised by the agent, ends the run with its reason)."""


#: Errors from the robot that end a run with their reason instead of raising out of it.
_DEVICE_FAULTS = (
    DeviceTimeout,
    SafetyStop,
    EStopActive,
    NotEnabled,
    ConnectionLost,
    CommandRejected,
    ProtocolError,
)


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
class NavigationResult:
    """What the agent's ``navigate`` call reports (any object with these attributes will do).

    Attributes
    ----------
    arrived : bool
        The robot stands within the distance band of the target, facing it.
    reason : str
        Why not, or how it went.
    pose : Pose2D
        The odometry pose at the end.
    path_xy : ndarray, shape (k, 2) [m] or None
        The (first) planned path, for the figures.
    """

    arrived: bool
    reason: str
    pose: Pose2D
    path_xy: np.ndarray | None = field(default=None, repr=False)


class Navigate(Protocol):
    def __call__(self, target_xy: tuple[float, float], min_distance: float, max_distance: float): ...


@dataclass(frozen=True)
class AgentConfig:
    """Settings of the search loop.

    Attributes
    ----------
    strategy : Strategy
    travel_speed_m_s, look_time_s : float [m/s], [s]
        The rate strategy's cost model (:meth:`SearchAgent._rate_cell`): a drive makes good
        ``travel_speed_m_s`` (turns, braking and the localizer's pan scans included) and a local search
        takes ``look_time_s``. Measured on the tuning split (seeds 1-2, 36 paper-strategy runs): median
        0.15 m/s (path length over the time spent navigating) and 8.5 s (median local search).
    global_threshold : float
        Global search when the largest cell probability is below ``global_threshold / n_cells``
        (twice the uniform value by default: the map holds no peak worth visiting).
    global_search, local_search : configs of the two searches
    lawnmower_spacing_m : float [m]
        Lattice spacing of the lawnmower baseline.
    coverage_radius_m : float [m]
        The frontier baseline counts the cells within this distance in front of the robot (the
        local search's hemisphere) as searched.
    rescan_distance_m : float [m]
        A repeated global search from within this distance of an earlier one would see the same
        colours again and add the same evidence a second time (it is not an independent measurement):
        the robot first drives to a new vantage point, the map cell farthest from every earlier scan
        point and at least ``vantage_margin_m`` inside the map (within ``vantage_reach_m`` of it).
    vantage_margin_m, vantage_reach_m : float [m]
    revisit_turns_deg : tuple of float [deg]
        A cell searched again (the Bayes update may leave a cell with strong colour evidence the most
        probable after one miss), or a neighbour's search answered for (within the local search's
        ``neighbour_radius_m``), is approached from further round it than the robot stood for that
        search: the first view may have shown the object's narrow side, or a face at a grazing angle,
        and the same view again adds no evidence. The turns are tried in order, each one way and then
        the other; when none is within reach the approach falls back to the nearest spot of the band,
        which against a wall (a shelf, a table's end: both 120 degree turns lie behind it) is often the
        first side again. Measured (tuning seeds 0-23, ``benchmarks/bench_local_search.py``, the book
        on the shelf): all 8 misses showed the book's 5 cm spine; stood 0.75 m from it, 30 degrees
        either side of the shelf's normal, 12 of those 16 stands found it, and 55 degrees either side
        was out of reach in 14 of 16. Yet ``(120, 60, 30)`` changed little in the closed loop (tuning
        split, shelf, 18 trials paired with ``(120,)``: 16/18 both, one book found and another lost,
        median 112 s against 103 s), so the default stays ``(120,)``.
    second_side : bool
        A local search that missed although the object's colours were near the cell (its second look
        aimed at a colour peak there) is followed at once by one from another side (the revisit's
        turns), before the robot moves on: a thin object shows its narrow side from many directions
        (the book on the shelf: all 8 misses of the bench above had a colour peak at the book). Off by
        default: on the tuning split's shelf trials (seeds 1-3, 18 trials, paired with it off) it
        found one book that the map alone missed, but every distractor of the object's colours (the
        spray bottle, poster_west, the toy block's yellow for the cereal box) now cost two searches
        at once, and four trials were lost: 14/18 successes against 16/18, median time 178 s
        against 104 s.
    side_look_deg : float [deg]
        A local search that missed although the object's colours were near the cell (its second look
        aimed at them) is followed by the *side look*: the robot steps this far round the strongest
        colour peak (at the middle of the local-search band from it, or its far edge), one way and then
        the other, and from each spot looks at the peaks again
        (:func:`lab.search.local_search.look_at_points`: no 9 views, only the second look). A book
        standing on the shelf with its spine to the room shows a 5 cm strip of blue and no pose:
        stood round it, one of its covers turns towards the camera. Not for a database too thin to give
        a pose from one view (``THIN_DATABASE_VIEWS``: the glossy cup). 0 turns this off. Measured on
        the tuning split: the book upright on the shelf at yaw 65, 90 and 115 degrees, 0.75 and 0.9 m
        away (12 stands placed by hand): from in front the whole local search missed 11; 35 degrees
        round, one of the two sides found it in all 12 (45 degrees the same, but closer to the shelf).
        In the closed loop (the book on the shelf, seeds 1-12, 24 trials paired with it off): 21/24
        successes against 17/24; 5 of its 66 side looks found the book.
    wide_band_m : float [m]
        A cell whose local-search band the navigator cannot reach is approached once more, the band's
        far edge this much further out (a cell against a wall or a shelf's back: the band lies almost
        all in the costmap's grown obstacles). 0 turns this off.
    max_nav_failures : int
        A cell the navigator failed to reach this often is excluded for the rest of the run (once:
        until the next global search).
    max_local_misses : int
        The paper's strategy excludes a cell for the rest of the run once this many failed local searches
        answered for it (it or a neighbour within the local search's ``neighbour_radius_m`` was searched;
        the second time from another side, ``revisit_turn_deg``). A thing of the object's colours that
        is not the object (the blue spray bottle for the blue book, a poster) gives a colour peak at
        every global search, and each one raised the cell again: on the tuning split (seeds 1-3, 54
        trials) 9 local searches went to cells two misses had answered for and none found anything,
        while 2 of 24 after one miss did (the second side). 0 turns this off.
    max_actions : int
        Safety bound on the loop (the time budget normally ends it first).
    """

    strategy: Strategy = Strategy.PAPER
    travel_speed_m_s: float = 0.15
    look_time_s: float = 8.5
    global_threshold: float = 2.0
    global_search: GlobalSearchConfig = field(default_factory=GlobalSearchConfig)
    local_search: LocalSearchConfig = field(default_factory=LocalSearchConfig)
    lawnmower_spacing_m: float = 1.6
    coverage_radius_m: float = 1.4
    rescan_distance_m: float = 1.5
    vantage_margin_m: float = 0.8
    vantage_reach_m: float = 0.6
    revisit_turns_deg: tuple[float, ...] = (120.0,)
    second_side: bool = False
    side_look_deg: float = 35.0
    wide_band_m: float = 0.3
    max_nav_failures: int = 2
    max_local_misses: int = 2
    max_actions: int = 500

    def __post_init__(self):
        object.__setattr__(self, "strategy", Strategy.parse(self.strategy))
        if not (self.travel_speed_m_s > 0 and self.look_time_s > 0):
            raise ConfigError(
                "travel_speed_m_s and look_time_s must be > 0, got "
                f"{self.travel_speed_m_s}, {self.look_time_s}"
            )
        if not self.global_threshold > 0:
            raise ConfigError(f"global_threshold must be > 0, got {self.global_threshold}")
        if not 0 <= self.side_look_deg < 90:
            raise ConfigError(f"side_look_deg must be in [0, 90) degrees (0: off), got {self.side_look_deg}")
        if not self.wide_band_m >= 0:
            raise ConfigError(f"wide_band_m must be >= 0 m, got {self.wide_band_m}")
        turns = tuple(self.revisit_turns_deg)
        if not turns or not all(0 < t <= 180 for t in turns):
            raise ConfigError(
                f"revisit_turns_deg must be one or more turns in (0, 180] degrees, got {turns!r}"
            )
        object.__setattr__(self, "revisit_turns_deg", turns)
        if not self.lawnmower_spacing_m > 0 or not self.coverage_radius_m > 0:
            raise ConfigError("lawnmower_spacing_m and coverage_radius_m must be > 0")
        m = self.max_local_misses
        if isinstance(m, bool) or not isinstance(m, int) or m < 0:
            raise ConfigError(f"max_local_misses must be a whole number >= 0 (0: off), got {m!r}")


@dataclass(frozen=True)
class MapSnapshot:
    """The probability map at time ``t`` [s], after ``label`` (e.g. a failed local search of ``cell``)."""

    t: float
    P: np.ndarray = field(repr=False)
    label: str = ""
    cell: tuple[int, int] | None = None
    pose: Pose2D | None = None


@dataclass(frozen=True)
class SearchEvent:
    """One step of the run, for the record: ``kind`` is global / navigate / skip / local / end."""

    t: float
    kind: str
    cell: tuple[int, int] | None = None
    detail: str = ""

    def as_dict(self) -> dict:
        return {
            "t": round(self.t, 3),
            "kind": self.kind,
            "cell": None if self.cell is None else list(self.cell),
            "detail": self.detail,
        }


@dataclass(frozen=True)
class AgentResult:
    """How a run of :class:`SearchAgent` ended, and its record.

    Attributes
    ----------
    found : bool
    reason : str
        Why the run ended.
    G_WO : ndarray, shape (4, 4) or None
        The found object's pose in the world (odometry) frame.
    local : LocalSearchResult or None
        The successful local search.
    global_searches, local_searches : int
    events : tuple of SearchEvent
    snapshots : tuple of MapSnapshot
        After each global search and each failed local search.
    globals_ : tuple of GlobalSearchResult
    nav_paths : tuple of (target_xy, path_xy or None)
    P_final : ndarray
    t_start, t_end : float [s] (robot clock)
    """

    found: bool
    reason: str
    G_WO: np.ndarray | None = field(default=None, repr=False)
    local: LocalSearchResult | None = field(default=None, repr=False)
    global_searches: int = 0
    local_searches: int = 0
    events: tuple[SearchEvent, ...] = field(default=(), repr=False)
    snapshots: tuple[MapSnapshot, ...] = field(default=(), repr=False)
    globals_: tuple[GlobalSearchResult, ...] = field(default=(), repr=False)
    nav_paths: tuple = field(default=(), repr=False)
    P_final: np.ndarray | None = field(default=None, repr=False)
    t_start: float = 0.0
    t_end: float = 0.0


# --- the agent ------------------------------------------------------------------------------------------


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


@dataclass(frozen=True)
class _Target:
    """Where to go next: a cell to search, or (``vantage``) a place to scan from."""

    cell: tuple[int, int]
    xy: tuple[float, float]
    vantage: bool = False


class SearchAgent:
    """The search loop of the module docstring.

    Parameters
    ----------
    robot : Robot
        Enabled; usually a :class:`~lab.search.budget.BudgetedRobot` (then the budget ends the run cleanly).
    db : FeatureDatabase
        The searched object's database (features and colour model).
    navigate : callable
        ``navigate(target_xy, min_distance, max_distance) -> NavigationResult``-like.
    pmap : ProbabilityMap
        The map ``M_p`` with its prior ``P_0`` (updated in place).
    config : AgentConfig, optional
    rng : numpy.random.Generator
        Seeds the RANSAC starts of the local searches.
    max_time_s : float [s], optional
        Also end the run (between actions) once this much robot time has passed.
    observer : callable, optional
        ``observer(agent, event)`` after every :class:`SearchEvent` (live views and recordings,
        :mod:`lab.viz.live`). None (the default) costs nothing.
    """

    def __init__(
        self,
        robot: Robot,
        db: FeatureDatabase,
        navigate: Callable,
        pmap: ProbabilityMap,
        config: AgentConfig | None = None,
        *,
        rng: np.random.Generator,
        max_time_s: float = math.inf,
        observer: Callable | None = None,
    ):
        self.robot, self.db, self.navigate, self.pmap = robot, db, navigate, pmap
        self.observer = observer
        self.last_local: LocalSearchResult | None = None  # the last local search (for the observer)
        self.config = config or AgentConfig()
        self.rng = rng
        self.max_time_s = max_time_s
        self.matcher = make_matcher(db)
        shape = pmap.spec.shape
        self._excluded_temp = np.zeros(shape, bool)
        self._excluded = np.zeros(shape, bool)
        self._nav_failures = np.zeros(shape, int)
        self._misses = np.zeros(shape, int)  # failed local searches that answered for each cell
        self._stuck = 0  # navigation requests in a row that found the robot's own cell blocked
        self._best_view: ViewRecord | None = None  # the failed searches' view closest to a pose
        self._searched = np.zeros(shape, bool)
        self._events: list[SearchEvent] = []
        self._snapshots: list[MapSnapshot] = []
        self._globals: list[GlobalSearchResult] = []
        self._nav_paths: list = []
        self.global_searches = 0
        self.local_searches = 0
        self._local_since_global = 0
        self._lawnmower: list[tuple[float, float]] | None = None
        self._scan_points: list[tuple[float, float]] = []
        self._relocating = False
        self._stands: list[tuple[tuple[float, float], tuple[float, float]]] = []  # (searched xy, stood at)

    # -- bookkeeping -------------------------------------------------------------------------------
    def _event(self, kind: str, cell=None, detail: str = "") -> None:
        self._events.append(
            SearchEvent(self.robot.now(), kind, None if cell is None else tuple(cell), detail)
        )
        if self.observer is not None:
            self.observer(self, self._events[-1])

    def _snapshot(self, label: str, cell=None) -> None:
        self._snapshots.append(
            MapSnapshot(self.robot.now(), self.pmap.P.copy(), label, cell, self.robot.odometry())
        )

    @property
    def excluded(self) -> np.ndarray:
        return self._excluded | self._excluded_temp

    # -- the loop ----------------------------------------------------------------------------------
    def run(self) -> AgentResult:
        """Search until found, out of time (budget), out of places to look, stopped by a device fault
        (:class:`~lab.errors.LabError` from the robot: the reason names it) or interrupted (Ctrl-C: the
        reason is :data:`INTERRUPTED`); never raises for those, and stops the robot on the way out."""
        t0 = self.robot.now()
        found: LocalSearchResult | None = None
        reason = "action limit reached"
        try:
            for _ in range(self.config.max_actions):
                if self.robot.now() - t0 >= self.max_time_s:
                    reason = "time budget used up"
                    break
                target = self._next_target()
                if target is None:
                    reason = "no reachable place left to search"
                    break
                res = self._relocate(target) if target.vantage else self._visit(target.cell, target.xy)
                if res is not None and res.found:
                    found = res
                    reason = "found"
                    break
        except (SearchBudgetExceeded, _Stuck) as e:
            reason = str(e)
        except _DEVICE_FAULTS as e:  # a pan-tilt that never arrives, a safety stop, a lost link: end cleanly
            reason = f"stopped by a fault: {type(e).__name__}: {e}"
        except KeyboardInterrupt:  # Ctrl-C: the operator's stop; the record so far is the result
            reason = INTERRUPTED
        finally:
            try:
                self.robot.stop()
            except LabError:
                pass
        if found is None and reason != INTERRUPTED:
            reason += self._why_not_found()
        self._event("end", detail=reason)
        return AgentResult(
            found is not None,
            reason,
            None if found is None else found.G_WO,
            found,
            self.global_searches,
            self.local_searches,
            tuple(self._events),
            tuple(self._snapshots),
            tuple(self._globals),
            tuple(self._nav_paths),
            self.pmap.P.copy(),
            t0,
            self.robot.now(),
        )

    def _next_target(self):
        s = self.config.strategy
        pose = self.robot.odometry()
        if s is Strategy.PAPER or s is Strategy.RATE:
            return self._paper_target(pose)
        if s is Strategy.LAWNMOWER:
            return self._lawnmower_target(pose)
        return self._frontier_target(pose)

    def _paper_target(self, pose: Pose2D):
        spec = self.pmap.spec
        threshold = self.config.global_threshold / spec.n_cells
        selectable = ~self.excluded
        flat = not selectable.any() or float(self.pmap.P[selectable].max()) < threshold
        if self.global_searches == 0 or (flat and self._local_since_global > 0):
            if self._near_scan_point(pose) and not self._relocating:
                vantage = self._new_vantage_point()
                if vantage is not None:
                    self._relocating = True  # drive there first; the scan comes on the next turn
                    return vantage
            self._relocating = False
            self._global_search()
        cell = None
        if self.config.strategy is Strategy.RATE:
            cell = self._rate_cell(self.robot.odometry())
        if cell is None:
            cell = self.pmap.peak(exclude=self.excluded, near_xy=(pose.x, pose.y))
        if cell is None:
            return None
        return _Target(cell, self.pmap.centre(cell))

    def _rate_cell(self, pose: Pose2D) -> tuple[int, int] | None:
        """The rate strategy's next cell: among the map's peaks worth a visit (local maxima within the
        local search's ``neighbour_radius_m``, not excluded, at least ``global_threshold / n_cells``),
        the one with the most probability per second it costs (:func:`detection_rates`); None when
        there is no such peak (the caller takes the map's maximum)."""
        lc = self.config.local_search
        spec = self.pmap.spec
        P = np.where(self.excluded, -1.0, self.pmap.P)
        r_cells = max(1, int(round(lc.neighbour_radius_m / spec.resolution)))
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

    def _near_scan_point(self, pose: Pose2D) -> bool:
        d = self.config.rescan_distance_m
        return any(math.hypot(pose.x - x, pose.y - y) < d for x, y in self._scan_points)

    def _new_vantage_point(self):
        """The cell farthest from every earlier scan point, at least ``vantage_margin_m`` inside the map
        (ties: nearest the robot); None when there is none left."""
        spec = self.pmap.spec
        X, Y = spec.cell_centers()
        x0, x1, y0, y1 = spec.extent
        m = self.config.vantage_margin_m
        ok = (X >= x0 + m) & (X <= x1 - m) & (Y >= y0 + m) & (Y <= y1 - m) & ~self.excluded
        if not ok.any():
            return None
        d = np.min([np.hypot(X - x, Y - y) for x, y in self._scan_points], axis=0)
        score = np.where(ok, d, -1.0)
        i, j = np.unravel_index(int(np.argmax(score)), score.shape)
        return _Target((int(i), int(j)), self.pmap.centre((int(i), int(j))), vantage=True)

    def _lawnmower_target(self, pose: Pose2D):
        if not self._lawnmower:
            self._lawnmower = lawnmower_targets(
                self.pmap.spec, self.config.lawnmower_spacing_m, (pose.x, pose.y)
            )
        for _ in range(len(self._lawnmower)):
            xy = self._lawnmower.pop(0)
            cell = self.pmap.cell_of(*xy)
            if not self._excluded[cell]:
                return _Target(cell, self.pmap.centre(cell))
        return None

    def _frontier_target(self, pose: Pose2D):
        cand = frontier_cells(self._searched)
        cand = cand[~self.excluded[cand[:, 0], cand[:, 1]]] if len(cand) else cand
        if len(cand) == 0:
            if self._searched.all():
                self._searched[:] = False  # everything seen once: start a second sweep
                return self._frontier_target(pose)
            return None
        c = self.pmap.spec.centers_of(cand)
        d = np.hypot(c[:, 0] - pose.x, c[:, 1] - pose.y)
        # the nearest frontier cell that is not right under the robot (it must stand back to look)
        d = np.where(d < self.config.local_search.min_distance_m, d + 1e3, d)
        k = int(np.argmin(d))
        cell = (int(cand[k, 0]), int(cand[k, 1]))
        return _Target(cell, self.pmap.centre(cell))

    def _global_search(self) -> None:
        p = self.robot.odometry()
        self._scan_points.append((p.x, p.y))
        res = global_search(self.robot, self.db, self.pmap, self.config.global_search)
        self.global_searches += 1
        self._local_since_global = 0
        self._excluded_temp[:] = False
        self._globals.append(res)
        used = res.used_peaks
        self._event(
            "global", detail=f"{len(used)} colour peaks used of {len(res.peaks)}; max P {self.pmap.max:.4f}"
        )
        self._snapshot("global search")

    def _relocate(self, target: _Target) -> None:
        """Drive to a new vantage point for the next global search."""
        nav = self._navigate(target.xy, 0.0, self.config.vantage_reach_m)
        self._nav_paths.append((target.xy, getattr(nav, "path_xy", None)))
        if not nav.arrived:
            self._excluded_temp[target.cell] = True
            self._event("skip", target.cell, f"vantage point not reached ({nav.reason})")
        else:
            self._event(
                "navigate", target.cell, f"to a new vantage point for the global search: {nav.reason}"
            )

    def _last_stand(self, xy) -> tuple[float, float] | None:
        """Where the robot stood for the last local search that answered for the point ``xy`` [m] (its
        target within ``neighbour_radius_m``, as the map update counts it), or None."""
        r = self.config.local_search.neighbour_radius_m
        for searched, stood in reversed(self._stands):
            if math.dist(searched, xy) <= r + 1e-9:
                return stood
        return None

    def _approach(self, cell, xy):
        """Navigate to local-search range of the cell. A cell a local search answered for before (it,
        or a neighbour within ``neighbour_radius_m``: the map counted that search's miss for it) is
        approached from another side: ``revisit_turns_deg`` further round it from where the robot stood
        for the last such search, each turn in order, one way and then the other (a table or shelf
        against a wall is open on one side and its ends: the large turns are often behind the wall), by
        asking for a spot near that side's point; when all fail, from wherever the navigator can.
        (From the same side, a neighbour's search would see what the last one saw.)"""
        lc = self.config.local_search
        last = self._last_stand(xy)
        if last is not None:
            a0 = math.atan2(last[1] - xy[1], last[0] - xy[0])
            tol = 0.5 * (lc.max_distance_m - lc.min_distance_m)
            for turn in (s * t for t in self.config.revisit_turns_deg for s in (1, -1)):
                nav = self._stand_round(xy, a0 + math.radians(turn), tol)
                if nav.arrived:
                    return nav, f"from another side ({turn:+.0f} deg): {nav.reason}"
        nav = self._navigate(xy, lc.min_distance_m, lc.max_distance_m)
        if nav.arrived or self.config.wide_band_m <= 0:
            return nav, nav.reason
        # a cell against a wall or behind furniture: its band may lie (almost) all in the costmap's
        # grown obstacles, while a spot a little farther out is free and still close enough to look
        far = lc.max_distance_m + self.config.wide_band_m
        wide = self._navigate(xy, lc.min_distance_m, far)
        if wide.arrived:
            return wide, f"from {far:.1f} m ({nav.reason}): {wide.reason}"
        return wide, f"{nav.reason}; {wide.reason} with the band widened"

    def _stand_round(self, xy, angle: float, tol: float):
        """Navigate to within ``tol`` [m] of the spot in the direction ``angle`` [rad] from ``xy`` [m] at
        the middle of the local-search band, or else at its far edge (beside a table's end the middle
        may lie in the table's grown footprint while a spot a little farther out is free). The last
        navigation's result; ``arrived`` is False unless the robot stands within the band (give or take
        5 cm, up to the wide band's far edge) of ``xy``."""
        lc = self.config.local_search
        far = lc.max_distance_m + self.config.wide_band_m
        for r in (0.5 * (lc.min_distance_m + lc.max_distance_m), lc.max_distance_m):
            nav = self._navigate((xy[0] + r * math.cos(angle), xy[1] + r * math.sin(angle)), 0.0, tol)
            d = math.hypot(nav.pose.x - xy[0], nav.pose.y - xy[1])
            if nav.arrived and lc.min_distance_m - 0.05 <= d <= far:
                return nav
        if nav.arrived:
            return NavigationResult(False, f"arrived {d:.2f} m from it, outside the band", nav.pose)
        return nav

    def _note_views(self, res: LocalSearchResult) -> None:
        """Keep the failed searches' view that came closest to a pose (for a not-found run's reason)."""
        for v in res.views:
            if self._best_view is None or self._rank(v) > self._rank(self._best_view):
                self._best_view = v

    def _visit(self, cell, xy, second_side: bool = False) -> LocalSearchResult | None:
        """Navigate to local-search range of the cell, search, and update the map on a miss; a miss
        that saw the object's colours there is followed by a search from another side
        (``AgentConfig.second_side``; ``second_side``: this is that search)."""
        lc = self.config.local_search
        nav, how_arrived = self._approach(cell, xy)
        self._nav_paths.append((xy, getattr(nav, "path_xy", None)))
        self._stuck = self._stuck + 1 if "START_IN_OBSTACLE" in str(nav.reason) else 0
        if self._stuck >= MAX_STUCK:
            raise _Stuck(
                f"stuck: {self._stuck} navigation requests in a row found the robot's own cell blocked in "
                "its costmap (START_IN_OBSTACLE) and could not drive out"
            )
        if not nav.arrived:
            self._nav_failures[cell] += 1
            if self._nav_failures[cell] >= self.config.max_nav_failures:
                self._excluded[cell] = True
                how = "excluded for the rest of the run"
            else:
                self._excluded_temp[cell] = True
                how = "skipped until the next global search"
            self._event("skip", cell, f"not reached ({nav.reason}); {how}")
            return None
        self._event("navigate", cell, ("second side, " if second_side else "") + how_arrived)
        p = self.robot.odometry()
        self._stands.append(((float(xy[0]), float(xy[1])), (p.x, p.y)))
        res = local_search(self.robot, self.db, xy, self.rng, lc, self.matcher)
        self.last_local = res
        self._note_views(res)
        self.local_searches += 1
        self._local_since_global += 1
        self._mark_searched(xy)
        if res.found:
            self._event("local", cell, res.reason)
            return res
        for c in self._searched_cells(cell, lc.neighbour_radius_m):
            self.pmap.update(c, 0, lc.alpha, lc.beta)  # Eqs. (1)-(3): searched, not found
            self._misses[c] += 1
        self._event("local", cell, res.reason)
        self._snapshot("local search failed", cell)
        self._exclude_missed()
        thin = len(self.db) < THIN_DATABASE_VIEWS * lc.min_matches  # no pose from one view: no side look
        if self.config.side_look_deg > 0 and res.colour_peaks and not second_side and not thin:
            side = self._side_look(cell, res.colour_peaks)
            if side is not None and side.found:
                return side
        if self.config.second_side and res.colour_peaks and not second_side and not self.excluded[cell]:
            return self._visit(cell, xy, second_side=True)
        return res

    def _side_look(self, cell, peaks) -> LocalSearchResult | None:
        """Step ``side_look_deg`` round the strongest colour peak ``peaks[0]`` [m] from where the robot
        stood, one way and then the other, and look at the ``peaks`` from each spot that the navigator
        reaches (:attr:`AgentConfig.side_look_deg`). The found search's result, or None."""
        lc = self.config.local_search
        p = (float(peaks[0][0]), float(peaks[0][1]))
        here = self.robot.odometry()
        a0 = math.atan2(here.y - p[1], here.x - p[0])
        for turn in (self.config.side_look_deg, -self.config.side_look_deg):
            nav = self._stand_round(p, a0 + math.radians(turn), SIDE_LOOK_TOLERANCE_M)
            self._nav_paths.append((p, getattr(nav, "path_xy", None)))
            if not nav.arrived:
                self._event("skip", cell, f"side look ({turn:+.0f} deg) not reached ({nav.reason})")
                continue
            self._event("navigate", cell, f"side look, {turn:+.0f} deg round the colour peak: {nav.reason}")
            res = look_at_points(self.robot, self.db, peaks, self.rng, lc, self.matcher)
            self.last_local = res
            self._note_views(res)
            self._event("local", cell, f"side look: {res.reason}")
            if res.found:
                return res
        return None

    def _why_not_found(self) -> str:
        """What the failed local searches saw, in words, appended to a not-found run's reason: their best
        view (a track beats a RANSAC start, then more inliers, then more matches) against what a pose
        needs, and, for a database too thin to give a pose from one view (a glossy, featureless object:
        the paper's penguin cup), that this is why."""
        v = self._best_view
        if v is None:
            return ""
        lc, n_db = self.config.local_search, len(self.db)
        if v.n_matched < lc.min_matches:
            best = f"{v.n_matched} database matches in a view (a pose needs {lc.min_matches})"
        elif v.n_inliers < lc.min_inliers:
            best = (
                f"a RANSAC start with {v.n_inliers} inliers from {v.n_matched} database matches "
                f"(a pose needs {lc.min_inliers})"
            )
        else:
            best = f"a track from a RANSAC start with {v.n_inliers} inliers, {v.outcome}"
        out = f"; {self.local_searches} local searches never confirmed the object: at best {best}"
        if n_db < THIN_DATABASE_VIEWS * lc.min_matches:
            out += (
                f"; its database holds only {n_db} SIFT features (a glossy, featureless object, like "
                f"the paper's penguin cup): too few to give a pose from one view"
            )
        return out

    def _rank(self, v: ViewRecord) -> tuple:
        """How close a view came to a pose (as the local search ranks its own views)."""
        return (v.n_inliers >= self.config.local_search.min_inliers, v.n_inliers, v.n_matched)

    def _exclude_missed(self) -> None:
        """The map's strategies (paper, rate) give up the cells ``max_local_misses`` failed searches
        answered for."""
        m = self.config.max_local_misses
        if self.config.strategy not in (Strategy.PAPER, Strategy.RATE) or m == 0:
            return
        new = (self._misses >= m) & ~self._excluded
        if new.any():
            self._excluded |= new
            n = int(new.sum())
            why = f"{n} cells answered for by {m} failed local searches: not searched again"
            self._event("exclude", detail=why)

    def _searched_cells(self, cell, radius_m: float) -> list[tuple[int, int]]:
        """The searched cell first, then the cells whose centres lie within ``radius_m`` of its centre."""
        X, Y = self.pmap.spec.cell_centers()
        cx, cy = self.pmap.centre(cell)
        near = np.argwhere(np.hypot(X - cx, Y - cy) <= radius_m + 1e-9)
        return [tuple(cell)] + [(int(i), int(j)) for i, j in near if (i, j) != tuple(cell)]

    def _navigate(self, xy, min_distance: float, max_distance: float):
        try:
            return self.navigate(xy, min_distance, max_distance)
        except (SearchBudgetExceeded, *_DEVICE_FAULTS):
            raise
        except LabError as e:  # a navigator's clear refusal (outside the map, ...) is a failure to arrive
            return NavigationResult(False, f"navigation error: {e}", self.robot.odometry())

    def _mark_searched(self, target_xy) -> None:
        """Cells within the coverage radius in front of the robot (the local search's hemisphere)."""
        p = self.robot.odometry()
        X, Y = self.pmap.spec.cell_centers()
        d = np.hypot(X - p.x, Y - p.y)
        bearing = math.atan2(target_xy[1] - p.y, target_xy[0] - p.x)
        ang = np.abs(wrap_angle(np.arctan2(Y - p.y, X - p.x) - bearing))
        self._searched |= (d <= self.config.coverage_radius_m) & ((ang <= math.radians(100)) | (d < 0.3))
