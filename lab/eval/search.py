"""``lab eval search``: a grid of search trials (objects x placements x seeds x strategies x obstacles
x sensing profiles x localization modes), run by :func:`lab.eval.sweep.run_sweep` like ``lab eval identify``.

**Placements.** A trial's placement is the surface it names (``floor``, ``table``, ``shelf``) and a
seeded random spot on it: ``random_placement`` with ``numpy.random.default_rng([seed, object_index,
surface_index])`` (the object's index in ``lab search --list-objects``, the surface's in
``lab.runs.placement.SURFACES``), the same for every strategy, with and without obstacles, wherever
the job runs. These are the placements ``benchmarks/eval_search.py`` has always used.

**Scoring.** Each job's JSON is the ``lab search --json`` result (its map snapshots left out: they are
for figures) plus ``obstacles_on_path`` (the boxes were asked for) and ``shortest_path_m``, the shortest
collision-free path from the start to local search range of the object on the scene's true occupancy
(evaluation only, the robot never sees it), from which the report computes SPL (success weighted by path
length).

**A moving object** (``--moving random|evasive``, :mod:`lab.runs.moving`): the floor placements (and
with ``--surfaces floor,table`` the table placements too: the carrier drives on the table's top), and
every trial twice on the same placement, seed and motion: with the map's prediction step (``map =
predict``) and the static-map baseline (``map = static``); the report groups by both and by surface.
``--maps predict`` runs the first alone, and ``--maps predict,static --resume`` in the same folder adds
the baseline later on the same trials (a job's key names its map).
"""

from __future__ import annotations

import math
import statistics
from dataclasses import dataclass, replace
from pathlib import Path

from lab.errors import ConfigError
from lab.eval.executor import Job
from lab.eval.sweep import SweepKind, check_sensing, confidently_wrong_pose, sensing_label

__all__ = [
    "SEARCH",
    "SEARCH_FIELDS",
    "SEARCH_MOVING",
    "SEARCH_MAX_TIME_S",
    "confidently_wrong",
    "SearchSweep",
    "search_job",
    "search_key",
    "shortest_path_m",
    "spl",
    "stored_survey_for",
]

#: The fields of a ``lab eval search`` sweep file (the flags' names).
SEARCH_FIELDS = (
    "objects",
    "surfaces",
    "seeds",
    "strategies",
    "obstacles",
    "sensing",
    "localization",
    "max_time",
    "max_wall_time",
    "moving",
    "object_speed",
    "pause",
    "maps",
    "error_scale",
    "survey_tour",
    "survey_once",
)

MOVING_KINDS = ("random", "evasive")
MAPS = ("predict", "static")  # the map of a moving-object trial: with the prediction step, the baseline

STRATEGIES = ("paper", "rate", "lawnmower", "frontier")
#: ``half``: every placement once, with the obstacle boxes on every other one (alternating over seed, object
#: and surface, so each object and each surface gets half): the issue's "placements, half with obstacles"
OBSTACLES = {"no": (False,), "yes": (True,), "both": (False, True), "half": None}


LOCALIZATIONS = ("landmarks", "odometry")


def search_key(
    strategy: str,
    obstacles: bool,
    sensing: str,
    object: str,
    surface: str,
    seed: int,
    localization: str = "landmarks",
) -> str:
    """A search job's name: ``OUT/jobs/KEY.json``."""
    ob = "obst" if obstacles else "free"
    return f"{strategy}_{ob}_{sensing}_{localization}_{object}_{surface}_s{seed}"


#: The default sim-time budget of a trial [s]: ``lab search``'s own (``--max-time``), so the evaluation
#: measures what a user's run does; the report prints the successes within shorter budgets beside it.
#: How it was chosen: docs/tuning/search-time-budget.md.
SEARCH_MAX_TIME_S = 600.0


