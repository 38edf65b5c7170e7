"""The closed search loop (the search paper's Fig. 4): global search, navigate to a peak, local search,
update the map, repeat; with navigation injected and a time budget that always ends the run.

The paper's strategy (:attr:`~lab.search.strategies.Strategy.PAPER`)::

    loop until found or out of time:
        if the map's maximum (over cells not excluded) < global_threshold / n_cells
           (always at the start; afterwards only once a local search ran since the last global one):
            if an earlier scan stood within rescan_distance_m: drive to a new vantage point first
            global search from where the robot stands                  (global_search.py)
            its colour peaks' detections -> pmap.observe
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
        otherwise the local search's detection (y = 0, its constant alpha, beta, for the cell and its
                 neighbours within neighbour_radius_m, see LocalSearchConfig) -> pmap.observe,
                 and a map snapshot (the paper's Fig. 6); a cell max_local_misses such searches
                 answered for is excluded for good (a distractor's colour peak comes back at every scan)

Where to look next is the target strategy's choice (:mod:`lab.search.strategies`: the paper's, the
rate strategy, and the lawnmower and frontier baselines); the agent runs the searches, the navigation
and the bookkeeping, and hands each search's detections to
:meth:`~lab.search.probability_map.ProbabilityMap.observe`. Its settings: :class:`SearchAgentConfig`
(:mod:`lab.search.config`); its records and the navigation protocol: :mod:`lab.search.records`.

**The budget.** :class:`~lab.search.budget.BudgetedRobot` wraps the robot: once its clock passes the
deadline, the next ``step`` raises :class:`~lab.search.budget.SearchBudgetExceeded` -- inside the
navigator, a pan-tilt wait or a drive -- and the agent ends the run there ("time budget").

**A run that ends without the object** says why in its reason: how it ended ("time budget of 300 s used
up"), then what its local searches saw at best (database matches, a RANSAC start's inliers or a track
that was not confirmed, against what a pose needs), and, for an object whose database is too thin
for a pose from one view (the glossy cup, the paper's penguin cup), that this is the cause.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from lab.errors import (
    CommandRejected,
    ConnectionLost,
    DeviceTimeout,
    EStopActive,
    LabError,
    NotEnabled,
    ProtocolError,
    SafetyStop,
)
from lab.geometry import wrap_angle
from lab.robot import Robot
from lab.search.budget import SearchBudgetExceeded
from lab.search.config import SearchAgentConfig
from lab.search.follow import approach_track, start_tracks, track_for
from lab.search.global_search import GlobalSearchResult, global_search
from lab.search.local_search import (
    LocalSearchResult,
    ViewRecord,
    local_search,
    look_at_points,
    make_matcher,
)
from lab.search.probability_map import ProbabilityMap
from lab.search.records import AgentResult, MapSnapshot, NavigationResult, SearchEvent
from lab.search.strategies import Strategy, Target, make_strategy
from lab.vision.database import FeatureDatabase

__all__ = ["INTERRUPTED", "MAX_STUCK", "SIDE_LOOK_TOLERANCE_M", "THIN_DATABASE_VIEWS", "SearchAgent"]


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
    config : SearchAgentConfig, optional
    rng : numpy.random.Generator
        Seeds the RANSAC starts of the local searches.
    max_time_s : float [s], optional
        Also end the run (between actions) once this much robot time has passed.
    observer : callable, optional
        ``observer(agent, event)`` after every :class:`SearchEvent` (live views and recordings,
        :mod:`lab.viz.live`). None (the default) costs nothing.
    passable : callable, optional
        ``passable() -> (nx, ny)`` on the map's grid: where a moving object may go, as the robot
        believes, either a bool mask (:func:`lab.search.motion.passable_from_costmap`) or the cells
        labelled by surface (:func:`lab.search.motion.surfaces_from_costmap`, Eq. (P2): mass moves
        between neighbours of one surface); used only with a moving ``config.motion``. None: every cell.
    """

    def __init__(
        self,
        robot: Robot,
        db: FeatureDatabase,
        navigate: Callable,
        pmap: ProbabilityMap,
        config: SearchAgentConfig | None = None,
        *,
        rng: np.random.Generator,
        max_time_s: float = math.inf,
        observer: Callable | None = None,
        passable: Callable | None = None,
    ):
        self.robot, self.db, self.navigate, self.pmap = robot, db, navigate, pmap
        self.observer = observer
        self.passable = passable
        self._t_predicted: float | None = None  # the robot time the map was last predicted to
        self.last_local: LocalSearchResult | None = None  # the last local search (for the observer)
        self.config = config or SearchAgentConfig()
        self.rng = rng
        self.max_time_s = max_time_s
        self.matcher = make_matcher(db)
        shape = pmap.spec.shape
        self._excluded_temp = np.zeros(shape, bool)
        self._excluded = np.zeros(shape, bool)
        self.vantage_failed = np.zeros(shape, bool)  # near a vantage point not reached: not chosen again
        self._nav_failures = np.zeros(shape, int)
        self._misses = np.zeros(shape, int)  # failed local searches that answered for each cell
        self._stuck = 0  # navigation requests in a row that found the robot's own cell blocked
        self._best_view: ViewRecord | None = None  # the failed searches' view closest to a pose
        self.searched = np.zeros(shape, bool)  # cells the local searches covered (the frontier's)
        self.target_strategy = make_strategy(self.config)
        self._events: list[SearchEvent] = []
        self._snapshots: list[MapSnapshot] = []
        self._globals: list[GlobalSearchResult] = []
        self._nav_paths: list = []
        self.global_searches = 0
        self.local_searches = 0
        self.local_since_global = 0  # local searches since the last global search
        self.scan_points: list[tuple[float, float]] = []  # where the global searches stood [m]
        self._stands: list[tuple[tuple[float, float], tuple[float, float]]] = []  # (searched xy, stood at)
        self.tracks: list = []  # the last global search's colour tracks (a moving object, lab.search.follow)
        self._colour_model: np.ndarray | None = None  # that search's ratio histogram, to re-detect with

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
        """(nx, ny) bool: cells not to search now."""
        return self._excluded | self._excluded_temp

    @property
    def excluded_for_good(self) -> np.ndarray:
        """(nx, ny) bool: cells not to search for the rest of the run."""
        return self._excluded

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

    @property
    def moving(self) -> bool:
        """Whether the map has a prediction step (a motion model with a speed above 0)."""
        return self.config.motion is not None and self.config.motion.moving

    def predict(self) -> None:
        """The prediction step (:meth:`ProbabilityMap.predict`) from the last prediction to the robot's
        clock now; a no-op for a stationary object."""
        if not self.moving:
            return
        now = self.robot.now()
        if self._t_predicted is not None and now > self._t_predicted:
            free = np.ones(self.pmap.spec.shape, bool) if self.passable is None else self.passable()
            self.pmap.predict(now - self._t_predicted, free, self.config.motion)
        self._t_predicted = now

    def _next_target(self) -> Target | None:
        self.predict()
        pose = self.robot.odometry()
        return self.target_strategy.next_target(self, pose)

    def global_search(self) -> None:
        """A global search from where the robot stands; its colour peaks update the map."""
        p = self.robot.odometry()
        self.scan_points.append((p.x, p.y))
        res = global_search(self.robot, self.db, self.pmap, self.config.global_search)
        self.predict()
        for detection in res.detections:
            self.pmap.observe(detection)
        self.global_searches += 1
        self.local_since_global = 0
        self._excluded_temp[:] = False
        self._globals.append(res)
        if self.moving and self.config.colour_track is not None:
            self.tracks = start_tracks(res, self.config.motion.speed_mps, self.config.colour_track)
            self._colour_model = res.colour_model
        used = res.used_peaks
        self._event(
            "global", detail=f"{len(used)} colour peaks used of {len(res.peaks)}; max P {self.pmap.max:.4f}"
        )
        self._snapshot("global search")

    def _relocate(self, target: Target) -> None:
        """Drive to a new vantage point for the next global search."""
        nav = self._navigate(target.xy, 0.0, self.config.vantage_reach_m)
        self._nav_paths.append((target.xy, getattr(nav, "path_xy", None)))
        if not nav.arrived:
            self._excluded_temp[target.cell] = True
            X, Y = self.pmap.spec.cell_centers()
            near = np.hypot(X - target.xy[0], Y - target.xy[1]) <= self.config.vantage_reach_m + 1e-9
            self.vantage_failed |= near
            self.vantage_failed[target.cell] = True
            self._event("skip", target.cell, f"vantage point not reached ({nav.reason})")
        else:
            self._event(
                "navigate", target.cell, f"to a new vantage point for the global search: {nav.reason}"
            )

    def _last_stand(self, xy) -> tuple[float, float] | None:
        """Where the robot stood for the last local search that answered for the point ``xy`` [m] (its
        target within ``neighbour_radius_m``, as the map update counts it), or None."""
        r = self.config.local_search.detection.neighbour_radius_m
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
        (``SearchAgentConfig.second_side``; ``second_side``: this is that search)."""
        lc = self.config.local_search
        followed = self._follow(xy)
        if followed is not None:  # the robot stands in the band of the track's predicted position
            nav, how_arrived, xy = followed.nav, followed.detail, followed.xy
            ij, inside = self.pmap.spec.cells_of(np.array([xy]))
            cell = (int(ij[0, 0]), int(ij[0, 1])) if inside[0] else cell
        else:
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
        res = local_search(self.robot, self.db, xy, self.rng, lc, self.matcher, cell=cell)
        self.last_local = res
        self._note_views(res)
        self.local_searches += 1
        self.local_since_global += 1
        self._mark_searched(xy)
        if res.found:
            self._event("local", cell, res.reason)
            return res
        self.predict()
        self.pmap.observe(res.detection)  # Eqs. (1)-(3): searched, not found
        for c in res.detection.cells(self.pmap.spec):
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

    def _follow(self, xy):
        """Approach the colour track that started at the map target ``xy`` [m] (a moving object, with
        ``config.colour_track``): the :class:`~lab.search.follow.FollowResult` when the robot arrived in
        the local-search band of its predicted position; None when there is no such track or it was
        lost or not reached (the agent then approaches the cell, as without tracks). A track is followed
        once: the local search that follows answers for it."""
        track = None if not self.tracks else track_for(self.tracks, xy, self.robot.now())
        if track is None:
            return None
        self.tracks.remove(track)
        lc = self.config.local_search
        res = approach_track(
            self.robot,
            self._navigate,
            track,
            self._colour_model,
            self.db,
            (lc.min_distance_m, lc.max_distance_m),
            self.config.travel_speed_m_s,
        )
        if res.nav is not None:
            self._nav_paths.append((res.xy, getattr(res.nav, "path_xy", None)))
        if not res.arrived:
            self._event("track", None, res.detail + "; approaching the map's cell instead")
            return None
        return res

    def _side_look(self, cell, peaks) -> LocalSearchResult | None:
        """Step ``side_look_deg`` round the strongest colour peak ``peaks[0]`` [m] from where the robot
        stood, one way and then the other, and look at the ``peaks`` from each spot that the navigator
        reaches (:attr:`SearchAgentConfig.side_look_deg`). The found search's result, or None."""
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
        self.searched |= (d <= self.config.coverage_radius_m) & ((ang <= math.radians(100)) | (d < 0.3))
