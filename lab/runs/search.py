"""One search trial, end to end: build the world, place the object, search, and score against truth.

:func:`run_search` is what ``lab search`` runs; :meth:`SearchResult.to_json` is exactly what it writes
(the fields of the ``lab search`` contract in ``design.md``, and more). The agent never sees the truth:
the object's true pose, the collision count and the errors are filled in here, after the run.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from lab.errors import ConfigError
from lab.geometry import R_to_euler_zyx, se3_inv
from lab.navigation.astar import astar_to_region
from lab.navigation.drive_loop import NavOutcome
from lab.navigation.grid import GridSpec
from lab.navigation.localization import LocalizationMode, LocalizedRobot
from lab.navigation.navigator import Navigator
from lab.robot import Robot
from lab.runs.placement import (
    check_placement,
    circle_polygon,
    footprint,
    polygon_inside,
    polygons_overlap,
    random_placement,
    searchable_objects,
    supports,
)
from lab.runs.robots import make_robot
from lab.scene import BodySpec, Scene, load_scene
from lab.search.agent import AgentConfig, AgentResult, NavigationResult, SearchAgent, SearchEvent, Strategy
from lab.search.budget import BudgetedRobot
from lab.search.probability_map import ProbabilityMap
from lab.training.landmarks import trained_landmark_map
from lab.training.search import search_database
from lab.vision.database import FeatureDatabase

__all__ = [
    "SearchResult",
    "SearchTrace",
    "map_spec",
    "navigator_factory",
    "outcome_in_words",
    "path_obstacles",
    "pose_errors",
    "run_search",
]

#: Success, as the acceptance counts it: found, within 5 cm and 10 degrees of the truth.
SUCCESS_POSITION_M = 0.05
SUCCESS_ORIENTATION_DEG = 10.0

NavigatorFactory = Callable[[Robot, GridSpec], Callable]


def map_spec(scene: Scene, resolution: float = 0.2) -> GridSpec:
    """The probability map's grid: the room's floor in ``resolution`` cells (the paper's 20 cm)."""
    if scene.room is None:
        raise ConfigError(f"scene {scene.name!r} has no room to search")
    sx, sy = scene.room.size
    return GridSpec.from_bounds(-sx / 2, -sy / 2, sx / 2, sy / 2, resolution)


def pose_errors(G_est: np.ndarray, G_true: np.ndarray) -> tuple[float, float]:
    """Position error [m] and orientation error [deg] (the angle of ``R_est^T R_true``)."""
    pe = float(np.linalg.norm(G_est[:3, 3] - G_true[:3, 3]))
    R = G_est[:3, :3].T @ G_true[:3, :3]
    oe = math.degrees(math.acos(float(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))))
    return pe, oe


def _pose_dict(G: np.ndarray) -> dict:
    return {
        "position_m": [round(float(v), 5) for v in G[:3, 3]],
        "euler_zyx_deg": [round(math.degrees(float(v)), 4) for v in R_to_euler_zyx(G[:3, :3])],
    }