@dataclass(frozen=True)
class SearchSweep:
    """The grid of ``lab eval search``."""

    objects: tuple[str, ...] = ("cereal_box", "book", "toy_block")
    surfaces: tuple[str, ...] = ("floor", "table", "shelf")
    seeds: tuple[int, ...] = ()
    strategies: tuple[str, ...] = STRATEGIES
    obstacles: str = "both"
    sensing: tuple[str, ...] = ("realistic",)
    localization: tuple[str, ...] = ("landmarks",)
    max_time: float = SEARCH_MAX_TIME_S
    max_wall_time: float | None = None
    moving: str | None = None
    object_speed: float = 0.1
    pause: float = 5.0
    maps: tuple[str, ...] = MAPS
    error_scale: tuple[float, ...] = (1.0,)
    survey_tour: bool = False
    survey_once: str | None = None

    def check(self) -> None:
        from lab.eval.robustness import parse_error_scales
        from lab.runs.placement import SURFACES, searchable_objects

        if not self.seeds:
            raise ConfigError("the seed range is empty: give --seeds like 100000-100001 (or seeds = [...])")
        known = searchable_objects()
        for o in self.objects:
            if o not in known:
                raise ConfigError(f"unknown object {o!r}; searchable objects: {', '.join(known)}")
        if not self.objects:
            raise ConfigError(f"no objects: give --objects like {','.join(known[:2])}")
        for s in self.surfaces:
            if s not in SURFACES:
                raise ConfigError(f"unknown surface {s!r}; surfaces: {', '.join(SURFACES)}")
        if not self.surfaces:
            raise ConfigError(f"no surfaces: give --surfaces like {','.join(SURFACES)}")
        for s in self.strategies:
            if s not in STRATEGIES:
                raise ConfigError(f"unknown strategy {s!r}; strategies: {', '.join(STRATEGIES)}")
        if not self.strategies:
            raise ConfigError(f"no strategies: give --strategies like {','.join(STRATEGIES)}")
        if self.obstacles not in OBSTACLES:
            raise ConfigError(f"obstacles must be one of {', '.join(OBSTACLES)}, got {self.obstacles!r}")
        check_sensing(self.sensing)
        for m in self.localization:
            if m not in LOCALIZATIONS:
                raise ConfigError(f"unknown localization {m!r}; allowed: {', '.join(LOCALIZATIONS)}")
        if not self.localization:
            raise ConfigError(f"no localization: give --localization like {','.join(LOCALIZATIONS)}")
        if not self.max_time > 0:
            raise ConfigError(f"max_time must be > 0 s, got {self.max_time}")
        parse_error_scales(self.error_scale)
        if self.max_wall_time is not None and not self.max_wall_time > 0:
            raise ConfigError(f"max_wall_time must be > 0 s, got {self.max_wall_time}")
        if self.moving is not None:
            if self.moving not in MOVING_KINDS:
                raise ConfigError(f"unknown --moving {self.moving!r}; allowed: {', '.join(MOVING_KINDS)}")
            from lab.runs.moving import MOVING_SURFACES, MovingOptions

            if not set(self.surfaces) <= set(MOVING_SURFACES):
                raise ConfigError(
                    f"a moving object rides on the floor or a table's top: --surfaces within "
                    f"{','.join(MOVING_SURFACES)}, got {','.join(self.surfaces)}"
                )

            MovingOptions(self.moving, self.object_speed, self.pause)  # one clear line for a bad speed
            bad = [m for m in self.maps if m not in MAPS]
            if bad or not self.maps:
                raise ConfigError(f"unknown --maps {','.join(bad) or '(none)'}; maps: {','.join(MAPS)}")

    def jobs(self) -> list[Job]:
        """Every trial; the shelf's last (the slowest), strategies next to each other on a placement."""
        from lab.eval.robustness import scale_suffix
        from lab.runs.placement import SURFACES, searchable_objects

        objects = searchable_objects()
        out = []
        for surface in sorted(self.surfaces, key=SURFACES.index):
            for seed in self.seeds:
                for name in self.objects:
                    for ob in self._obstacles(seed, objects.index(name), SURFACES.index(surface)):
                        for sensing, k in [(s, k) for s in self.sensing for k in self.error_scale]:
                            for loc in self.localization:
                                for strategy in self.strategies:
                                    kw = dict(
                                        object=name,
                                        surface=surface,
                                        seed=seed,
                                        strategy=strategy,
                                        obstacles=ob,
                                        sensing=sensing,
                                        localization=loc,
                                        max_time=self.max_time,
                                        max_wall_time=self.max_wall_time,
                                        placement_key=[seed, objects.index(name), SURFACES.index(surface)],
                                        error_scale=k,
                                    )
                                    label = sensing_label(sensing)
                                    key = search_key(strategy, ob, label, name, surface, seed, loc)
                                    key += scale_suffix(k)
                                    if self.survey_tour:  # its own jobs: a resume never mixes the two
                                        kw["survey_tour"], key = True, f"{key}_tour"
                                    if self.survey_once:  # the room surveyed once per seed, kept here
                                        kw["survey_once"], key = self.survey_once, f"{key}_surveyed"
                                    out.extend(self._moving_jobs(key, kw))
        return out

    def _obstacles(self, seed: int, i_object: int, i_surface: int) -> tuple[bool, ...]:
        """With and/or without the obstacle boxes at one placement (``half``: on every other one)."""
        choice = OBSTACLES[self.obstacles]
        return choice if choice is not None else ((seed + i_object + i_surface) % 2 == 1,)

    def _moving_jobs(self, key: str, kw: dict) -> list[Job]:
        """The job of a stationary object as it always was; for a moving one, one job per map."""
        if self.moving is None:
            return [Job(key, search_job, kw)]
        motion = dict(moving=self.moving, object_speed=self.object_speed, pause=self.pause)
        key = f"{key}_moving-{self.moving}"
        return [Job(f"{key}-{m}", search_job, {**kw, **motion, "map": m}) for m in self.maps]


