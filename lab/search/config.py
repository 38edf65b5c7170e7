"""The search agent's settings (:class:`SearchAgentConfig`)."""

from __future__ import annotations

from dataclasses import dataclass, field

from lab.errors import ConfigError
from lab.search.colour_track import ColourTrackConfig
from lab.search.global_search import GlobalSearchConfig
from lab.search.local_search import LocalSearchConfig
from lab.search.motion import MotionModel
from lab.search.strategies import Strategy

__all__ = ["SearchAgentConfig"]


@dataclass(frozen=True)
class SearchAgentConfig:
    """Settings of the search loop (:class:`lab.search.agent.SearchAgent`).

    Attributes
    ----------
    strategy : Strategy
    travel_speed_m_s, look_time_s : float [m/s], [s]
        The rate strategy's cost model (:meth:`lab.search.strategies.MapPeakStrategy.rate_cell`): a
        drive makes good ``travel_speed_m_s`` (turns, braking and the localizer's pan scans included)
        and a local search takes ``look_time_s``; both the medians of paper-strategy runs. How they
        were measured: docs/tuning/search-rate-cost-model.md.
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
        A vantage point the navigator did not reach is not chosen again, nor any cell within
        ``vantage_reach_m`` of it (the navigator looked for a goal there and found none it could
        reach), and the robot tries the next one at once, up to ``max_nav_failures`` drives in a row,
        before it scans where it stands: scanning from the same spot again sees the same colours.
    vantage_margin_m, vantage_reach_m : float [m]
    revisit_turns_deg : tuple of float [deg]
        A cell searched again (the Bayes update may leave a cell with strong colour evidence the most
        probable after one miss), or a neighbour's search answered for (within the local search's
        ``detection.neighbour_radius_m``), is approached from further round it than the robot stood
        for that search: the first view may have shown the object's narrow side, or a face at a grazing
        angle, and the same view again adds no evidence. The turns are tried in order, each one way and
        then the other; when none is within reach the approach falls back to the nearest spot of the
        band, which against a wall (a shelf, a table's end: both 120 degree turns lie behind it) is
        often the first side again. Smaller turns as well changed little in the closed loop, so the
        default is the one turn. How it was chosen: docs/tuning/search-revisit-turns.md.
    second_side : bool
        A local search that missed although the object's colours were near the cell (its second look
        aimed at a colour peak there) is followed at once by one from another side (the revisit's
        turns), before the robot moves on: a thin object shows its narrow side from many directions.
        Off by default: every distractor of the object's colours then costs two searches at once, more
        than the finds it adds. How it was chosen: docs/tuning/search-second-side.md.
    side_look_deg : float [deg]
        A local search that missed although the object's colours were near the cell (its second look
        aimed at them) is followed by the *side look*: the robot steps this far round the strongest
        colour peak (at the middle of the local-search band from it, or its far edge), one way and then
        the other, and from each spot looks at the peaks again
        (:func:`lab.search.local_search.look_at_points`: no 9 views, only the second look). A book
        standing on the shelf with its spine to the room shows a 5 cm strip of blue and no pose:
        stood round it, one of its covers turns towards the camera. Not for a database too thin to give
        a pose from one view (``THIN_DATABASE_VIEWS``: the glossy cup). 0 turns this off. How it was
        chosen: docs/tuning/search-side-look.md.
    wide_band_m : float [m]
        A cell whose local-search band the navigator cannot reach is approached once more, the band's
        far edge this much further out (a cell against a wall or a shelf's back: the band lies almost
        all in the costmap's grown obstacles). 0 turns this off.
    max_nav_failures : int
        A cell the navigator failed to reach this often is excluded for the rest of the run (once:
        until the next global search).
    max_local_misses : int
        The paper's strategy excludes a cell for the rest of the run once this many failed local searches
        answered for it (it or a neighbour within the local search's ``detection.neighbour_radius_m``
        was searched; the second time from another side, ``revisit_turns_deg``). A thing of the
        object's colours that is not the object (the blue spray bottle for the blue book, a poster)
        gives a colour peak at every global search, and each one raised the cell again; a third search
        of such a cell has not been seen to find anything. 0 turns this off. How it was chosen:
        docs/tuning/search-max-local-misses.md.
    max_actions : int
        Safety bound on the loop (the time budget normally ends it first).
    motion : MotionModel, optional
        A moving object's motion model: before every map update and every choice of the next target the
        map is predicted over the time since the last prediction (:mod:`lab.search.motion`). Cells that
        ``max_local_misses`` failed searches answered for are still given up: a distractor of the
        object's colours stays put while the object moves (docs/tuning/search-moving-object.md). None
        (the default) or a speed of 0: the paper's stationary object, the map untouched between updates.
    colour_track : ColourTrackConfig, optional
        With a moving ``motion``: each used colour peak of a global search becomes a track, and a map
        target where one started is approached by following it with the head (:mod:`lab.search.follow`),
        the local search looking at its predicted position. None (the default): the map's cell, as the
        paper's search.
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
    motion: MotionModel | None = None
    colour_track: ColourTrackConfig | None = None

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
