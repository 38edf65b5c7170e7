r"""The navigation loop on a robot: stereo frames -> costmap -> A* -> pure pursuit, replanning as it goes.

The object-search paper's navigation mode (Sec. III-D and Fig. 4), on any :class:`lab.robot.Robot`::

    observe(frame):  dense disparity -> points_C --G_WC = G_WR(odom) G_RC(pan, tilt)--> points_W
                     -> ground plane (RANSAC, refitted per view, gated) -> Costmap.integrate
    scan():          the head tilted down, a sweep of pan angles, observe() at each
    go_to(goal):     A* on the inflated costmap -> PathFollower via drive_to; every frame_period
                     seconds the head looks along the path ahead, observe(), and the Replanner plans
                     again when the path ahead crosses a (grown) obstacle
    go_near(target): the same towards any cell at a distance band from a target, then face it
                     (both run a :class:`~lab.navigation.drive_loop.DriveLoop`, step by step)

The navigator sees only what the robot gives every algorithm: stereo frames with their pan-tilt state
and odometry, and odometry. Poses are odometry poses in the world frame W (``docs/conventions.md``); its
drift is not corrected here, so the map and the arrival are as good as odometry.

Choices, with the measurements behind them (lab room, 320 x 240 px, 0.12 m baseline, f = 208 px,
StereoSGBM with 64 disparities; ``benchmarks/bench_navigation.py`` measures the stereo error again):

* **Range.** Dense stereo's depth error grows as :math:`\sigma_Z = Z^2 \sigma_d / (f b)`. Against the
  simulator's depth buffer over 45 views, the 90th percentile of a point's horizontal position error is
  3.5 cm at 1-1.5 m, 10 cm (one cell) at 2-2.5 m, 15 cm at 2.5-3 m and 26 cm at 3.5-4 m, where gross
  errors (> 0.2 m in depth) reach 14 % of the points. A face's points then spill into the cells in
  front of it: after a scan, the share of obstacle cells within one cell of a true obstacle was 0.99
  with points up to 2.0 m, 0.92 up to 2.5 m and 0.91 up to 3.0 m (means over 7 scans; single scans
  down to 0.83 beyond 2 m). Points are used up to ``max_range = 2.0`` m, along the optical axis and on
  the floor; the robot drives at 0.5 m/s and looks every 0.5 s, so it still sees an obstacle 1.5 m
  before it gets there.
* **Checked disparity.** :func:`~lab.vision.dense.checked_disparity` pads the pair to match the full
  image width (plain StereoSGBM leaves its 64 leftmost columns empty, a fifth of the view) and keeps a
  disparity only when the right image's disparity agrees. Mismatches in weak texture next to a near
  surface put points at the near surface's depth in front of a far wall, i.e. false obstacles in front
  of the robot; the check halves those (measured: points placed over 0.5 m too near, from 0.42 % to
  0.23 % of the points within 2 m) and, in trials, the goals given up as blocked (3 of 40 to 0 of 40).
* **Nothing below the floor.** With 64 disparities nothing nearer than ``f b / 63 = 0.40`` m can be
  matched; a surface nearer than that (the robot passing close to a crate) aliases to a wrong, smaller
  disparity, i.e. to points farther along the ray, which point down: below the floor. Labelled as
  holes (the costmap's ``drop_depth``) they planted false obstacles behind nearby boxes, so points
  below the floor are ignored (``drop_depth=None``; the lab has no steps, and the real base has cliff
  sensors).
* **Support by surface area.** A view votes OBSTACLE for a cell only when its obstacle points cover
  ``min_obstacle_area`` (10 cm^2) of surface there, each point standing for ``(step Z / f)^2``. At
  2 m that is the costmap's 3 points; at 0.5 m it is about 40, so a few stray matches at a depth
  discontinuity close to the camera (a table's top edge against the far wall) no longer block the goal
  in front of it.
* **Tilt.** The head looks down 25 degrees while driving and scanning (the paper tilts it down to see
  more floor): with a 60 degree vertical field of view the image spans 55 degrees below to 5 degrees
  above the horizon, so the floor is seen from about 0.5 m in front of the robot and the edges of table
  tops at the camera's height are still in view.
* **Ground plane.** Fitted to each view's points within ``ground_fit_range`` by
  :func:`~lab.navigation.ground.fit_ground_plane`. A fit is accepted when it is within
  ``plane_max_tilt`` of horizontal and within ``plane_max_jump`` of the previous plane under the
  camera; otherwise (a view of a wall, of a table's top edge) the previous plane is kept. A view before
  any plane was accepted is skipped. Measured fits: offsets within 2 cm, tilts below 0.4 degrees.
* **Deciding "no path" near, not far.** Stereo noise fattens faces by up to two cells at 2 m, enough
  to block a goal 0.4 m from a wall when seen from afar. When replanning finds no path while driving,
  the robot keeps to its old path while its next ``confirm_range`` metres are clear and gives up only
  when the blockage is that close. A goal inside the grown obstacles that the footprint itself fits
  (``goal_approach``) is reached by planning to the nearest open cell and driving the rest straight.
* **Arrival.** The follower's tolerances (6 cm, 6 degrees on odometry; it aims at half) leave room for
  odometry drift within the 10 cm / 10 degrees the robot must reach on its true pose.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from lab.errors import ConfigError
from lab.geometry import Pose2D, transform_points
from lab.navigation.astar import heading_towards
from lab.navigation.costmap import CellState, CostGrid, Costmap, CostmapConfig, CostmapUpdate
from lab.navigation.drive_loop import DriveLoop, NavResult, NearTarget, ToGoal, check_timeout
from lab.navigation.grid import GridSpec, check_finite_xy
from lab.navigation.ground import GroundPlane, NoGroundPlane, fit_ground_plane
from lab.navigation.paths import nearest_index, point_ahead
from lab.robot import Robot, StereoFrame
from lab.vision.dense import dense_points

__all__ = [
    "Navigator",
    "NavigatorConfig",
    "Observation",
    "ScanResult",
]

#: Height of the stereo head above its pan-tilt axes [m]: the top of the robot is ``mount_R[2]`` plus this.
HEAD_HEIGHT_M = 0.15


@dataclass(frozen=True)
class NavigatorConfig:
    """Settings of the navigation loop (see the module docstring for how the defaults were chosen).

    Attributes
    ----------
    resolution : float [m]
        Costmap cell size when the navigator builds its own grid (the paper: 0.10 m).
    margin : float [m]
        The default grid covers the bounds plus this margin on every side (the walls and a bit beyond).
    costmap : CostmapConfig
        Height bands and evidence rule; its ``max_range`` [m] is the floor distance from the camera
        beyond which points are ignored.
    max_range : float [m]
        Dense points deeper than this along the optical axis are dropped.
    pixel_step : int
        Dense points are taken every ``pixel_step`` pixels in both directions.
    lr_check : bool
        Use :func:`~lab.vision.dense.checked_disparity` (full image width, left-right consistent).
    min_obstacle_area : float [m^2]
        A view votes OBSTACLE for a cell only if its obstacle points there cover at least this much
        surface (see :meth:`Navigator._supported`); 0 leaves it to the point count alone.
    ground_fit_range : float [m]
        Points up to this depth are used to fit the ground plane.
    plane_max_tilt : float [rad]
        A fitted plane tilted more than this is refused.
    plane_max_jump : float [m]
        A fitted plane whose height under the camera differs by more than this from the previous one's
        is refused (the previous plane is kept), unless three level fits in a row disagree with it.
    tilt : float [rad]
        Tilt of the head while driving and scanning (negative: looking down).
    scan_pans : tuple of float [rad]
        Pan angles of :meth:`Navigator.scan`: 7 views 50 degrees apart cover all around the robot with a
        75 degree horizontal field of view.
    look_ahead : float [m]
        While driving, the head pans towards the point this far ahead along the path.
    frame_period : float [s]
        Robot time between stereo frames (and replanning checks) while driving.
    control_dt : float [s]
        Control period of the path follower.
    inflation_margin : float [m] or None
        Obstacles are grown by the robot's radius plus this (None: one cell, see
        :meth:`Costmap.inflated`).
    goal_tolerance_xy : float [m]
    goal_tolerance_theta : float [rad]
        The path follower's arrival tolerances on the odometry pose (it aims at half of them). Tighter
        than the usual 0.1 m / 10 degrees, leaving room for the odometry's drift when the true pose
        must be within those.
    goal_approach : float [m]
        When a :meth:`Navigator.go_to` goal lies in the grown obstacles (the map's obstacles are grown
        by more than the robot's radius, and stereo noise fattens them by about a cell) but the
        footprint fits there, A* plans to the nearest open cell within this distance of the goal and
        the robot drives the rest straight. 0 disables it (such goals give GOAL_IN_OBSTACLE).
    goal_clearance : float [m]
        On that last stretch the footprint must keep this far from every obstacle cell.
    confirm_range : float [m]
        When replanning finds no path while driving (the goal looks blocked, or unreachable), the robot
        keeps to its old path as long as the next ``confirm_range`` metres of it are clear, and gives up
        only when the blockage is that close: the far cells of the map come from noisy far views that
        nearer views may clear.
    unknown_cost : float
        A* cost multiplier of unknown cells (``inf``: plan through seen floor only).
    clearance, clearance_cost : float
        The band beyond the grown obstacles in which cells cost more (see :meth:`Costmap.inflated`).
    seed : int
        Seeds the RANSAC ground-plane fits.
    """

    resolution: float = 0.1
    margin: float = 0.5
    costmap: CostmapConfig = CostmapConfig(max_range=2.0, drop_depth=None)
    max_range: float = 2.0
    pixel_step: int = 2
    lr_check: bool = True
    min_obstacle_area: float = 0.001
    ground_fit_range: float = 2.0
    plane_max_tilt: float = math.radians(3.0)
    plane_max_jump: float = 0.05
    tilt: float = math.radians(-25.0)
    scan_pans: tuple[float, ...] = tuple(math.radians(a) for a in (-150, -100, -50, 0, 50, 100, 150))
    look_ahead: float = 1.2
    frame_period: float = 0.5
    control_dt: float = 0.05
    inflation_margin: float | None = None
    goal_tolerance_xy: float = 0.06
    goal_tolerance_theta: float = math.radians(6.0)
    goal_approach: float = 0.3
    goal_clearance: float = 0.05
    confirm_range: float = 1.2
    unknown_cost: float = 2.0
    clearance: float = 0.2
    clearance_cost: float = 2.0
    seed: int = 0

    def __post_init__(self):
        for name in (
            "resolution",
            "max_range",
            "ground_fit_range",
            "look_ahead",
            "frame_period",
            "control_dt",
        ):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ConfigError(f"NavigatorConfig.{name} must be a finite number > 0, got {v!r}")
        if not (math.isfinite(self.margin) and self.margin >= 0):
            raise ConfigError(f"NavigatorConfig.margin must be >= 0 m, got {self.margin!r}")
        if int(self.pixel_step) != self.pixel_step or self.pixel_step < 1:
            raise ConfigError(f"NavigatorConfig.pixel_step must be an integer >= 1, got {self.pixel_step!r}")
        if self.frame_period < self.control_dt:
            raise ConfigError("NavigatorConfig.frame_period must be at least one control_dt")
        if not self.scan_pans or not all(math.isfinite(a) for a in self.scan_pans):
            raise ConfigError("NavigatorConfig.scan_pans must be finite angles [rad]")
        if self.inflation_margin is not None and not self.inflation_margin >= 0:
            raise ConfigError(f"inflation_margin must be >= 0 m or None, got {self.inflation_margin!r}")


@dataclass(frozen=True, eq=False)
class Observation:
    """What one stereo frame did.

    Attributes
    ----------
    t : float [s]
        Capture time of the frame.
    n_points : int
        Dense points within ``max_range`` in the frame.
    plane : GroundPlane or None
        The plane the points were labelled with (None: the view was skipped, see ``skipped``).
    plane_refit : bool
        The plane was fitted to this view (False: a previous plane was reused).
    update : CostmapUpdate or None
        What the view changed in the costmap (None when skipped).
    skipped : str or None
        Why the view was not integrated.
    """

    t: float
    n_points: int
    plane: GroundPlane | None
    plane_refit: bool
    update: CostmapUpdate | None = field(default=None, repr=False)
    skipped: str | None = None


@dataclass(frozen=True, eq=False)
class ScanResult:
    """A pan sweep: one :class:`Observation` per pan angle, and the robot time it took [s]."""

    observations: tuple[Observation, ...]
    elapsed_s: float

    @property
    def new_obstacle_cells(self) -> int:
        return sum(len(o.update.new_obstacles) for o in self.observations if o.update is not None)


class Navigator:
    """Drive a robot to goals on a costmap it builds from its own stereo frames (module docstring).

    Parameters
    ----------
    robot : Robot
        Enabled. The navigator commands its base and its head.
    spec : GridSpec, optional
        The costmap's grid. Default: ``bounds`` plus ``config.margin`` at ``config.resolution``.
    config : NavigatorConfig, optional
    bounds : (x_min, y_min, x_max, y_max) [m], optional
        The workspace, required when ``spec`` is not given: the world's floor, read from its scene
        (:func:`~lab.navigation.grid.room_bounds` of :func:`lab.scene.load_scene`'s result).

    The costmap's ``robot_height`` is raised to the top of the robot's head (the pan-tilt axes,
    ``camera.mount_R``, plus :data:`HEAD_HEIGHT_M`) when the configured one is lower: the lab room's
    robot carries its head at 1.1 m, and a board at 1.1-1.2 m is something it would hit.

    Attributes
    ----------
    costmap : Costmap
        The map built so far (for plots and tests; :meth:`planning_grid` is what A* searches).
    plane : GroundPlane or None
        The last accepted ground plane.
    radius : float [m]
        Obstacles are grown by this for planning.
    pose_guard : callable () -> str or None, or None
        Asked before every frame of a drive is integrated (:class:`~lab.navigation.drive_loop.DriveLoop`):
        a reason (a message) when the robot's pose has become too uncertain to map and drive on, which
        ends the drive with POSE_UNCERTAIN; None drives on. The costmap places every frame with the
        pose, so frames from a drifting pose leave slanted copies of walls behind that no later view
        clears (after 88 s without a landmark, a search stood in its own phantom wall:
        docs/tuning/room-errors.md). Whoever knows the pose's covariance sets it (the search's
        :class:`~lab.search.report_policy.RelocalizingNavigate`); None (default): no guard.

    Examples
    --------
    >>> bounds = room_bounds(load_scene("lab_room"))                 # doctest: +SKIP
    >>> nav = Navigator(robot, bounds=bounds)                        # doctest: +SKIP
    >>> nav.scan()                                                   # doctest: +SKIP
    >>> res = nav.go_to((1.0, 2.0), final_heading=0.0, timeout=60)   # doctest: +SKIP
    >>> res.outcome, res.replans                                     # doctest: +SKIP
    """

    def __init__(
        self,
        robot: Robot,
        spec: GridSpec | None = None,
        config: NavigatorConfig | None = None,
        *,
        bounds: Sequence[float] | None = None,
    ):
        self.robot = robot
        cfg = config if config is not None else NavigatorConfig()
        head_top = float(robot.camera.mount_R[2]) + HEAD_HEIGHT_M
        if cfg.costmap.robot_height < head_top:
            # a taller robot than the costmap assumes: what its head would hit is an obstacle too
            cfg = replace(cfg, costmap=replace(cfg.costmap, robot_height=head_top))
        self.config = cfg
        if spec is None and bounds is None:
            raise ConfigError("give the navigator its workspace: spec, or bounds (room_bounds(scene))")
        if spec is None:
            x0, y0, x1, y1 = (float(v) for v in bounds)
            m = cfg.margin
            spec = GridSpec.from_bounds(x0 - m, y0 - m, x1 + m, y1 + m, cfg.resolution)
        elif bounds is not None:
            raise ConfigError("give either spec or bounds, not both")
        self.costmap = Costmap(spec, cfg.costmap)
        self.planned_path: np.ndarray | None = None  # (n, 2) [m] W: the waypoints being driven (for views)
        self.plane: GroundPlane | None = None
        margin = spec.resolution if cfg.inflation_margin is None else cfg.inflation_margin
        self.radius = robot.base_limits.radius + margin
        self._rng = np.random.default_rng(cfg.seed)
        self._grid: CostGrid | None = None
        self._plane_rejects = 0
        self.pose_guard: Callable[[], str | None] | None = None

    @property
    def spec(self) -> GridSpec:
        return self.costmap.spec

    # -- perception ------------------------------------------------------------------------------
    def observe(self, frame: StereoFrame) -> Observation:
        """Integrate one stereo frame into the costmap.

        Dense points in the camera frame C are taken to the world by
        ``G_WC = G_WR(frame.odom) @ frame.G_RC``, labelled against the ground plane and binned into
        the costmap (obstacle priority, evidence accumulated over views).

        Returns
        -------
        Observation
            With ``skipped`` set (and the costmap unchanged) when no ground plane has been accepted yet
            and this view shows none either (it faces a wall).
        """
        cfg = self.config
        P_C = dense_points(
            frame.left,
            frame.right,
            frame.camera,
            step=cfg.pixel_step,
            max_depth=cfg.max_range,
            checked=cfg.lr_check,
        )
        G_WC = frame.odom.G() @ frame.G_RC
        P_W = transform_points(G_WC, P_C)  # p_W = G_WC p_C
        plane, refit = self._ground_plane(P_W[P_C[:, 2] <= cfg.ground_fit_range], G_WC)
        if plane is None:
            return Observation(frame.t, len(P_W), None, False, skipped="no ground plane yet")
        keep = self._supported(P_W, P_C[:, 2], plane, frame.camera.fx)
        upd = self.costmap.integrate(P_W[keep], plane, sensor_origin_xy=(G_WC[0, 3], G_WC[1, 3]))
        self._grid = None
        return Observation(frame.t, len(P_W), plane, refit, upd)

    def _supported(self, P_W: np.ndarray, Z: np.ndarray, plane: GroundPlane, f: float) -> np.ndarray:
        r"""Mask of the points to integrate: all but obstacle points in cells where, in this view, they
        cover less than ``config.min_obstacle_area`` of surface.

        A point taken every ``s`` pixels at depth ``Z`` stands for a patch of about
        :math:`(s Z / f)^2` of a surface facing the camera, so the summed patch area is how much
        obstacle surface the view saw in a cell, whatever its range. Counting points instead (the
        costmap's ``min_obstacle_points``) favours near cells, where a few stray matches at a depth
        discontinuity already make the count.
        """
        cfg = self.config
        keep = np.ones(len(P_W), dtype=bool)
        if cfg.min_obstacle_area <= 0 or len(P_W) == 0:
            return keep
        spec = self.spec
        obst = self.costmap.label_points(P_W, plane) == CellState.OBSTACLE
        ij, inside = spec.cells_of(P_W[:, :2])
        obst &= inside
        k = spec.flat(ij[obst])
        area = np.bincount(k, weights=(cfg.pixel_step * Z[obst] / f) ** 2, minlength=spec.n_cells)
        keep[np.flatnonzero(obst)[area[k] < cfg.min_obstacle_area]] = False
        return keep

    def _ground_plane(self, P_W: np.ndarray, G_WC: np.ndarray) -> tuple[GroundPlane | None, bool]:
        cfg = self.config
        try:
            fit = fit_ground_plane(P_W, self._rng)
        except NoGroundPlane:
            return self.plane, False
        if fit.tilt > cfg.plane_max_tilt:
            return self.plane, False
        if self.plane is not None:
            cx, cy = G_WC[0, 3], G_WC[1, 3]
            if abs(float(fit.z_at(cx, cy)) - float(self.plane.z_at(cx, cy))) > cfg.plane_max_jump:
                # a jump: keep the previous plane, unless level fits have disagreed with it several
                # views in a row (then the previous one was the odd one out)
                self._plane_rejects += 1
                if self._plane_rejects < 3:
                    return self.plane, False
        self._plane_rejects = 0
        self.plane = fit
        return fit, True

    def look(self, pan: float, tilt: float | None = None) -> StereoFrame:
        """Point the head at ``(pan, tilt)`` [rad] (tilt default ``config.tilt``), wait, and capture."""
        tilt = self.config.tilt if tilt is None else tilt
        lim = self.robot.pan_tilt_limits
        self.robot.command_pan_tilt(pan, tilt)
        self.robot.wait_pan_tilt(timeout=2.0 * (lim.pan_max - lim.pan_min) / lim.min_speed)
        return self.robot.capture_stereo()

    def scan(self, pans: Sequence[float] | None = None, tilt: float | None = None) -> ScanResult:
        """Stand still and sweep the head through ``pans`` [rad] at ``tilt`` [rad], observing each view.

        Defaults: ``config.scan_pans`` (all around) and ``config.tilt`` (looking down). Angles outside the
        pan-tilt limits raise :class:`~lab.errors.LimitError` before the head moves.
        """
        pans = tuple(self.config.scan_pans if pans is None else pans)
        tilt = self.config.tilt if tilt is None else tilt
        for p in pans:
            self.robot.pan_tilt_limits.check(p, tilt)
        self.robot.stop()
        t0 = self.robot.now()
        obs = tuple(self.observe(self.look(p, tilt)) for p in pans)
        return ScanResult(obs, self.robot.now() - t0)

    def planning_grid(self) -> CostGrid:
        """The inflated cost grid of the current costmap (cached until the next observation)."""
        if self._grid is None:
            cfg = self.config
            self._grid = self.costmap.inflated(
                self.radius,
                unknown_cost=cfg.unknown_cost,
                clearance=cfg.clearance,
                clearance_cost=cfg.clearance_cost,
            )
        return self._grid

    def clear_under_robot(self) -> int:
        """Clear the costmap under the robot's footprint when its own cell is blocked on the planning
        grid, and return how many OBSTACLE cells that cleared (0: nothing was blocked by marks under it).

        Where the robot stands there is no obstacle: a mark there is stale, or a landmark update moved
        the pose estimate onto marks made before it. Left alone, every path from there was
        START_IN_OBSTACLE (the escape's straight line starts in a lethal cell), and a search tried each
        of its cells in turn without moving. Obstacles merely near the footprint are kept: the
        escape (:class:`~lab.navigation.paths.Replanner`) drives out of their grown band."""
        p = self.robot.odometry()
        if not self.spec.contains_xy(p.x, p.y) or math.isfinite(self.planning_grid().cost_at(p.x, p.y)):
            return 0
        n = self.costmap.clear_disc((p.x, p.y), self.robot.base_limits.radius)
        if n:
            self._grid = None
        return n

    # -- driving -----------------------------------------------------------------------------------
    def go_to(
        self,
        goal_xy,
        final_heading: float | None = None,
        *,
        face_xy=None,
        timeout: float = 120.0,
    ) -> NavResult:
        """Drive to ``goal_xy`` [m] and turn to ``final_heading`` [rad] (or to face ``face_xy``).

        Plans with A* on the inflated costmap, follows the path with pure pursuit, and every
        ``config.frame_period`` seconds looks along the path ahead, integrates the frame and replans when
        the path ahead is blocked.

        Parameters
        ----------
        goal_xy : (x, y) [m] or Pose2D
            A pose's heading is used as the final heading unless one is given.
        final_heading : float [rad], optional
        face_xy : (x, y) [m], optional
            Turn at the goal to face this point (instead of ``final_heading``).
        timeout : float [s]
            Robot time after which the request ends with TIMEOUT.

        Returns
        -------
        NavResult
            A goal outside the map or in a known obstacle gives NO_PATH with its reason at once; one that
            turns out blocked or unreachable on the way gives NO_PATH when the map shows it.

        Raises
        ------
        ValueError
            ``goal_xy``, ``final_heading``, ``face_xy`` or ``timeout`` is NaN or infinite (named), or both
            a heading and ``face_xy`` are given.
        """
        gx, gy = check_finite_xy("goal_xy", goal_xy)
        heading = _final_heading(goal_xy, final_heading, face_xy)
        check_timeout(timeout)
        self.clear_under_robot()
        return DriveLoop(self, ToGoal(self, (gx, gy), heading), timeout).run()

    def go_near(
        self,
        target_xy,
        min_distance: float,
        max_distance: float,
        *,
        timeout: float = 120.0,
    ) -> NavResult:
        """Drive to the nearest reachable spot ``[min_distance, max_distance]`` [m] from a target and face it.

        The goal is any unblocked cell of the ring around ``target_xy`` (:func:`astar_to_region`; the
        search robot goes to look at a probability-map cell, which may hold a table). At the end the
        robot turns in place to face the target from where it actually stands.

        Raises
        ------
        ValueError
            ``target_xy`` or ``timeout`` is NaN or infinite, or the distance band is empty or not finite.
        """
        tx, ty = check_finite_xy("target_xy", target_xy)
        if not (math.isfinite(max_distance) and 0 <= min_distance <= max_distance):
            raise ValueError(
                f"need 0 <= min_distance <= max_distance < inf, got {min_distance!r}, {max_distance!r}"
            )
        check_timeout(timeout)
        self.clear_under_robot()
        return DriveLoop(self, NearTarget((tx, ty), min_distance, max_distance), timeout).run()

    def footprint_clear(self, a_xy, b_xy, step: float = 0.02) -> bool:
        """Whether the robot's footprint, swept straight from ``a_xy`` to ``b_xy`` [m], keeps at least
        ``config.goal_clearance`` off every OBSTACLE cell of the costmap (cells as squares, not centres).

        Used for the last stretch of :meth:`go_to` into the grown obstacles, where A* does not go.
        """
        spec = self.spec
        a, b = np.asarray(a_xy, dtype=float)[:2], np.asarray(b_xy, dtype=float)[:2]
        n = max(2, math.ceil(float(np.hypot(*(b - a))) / step) + 1)
        S = a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)
        if not spec.cells_of(S)[1].all():
            return False
        need = self.robot.base_limits.radius + self.config.goal_clearance
        C = spec.centers_of(np.argwhere(self.costmap.obstacle))
        C = C[np.hypot(C[:, 0] - a[0], C[:, 1] - a[1]) <= float(np.hypot(*(b - a))) + need + spec.resolution]
        if len(C) == 0:
            return True
        h = 0.5 * spec.resolution
        dx = np.maximum(np.abs(S[:, None, 0] - C[None, :, 0]) - h, 0.0)
        dy = np.maximum(np.abs(S[:, None, 1] - C[None, :, 1]) - h, 0.0)
        return bool(np.hypot(dx, dy).min() >= need)

    def path_ahead_clear(self, waypoints: np.ndarray, pose, distance: float) -> bool:
        """Whether the next ``distance`` metres of a path, from the robot's projection on it, are
        :meth:`footprint_clear` (the robot may keep driving there while a replan is pending)."""
        W = np.asarray(waypoints, dtype=float).reshape(-1, 2)
        xy = np.array(check_finite_xy("pose", pose))
        if len(W) == 0:
            return False
        pts = [xy]
        if len(W) > 1:
            k = nearest_index(W, xy)
            pts.append(point_ahead(W[k:], xy, 0.0))
            left = distance
            for q in W[k + 1 :]:
                seg = float(np.hypot(*(q - pts[-1])))
                if seg >= left:
                    pts.append(pts[-1] + (q - pts[-1]) * (left / max(seg, 1e-12)))
                    break
                left -= seg
                pts.append(q)
        else:
            pts.append(W[0])
        return all(self.footprint_clear(a, b) for a, b in zip(pts[:-1], pts[1:], strict=True))


def _final_heading(goal_xy, final_heading: float | None, face_xy) -> float | None:
    """The heading [rad] :meth:`Navigator.go_to` turns to at the goal: ``final_heading``, else a
    :class:`Pose2D` goal's own, else towards ``face_xy``; None for none (ValueError: NaN, or both)."""
    if final_heading is None and isinstance(goal_xy, Pose2D):
        final_heading = goal_xy.theta
    if final_heading is not None and not math.isfinite(final_heading):
        raise ValueError(f"final_heading must be finite or None, got {final_heading!r}")
    if face_xy is not None:
        if final_heading is not None:
            raise ValueError("give final_heading or face_xy, not both")
        final_heading = heading_towards(check_finite_xy("goal_xy", goal_xy), face_xy)
    return final_heading