def shortest_path_m(scene, place, local_max_m: float, local_min_m: float) -> float:
    """Length [m] of the shortest collision-free path from the robot's start to local-search range
    (``local_min_m`` .. ``local_max_m``) of the object at ``place``, on the scene's true occupancy (every
    body but posters and the object, and the walls) grown by the robot's radius: A* on a 5 cm grid.
    NaN when there is none. Evaluation only."""
    import numpy as np

    from lab.navigation import Costmap, GridSpec, astar_to_region
    from lab.robot import BaseLimits
    from lab.runs.placement import footprint

    sx, sy = scene.room.size
    spec = GridSpec.from_bounds(-sx / 2, -sy / 2, sx / 2, sy / 2, 0.05)
    X, Y = spec.cell_centers()
    pts = np.stack([X.ravel(), Y.ravel()], axis=1)
    occ = np.zeros(len(pts), bool)
    for b in scene.bodies:
        if b.role in ("decor", "object"):
            continue
        poly = footprint(b)  # convex: a cell is inside when it is on one side of every edge
        edges = np.roll(poly, -1, axis=0) - poly
        rel = pts[:, None, :] - poly[None, :, :]
        cross = edges[None, :, 0] * rel[:, :, 1] - edges[None, :, 1] * rel[:, :, 0]
        occ |= np.all(cross >= 0, axis=1) | np.all(cross <= 0, axis=1)
    occ = occ.reshape(spec.shape)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = True
    grid = Costmap.from_occupancy(spec, occ).inflated(BaseLimits().radius)
    rx, ry, _ = scene.robot_start
    path = astar_to_region(grid, (rx, ry), (place[0], place[1]), local_max_m, local_min_m)
    return float(path.length) if path.found else math.nan


def search_job(
    object: str,
    surface: str,
    seed: int,
    strategy: str,
    obstacles: bool,
    sensing: str,
    max_time: float,
    max_wall_time: float | None,
    placement_key: list[int],
    localization: str = "landmarks",
    moving: str | None = None,
    object_speed: float = 0.1,
    pause: float = 5.0,
    map: str = "static",
    error_scale: float = 1.0,
    survey_tour: bool = False,
    survey_once: str | None = None,
) -> dict:
    """One search trial in this worker process (its own PyBullet client): the ``lab search --json``
    result without its map snapshots, with ``shortest_path_m``; the profile's errors times
    ``error_scale``; with ``survey_tour``, a survey tour before the search
    (:func:`lab.runs.room.survey_the_room`); with ``survey_once`` (a folder), the room of ``seed`` surveyed
    once (:func:`stored_survey_for`) and the search started from it."""
    import numpy as np

    from lab.runs.moving import MovingOptions
    from lab.runs.placement import random_placement
    from lab.runs.search import navigator_factory, run_search
    from lab.scene import load_scene
    from lab.search.config import SearchAgentConfig
    from lab.sim.sensing import sensing_profile

    scene = load_scene("lab_room")
    place = random_placement(scene, object, np.random.default_rng(placement_key), surface)
    r = run_search(
        object,
        seed,
        place=place,
        strategy=strategy,
        max_time=max_time,
        navigate=navigator_factory,
        obstacles=obstacles,
        max_wall_time=max_wall_time,
        sensing=sensing_profile(sensing).scaled(error_scale),
        localization=localization,
        moving=None
        if moving is None
        else MovingOptions(moving, object_speed, pause, predict=map == "predict", surface=surface),
        survey_tour=survey_tour,
        survey=None if survey_once is None else stored_survey_for(survey_once, seed, sensing, error_scale),
    )
    d = r.to_json()
    d["n_snapshots"] = len(d.pop("map_snapshots", []))
    if moving is not None:
        d["truth_time_s"] = d["moving"]["truth_time_s"]
    d["obstacles_on_path"] = bool(obstacles)  # asked for (``obstacles`` lists the boxes that fit)
    std = d.get("pose_std") or {}
    d["std_position_m"], d["std_orientation_deg"] = std.get("position_m"), std.get("orientation_deg")
    lc = SearchAgentConfig().local_search
    sp = shortest_path_m(r.trace.scene, place, lc.max_distance_m, lc.min_distance_m)
    d["shortest_path_m"] = round(sp, 4) if math.isfinite(sp) else None
    return d