def path_obstacles(
    scene: Scene, name: str, place, rng: np.random.Generator, n: int = 2, size=(0.3, 0.3, 0.5)
) -> tuple[Scene, list[tuple[float, float, float, float]]]:
    """Put ``n`` boxes on the straight line from the robot's start to the object (the "obstacles placed
    in the planned path" of the paper's second set of trials).

    Each box goes at a random point along the middle of the line (jittered sideways by up to 15 cm),
    clear of other bodies by 0.35 m, at least 0.8 m from the start and 1.0 m from the object, so the
    robot can still get past and stand near the object. Boxes that find no such spot are left out.
    """
    rx, ry, _ = scene.robot_start
    ox, oy = float(place[0]), float(place[1])
    length = math.hypot(ox - rx, oy - ry)
    room = supports(scene)[0].polygon
    out_bodies, poses = list(scene.bodies), []
    ux, uy = ((ox - rx) / length, (oy - ry) / length) if length > 1e-9 else (1.0, 0.0)
    for k in range(n):
        for _ in range(200):
            s = rng.uniform(0.8, max(0.8, length - 1.0))
            lat = rng.uniform(-0.15, 0.15)
            x, y = rx + s * ux - lat * uy, ry + s * uy + lat * ux
            yaw = float(rng.uniform(0, 90))
            body = BodySpec(
                f"obstacle_{k + 1}", "box", tuple(size), (x, y, 0.0, yaw), "obstacle", (0.45, 0.4, 0.35)
            )
            fp = footprint(body)
            if not polygon_inside(footprint(body, 0.35), room):
                continue
            if any(polygons_overlap(fp, footprint(b, 0.35)) for b in out_bodies if b.role != "decor"):
                continue
            near_start = polygons_overlap(fp, circle_polygon(rx, ry, 0.6))
            if near_start or polygons_overlap(fp, circle_polygon(ox, oy, 1.0)):
                continue
            out_bodies.append(body)
            poses.append((x, y, 0.0, yaw))
            break
    return replace(scene, bodies=tuple(out_bodies)), poses


@dataclass(frozen=True)
class SearchTrace:
    """Everything a trial recorded beyond the JSON (for the figures): the agent's record, the map's grid,
    the odometry trajectory ``(t, x, y, theta)``, the world's scene and the database the agent searched
    with."""

    agent: AgentResult = field(repr=False)
    spec: GridSpec = field(repr=False)
    trajectory: np.ndarray = field(repr=False)
    scene: Scene = field(repr=False)
    db: FeatureDatabase | None = field(default=None, repr=False)


@dataclass(frozen=True)
class SearchResult:
    """The outcome of one trial: the ``lab search`` JSON fields, and the trace for the figures.

    Attributes
    ----------
    object : str
    found : bool
        The agent's claim.
    true_pose, estimated_pose : dict or None
        ``{"position_m": [x, y, z], "euler_zyx_deg": [alpha, beta, gamma]}`` of the object frame O in
        the world (the estimate in the odometry frame, which the run started aligned with).
    position_error_m, orientation_error_deg : float or None
        Against the truth (None when not found).
    path_length_m : float
        Distance driven, from odometry.
    global_searches, local_searches : int
    collisions : int
        Bumps, from the simulator's truth.
    sim_time_s, wall_time_s : float [s]
    seed : int
    strategy : str
    success : bool
        Found within :data:`SUCCESS_POSITION_M` and :data:`SUCCESS_ORIENTATION_DEG`.
    reason : str
        Why the run ended.
    place : tuple of 4 floats
        The object's placement ``(x, y, z_underside, yaw_deg)``.
    surface : str
        floor, table or shelf.
    obstacles : tuple
        Placements of the extra obstacles (``--obstacles``).
    camera_frame_error : dict or None
        ``{"position_m", "orientation_deg"}``: the estimate's error in the camera frame at detection
        (the local search's own error; ``position_error_m`` adds the odometry's drift to it).
    odometry_error_m : float
        Distance between the odometry's and the true robot position at the end of the run.
    localization_error_m : float
        Distance between the robot's pose estimate (odometry alone, or localized against the room's
        landmarks) and the true robot position at the end of the run.
    localization : str
        ``odometry`` or ``landmarks`` (:mod:`lab.navigation.localization`).
    landmark_updates : int
        Landmark observations the localizer used (0 with landmarks: it fell back to odometry alone,
        and ``localization_note`` says so).
    localization_note : str or None
    events : tuple of SearchEvent
    trace : SearchTrace
    recording : str or None
        The animation written (``record``): one frame per event.
    sensing : str
        The simulator's sensing profile the trial ran under.
    """

    object: str
    found: bool
    true_pose: dict
    estimated_pose: dict | None
    position_error_m: float | None
    orientation_error_deg: float | None
    path_length_m: float
    global_searches: int
    local_searches: int
    collisions: int
    sim_time_s: float
    wall_time_s: float
    seed: int
    strategy: str
    success: bool
    reason: str
    place: tuple[float, float, float, float]
    surface: str
    obstacles: tuple = ()
    camera_frame_error: dict | None = None
    odometry_error_m: float = 0.0
    localization_error_m: float = 0.0
    localization: str = "odometry"
    landmark_updates: int = 0
    localization_note: str | None = None
    events: tuple[SearchEvent, ...] = field(default=(), repr=False)
    trace: SearchTrace | None = field(default=None, repr=False, compare=False)
    recording: str | None = None
    sensing: str = "ideal"

    def to_json(self) -> dict:
        """The JSON ``lab search --json`` writes (plain types only)."""
        snaps = [] if self.trace is None else self.trace.agent.snapshots
        return {
            "object": self.object,
            "found": bool(self.found),
            "true_pose": self.true_pose,
            "estimated_pose": self.estimated_pose,
            "position_error_m": self.position_error_m,
            "orientation_error_deg": self.orientation_error_deg,
            "path_length_m": round(float(self.path_length_m), 4),
            "global_searches": int(self.global_searches),
            "local_searches": int(self.local_searches),
            "collisions": int(self.collisions),
            "sim_time_s": round(float(self.sim_time_s), 3),
            "wall_time_s": round(float(self.wall_time_s), 3),
            "seed": int(self.seed),
            "strategy": self.strategy,
            "success": bool(self.success),
            "reason": self.reason,
            "place": [round(float(v), 4) for v in self.place],
            "surface": self.surface,
            "obstacles": [[round(float(v), 4) for v in o] for o in self.obstacles],
            "camera_frame_error": self.camera_frame_error,
            "odometry_error_m": round(float(self.odometry_error_m), 4),
            "localization_error_m": round(float(self.localization_error_m), 4),
            "localization": self.localization,
            "landmark_updates": int(self.landmark_updates),
            "localization_note": self.localization_note,
            "events": [e.as_dict() for e in self.events],
            "recording": self.recording,
            "sensing": self.sensing,
            "map_snapshots": [
                {
                    "t": round(s.t, 3),
                    "label": s.label,
                    "cell": None if s.cell is None else list(s.cell),
                    "max_p": float(s.P.max()),
                }
                for s in snaps
            ],
        }