def stored_survey_for(folder: str, seed: int, sensing: str, error_scale: float) -> Path:
    """The room of episode ``seed`` under ``sensing`` x ``error_scale`` surveyed once (``lab survey``,
    :func:`lab.runs.survey.run_survey`), in ``folder``: made by the first job of that room to need it
    (under a lock, so that two workers do not both drive it), read by the others."""
    from filelock import FileLock

    from lab.eval.robustness import scale_suffix
    from lab.runs.survey import run_survey
    from lab.sim.sensing import sensing_profile

    path = Path(folder) / f"{sensing_label(sensing)}_s{seed}{scale_suffix(error_scale)}.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    with FileLock(f"{path}.lock"):
        if not path.is_file():
            run_survey(path, seed, sensing=sensing_profile(sensing).scaled(error_scale))
    return path


def spl(rows) -> float:
    """Success weighted by path length: the mean of ``S_i l_i / max(p_i, l_i)`` (``l_i`` the shortest
    path, ``p_i`` the driven one); NaN without rows."""
    vals = []
    for d in rows:
        lo, p = d.get("shortest_path_m"), d.get("path_length_m") or 0.0
        ok = d.get("success") and lo not in (None, "") and math.isfinite(float(lo))
        vals.append(float(lo) / max(float(p), float(lo), 1e-9) if ok else 0.0)
    return sum(vals) / len(vals) if vals else math.nan


def confidently_wrong(row, position_m: float = 0.05, orientation_deg: float = 10.0) -> bool:
    """Whether a found pose is confidently wrong (issue 52's acceptance): more than ``position_m`` [m] or
    ``orientation_deg`` [deg] off the truth while its stated deviation (``std_position_m``,
    ``std_orientation_deg``: the JSON's ``pose_std``) is under a third of its error. False when not
    found, without a truth, or without a stated deviation.

    >>> confidently_wrong({"found": True, "position_error_m": 0.06, "orientation_error_deg": 2.0,
    ...                    "std_position_m": 0.01, "std_orientation_deg": 1.0})
    True
    >>> confidently_wrong({"found": True, "position_error_m": 0.06, "orientation_error_deg": 2.0,
    ...                    "std_position_m": 0.03, "std_orientation_deg": 1.0})
    False
    """

    if str(row.get("found")) not in ("True", "true", "1"):
        return False
    return confidently_wrong_pose(row, position_m, orientation_deg)


def _median(xs) -> str:
    xs = [float(x) for x in xs if x not in (None, "")]
    return f"{statistics.median(xs):.1f}" if xs else "-"


SEARCH = SweepKind(
    name="search",
    schema="search",
    columns=(
        "key",
        "object",
        "surface",
        "strategy",
        "obstacles",
        "sensing",
        "localization",
        "seed",
        "max_time",
        "error_scale",
        "success",
        "found",
        "path_length_m",
        "shortest_path_m",
        "position_error_m",
        "orientation_error_deg",
        "std_position_m",
        "std_orientation_deg",
        "collisions",
        "odometry_error_m",
        "localization_error_m",
        "landmark_updates",
        "landmark_refinds",
        "global_searches",
        "local_searches",
        "sim_time_s",
        "wall_time_s",
        "reason",
        "error",
    ),
    params=(
        "object",
        "surface",
        "strategy",
        "obstacles",
        "sensing",
        "error_scale",
        "localization",
        "seed",
        "max_time",
    ),
    conditions=("strategy", "obstacles", "sensing", "localization"),
    medians=(
        ("found", lambda rs: str(sum(bool(r["found"]) for r in rs))),
        ("SPL", lambda rs: f"{spl(rs):.3f}"),
        ("median path m", lambda rs: _median(r["path_length_m"] for r in rs)),
        ("median sim s", lambda rs: _median(r["sim_time_s"] for r in rs)),
        ("collisions", lambda rs: str(sum(int(r["collisions"] or 0) for r in rs))),
        ("confidently wrong", lambda rs: str(sum(confidently_wrong(r) for r in rs))),
    ),
    state=lambda res: (
        f"success {res['success']} (found {res['found']}), path {res['path_length_m']:.1f} m, "
        f"{res['sim_time_s']:.1f} s sim: {res['reason']}"
    ),
)

#: ``lab eval search --moving``: the same sweep, its rows grouped by the motion, the map and the surface
#: (the floor, a table's top) as well.
SEARCH_MOVING = replace(
    SEARCH,
    columns=(
        *SEARCH.columns[:-2],
        "moving",
        "map",
        "object_speed",
        "pause",
        "truth_time_s",
        *SEARCH.columns[-2:],
    ),
    params=(*SEARCH.params, "moving", "map", "object_speed", "pause"),
    conditions=("moving", "map", "surface", *SEARCH.conditions),
)