def run_search(
    object: str,
    seed: int,
    place=None,
    strategy: str | Strategy = "paper",
    max_time: float = 600.0,
    navigate: NavigatorFactory | None = None,
    *,
    obstacles: bool = False,
    world: str | Scene = "lab_room",
    config: AgentConfig | None = None,
    supersample: int = 2,
    max_wall_time: float | None = None,
    progress: bool = False,
    record=None,
    attach: Callable | None = None,
    sensing="realistic",
    localization="odometry",
) -> SearchResult:
    """Run one search trial in the simulator and score it: the :class:`SearchResult`.

    Parameters
    ----------
    object : str
        A searchable object (:func:`lab.runs.placement.searchable_objects`).
    seed : int
        Seeds the placement (when ``place`` is None), the obstacles, the sensor errors and RANSAC.
    place : (x, y, z_underside, yaw_deg), optional
        Where to put the object (checked: in the room, on a surface, clear of the other bodies and the
        robot). Default: a seeded random valid placement.
    strategy : {"paper", "lawnmower", "frontier"}; max_time, max_wall_time : float [s]
        Simulated-time budget (the run ends "not found" when it is used up); and, optionally, wall time.
    navigate : callable ``(robot, spec) -> navigate``
        Required: the navigation callable (:mod:`lab.search.agent`) for the budgeted robot and the
        map's grid (:func:`navigator_factory`).
    obstacles : bool
        Add boxes on the straight line from the start to the object (:func:`path_obstacles`).
    world, config, supersample :
        The scene; the agent's config (its ``strategy`` replaced); render supersampling (2: twice the
        SIFT matches on the small objects as 1).
    progress, record, attach :
        Say when a database is built; write an animation of the live view (one frame per event);
        ``attach(agent)`` before the run (a notebook's ``LiveView.for_search(agent).widget``).
    sensing : str or mapping
        The sensing profile (:func:`lab.sim.sensing.sensing_profile`; default realistic).
    localization : {"landmarks", "odometry"}
        Where the robot's pose comes from (:class:`lab.navigation.localization.LocalizedRobot`): the
        odometry corrected by the room's posters, or odometry alone (default, until the localizer's effect
        on the search is measured).
    """
    wall0 = time.perf_counter()
    strategy = Strategy.parse(strategy)
    scene = world if isinstance(world, Scene) else load_scene(world)
    recorder = _check_trial(scene, object, navigate, max_time, record)
    mode = LocalizationMode.parse(localization)
    landmarks = trained_landmark_map(scene, progress=progress) if mode is LocalizationMode.LANDMARKS else None
    rng = np.random.default_rng(seed)
    scene, place, surface, obstacle_poses = _place_object(scene, object, place, obstacles, rng)
    db = search_database(object, progress=progress)
    cfg = replace(config or AgentConfig(), strategy=strategy)
    spec = map_spec(scene)
    from lab.sim import RenderSettings, SimWorld

    with (
        SimWorld(scene, RenderSettings(supersample=supersample)) as w,
        make_robot(world=w, seed=seed, sensing=sensing) as run,
    ):
        robot = LocalizedRobot(run.robot, mode, landmarks, rng=np.random.default_rng([seed, 20]))
        hook = _with_progress(attach) if progress else attach
        parts = (db, navigate, spec, cfg, seed, recorder, hook, (max_time, max_wall_time))
        out, truth, budget, odom = _search(robot, w, object, *parts)
        profile = run.sensing
        estimate = robot.pose_estimate()
    note = None
    if mode is LocalizationMode.LANDMARKS and estimate.n_updates == 0:
        note = "no landmark was seen: the pose is odometry alone"
        print(f"lab: localization: {note}", file=sys.stderr)
    return SearchResult(
        **_scored(object, out, truth, odom),
        localization_error_m=math.hypot(
            estimate.pose.x - truth.robot_pose.x, estimate.pose.y - truth.robot_pose.y
        ),
        localization=mode.value,
        landmark_updates=estimate.n_updates,
        localization_note=note,
        path_length_m=budget.path_length_m,
        global_searches=out.global_searches,
        local_searches=out.local_searches,
        sim_time_s=truth.sim_time_s,
        wall_time_s=time.perf_counter() - wall0,
        seed=int(seed),
        strategy=strategy.value,
        place=place,
        surface=surface,
        obstacles=tuple(obstacle_poses),
        events=out.events,
        trace=SearchTrace(out, spec, np.array(budget.trajectory), scene, db),
        recording=None if recorder is None or (p := recorder.close()) is None else str(p),
        sensing=profile,
    )


def _search(robot, w, object, db, navigate, spec, cfg, seed, recorder, attach, budgets):
    """The agent's run on the enabled robot within the time budgets (sim, wall), with the truth behind
    it read once it has ended: returns the agent's result, the truth, the budgeted robot and its
    odometry at the end."""
    robot.enable()
    budget = BudgetedRobot(robot, *budgets)
    nav = _relocalizing(navigate(budget, spec), robot)
    agent = SearchAgent(budget, db, nav, ProbabilityMap(spec), cfg, rng=np.random.default_rng([seed, 1]))
    if recorder is not None:
        from lab.viz.live import LiveView

        LiveView.for_search(agent, rate_hz=None, recorder=recorder, widget=False)
    if attach is not None:
        attach(agent)
    out = agent.run()
    out = _relocalized_find(out, robot)
    truth = _TrialTruth(
        G_WO=w.truth.G_W(object),
        G_WC=w.truth.G_WC(),  # the head has not moved since the last frame of a found track
        robot_pose=w.truth.robot_pose(),
        collisions=int(w.truth.collisions),
        sim_time_s=robot.now(),
    )
    return out, truth, budget, robot.base.odometry()


def _relocalizing(navigate, robot: LocalizedRobot):
    """Active re-localization before every drive: when the pose is uncertain, look for a landmark first."""

    def go(*args, **kwargs):
        robot.relocalize()
        return navigate(*args, **kwargs)

    for k, v in vars(navigate).items():  # keep what the callable carries (its navigator, for figures)
        setattr(go, k, v)
    return go


def _relocalized_find(out: AgentResult, robot: LocalizedRobot) -> AgentResult:
    """Active re-localization before reporting a found object: the object's pose relative to the robot
    stays; its world pose follows the corrected robot pose ``G_WO' = G_WR' G_WR^-1 G_WO``."""
    if not out.found or out.G_WO is None or robot.mode is not LocalizationMode.LANDMARKS:
        return out
    before = robot.odometry()
    if robot.certain():
        return out
    robot.relocalize()
    after = robot.odometry()
    return replace(out, G_WO=after.G() @ se3_inv(before.G()) @ out.G_WO)


def _scored(object: str, out: AgentResult, truth: _TrialTruth, odom) -> dict:
    """The result's fields that compare the run with the truth: pose errors in W and in the camera
    frame C (the perception error alone, without the odometry's drift), success, odometry error."""
    pe = oe = cam = None
    if out.found:
        pe, oe = pose_errors(out.G_WO, truth.G_WO)
        cpe, coe = pose_errors(out.local.estimate.G_CO, se3_inv(truth.G_WC) @ truth.G_WO)
        cam = {"position_m": round(cpe, 5), "orientation_deg": round(coe, 3)}
    return {
        "object": object,
        "found": out.found,
        "true_pose": _pose_dict(truth.G_WO),
        "estimated_pose": None if out.G_WO is None else _pose_dict(out.G_WO),
        "position_error_m": None if pe is None else round(pe, 5),
        "orientation_error_deg": None if oe is None else round(oe, 3),
        "collisions": truth.collisions,
        "success": bool(out.found and pe <= SUCCESS_POSITION_M and oe <= SUCCESS_ORIENTATION_DEG),
        "reason": out.reason,
        "camera_frame_error": cam,
        "odometry_error_m": math.hypot(odom.x - truth.robot_pose.x, odom.y - truth.robot_pose.y),
    }


def progress_line(event: SearchEvent) -> str:
    """One decision of the search, for the console: ``lab search: t =  27.8 s  local (4, 13): found...``."""
    where = "" if event.cell is None else f" {tuple(event.cell)}"
    return f"lab search: t = {event.t:6.1f} s  {event.kind}{where}: {event.detail}"


def _with_progress(attach):
    """An ``attach`` hook that also prints every event of the agent to stderr as it happens (after any
    observer the recorder or ``attach`` set, which it keeps)."""

    def hook(agent) -> None:
        if attach is not None:
            attach(agent)
        before = agent.observer

        def observer(a, event) -> None:
            if before is not None:
                before(a, event)
            print(progress_line(event), file=sys.stderr, flush=True)

        agent.observer = observer

    return hook


def outcome_in_words(data: dict) -> str:
    """What a ``lab search`` result (its JSON fields) means, in one line for the console: found or
    not, and whether it counts as a success against the truth, with the limit that it missed.

    >>> outcome_in_words({"found": True, "success": False, "position_error_m": 0.083,
    ...                   "orientation_error_deg": 2.0, "reason": "found"})
    'found, but 8.3 cm from the true position: the limit is 5 cm'
    """
    if not data.get("found"):
        return f"not found: {data.get('reason') or 'no reason recorded'}"
    pe, oe = data.get("position_error_m"), data.get("orientation_error_deg")
    if pe is None or oe is None:
        return "found (no true pose to score it against)"
    misses = []
    if pe > SUCCESS_POSITION_M:
        misses.append(
            f"{100 * pe:.1f} cm from the true position: the limit is {100 * SUCCESS_POSITION_M:.0f} cm"
        )
    if oe > SUCCESS_ORIENTATION_DEG:
        misses.append(
            f"{oe:.1f} deg off the true orientation: the limit is {SUCCESS_ORIENTATION_DEG:.0f} deg"
        )
    if misses:
        return "found, but " + "; and ".join(misses)
    return (
        f"found and a success: {100 * pe:.1f} cm and {oe:.1f} deg from the true pose "
        f"(limits {100 * SUCCESS_POSITION_M:.0f} cm, {SUCCESS_ORIENTATION_DEG:.0f} deg)"
    )


@dataclass(frozen=True)
class _TrialTruth:
    """The simulator's truth at the end of a trial: for scoring only."""

    G_WO: np.ndarray  # the object in W
    G_WC: np.ndarray  # the camera in W at the last frame
    robot_pose: object  # Pose2D of the base
    collisions: int
    sim_time_s: float


def _check_trial(scene: Scene, object: str, navigate, max_time, record):
    """One clear error for an unknown object, a missing navigator, a bad time budget or a bad recording
    path, before anything is built; returns the recorder (None without ``record``)."""
    names = searchable_objects(scene)
    if object not in names:
        raise ConfigError(f"unknown object {object!r}; searchable objects: {', '.join(names)}")
    if navigate is None:
        raise ConfigError(
            "run_search needs a navigator: navigate=lambda robot, spec: <callable(target_xy, min_d, max_d)>"
        )
    if not (isinstance(max_time, (int, float)) and math.isfinite(max_time) and max_time > 0):
        raise ConfigError(f"max_time must be a finite number of seconds > 0, got {max_time!r}")
    if record is None:
        return None
    from lab.viz.recorder import Recorder

    return Recorder(record)


def _place_object(scene: Scene, object: str, place, obstacles: bool, rng: np.random.Generator):
    """Put the object at ``place`` (checked) or at a seeded random valid spot, and the path's obstacles:
    returns the scene, the placement, its surface and the obstacles' poses."""
    if place is None:
        place = random_placement(scene, object, rng)
    surface = check_placement(scene, object, place).kind
    place = tuple(float(v) for v in place)
    scene = scene.with_pose(object, place)
    obstacle_poses: list = []
    if obstacles:
        scene, obstacle_poses = path_obstacles(scene, object, place, rng)
    return scene, place, surface, obstacle_poses


# --- the navigation the search drives with -----------------------------------------------------------


def navigator_factory(robot, spec, timeout_s: float = 120.0):
    """``navigate`` for :func:`run_search`: scan once, then ``go_near`` each target.

    The navigator's workspace is the floor the map ``spec`` covers (the scene's room). The returned
    callable keeps its :class:`~lab.navigation.Navigator` as ``navigate.navigator`` (its costmap is what
    ``lab search --out`` draws under the trajectory). Each outcome carries the path A* plans first on the
    current costmap (``path_xy``, for the figures; the navigator replans on the way).
    """
    x0, x1, y0, y1 = (round(v, 9) for v in spec.extent)  # 30 x 0.2 m is 6.000000000000001 m
    nav = Navigator(robot, bounds=(x0, y0, x1, y1))
    state = {"scanned": False}

    def navigate(target_xy, min_distance: float, max_distance: float) -> NavigationResult:
        if not state["scanned"]:
            nav.scan()
            state["scanned"] = True
        first = astar_to_region(nav.planning_grid(), robot.odometry(), target_xy, max_distance, min_distance)
        r = nav.go_near(target_xy, min_distance, max_distance, timeout=timeout_s)
        arrived = r.outcome is NavOutcome.ARRIVED
        path = first.points_xy if first.found else None
        return NavigationResult(arrived, r.reason or r.outcome.name, r.pose, path)

    navigate.navigator = nav
    return navigate
