"""One navigation request of the :class:`~lab.navigation.navigator.Navigator`, step by step.

:meth:`Navigator.go_to` and :meth:`Navigator.go_near` differ only in where they send the robot (a
*destination*: :class:`ToGoal` or :class:`NearTarget`); the loop that takes it there is
:class:`DriveLoop`::

    plan:      A* on the inflated costmap to the destination (none: NO_PATH at once); a robot walled
               in by marks, with no escape, forgets those within the escape's reach, scans all
               round and plans again
    look:      the head turns along the path ahead, one frame, replan on what it saw
    drive:     drive_to with pure pursuit; at every control step the head follows the path ahead,
               every frame_period the pose guard (if any) is asked whether the pose is still good
               enough to map and drive on (no: POSE_UNCERTAIN, before the frame is integrated),
               then a frame is integrated and the Replanner checks the path ahead:
               a new path is handed to the follower; no path at all is confirmed only when the
               blockage lies within confirm_range (far cells come from noisy far views)
    face:      for go_near, a last turn towards the target from where the robot stopped
    report:    a NavResult (a bump, a safety stop or a timeout end the request too)
"""

from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass
from enum import Enum
from typing import TYPE_CHECKING, Protocol

import numpy as np

from lab.errors import SafetyStop
from lab.geometry import Pose2D, wrap_angle
from lab.navigation.astar import PathResult, PathStatus, astar, astar_to_region, heading_towards
from lab.navigation.costmap import CostGrid
from lab.navigation.follower import (
    DriveOutcome,
    DriveResult,
    FollowStatus,
    PathFollower,
    StepUpdate,
    drive_to,
)
from lab.navigation.paths import ReplanDecision, Replanner, point_ahead

if TYPE_CHECKING:
    from lab.navigation.navigator import Navigator

__all__ = ["Destination", "DriveLoop", "NavOutcome", "NavResult", "NearTarget", "ToGoal", "check_timeout"]


class NavOutcome(Enum):
    """How a navigation request ended."""

    ARRIVED = "arrived within the follower's tolerances (odometry)"
    NO_PATH = "no path (see the reason)"
    TIMEOUT = "timed out"
    BUMPED = "the base bumped into something (its bump count rose)"
    SAFETY_STOP = "the robot stopped itself (bump, cliff or wheel drop)"
    POSE_UNCERTAIN = "the pose guard stopped the drive: the pose is too uncertain to map on (see the reason)"


@dataclass(frozen=True)
class NavResult:
    """The end of :meth:`Navigator.go_to` or :meth:`Navigator.go_near`.

    Attributes
    ----------
    outcome : NavOutcome
    reason : str or None
        For NO_PATH the :class:`~lab.navigation.astar.PathStatus` name (``"GOAL_OUTSIDE_MAP"``,
        ``"GOAL_IN_OBSTACLE"``, ``"UNREACHABLE"``, ``"START_IN_OBSTACLE"``, ...); a message for
        SAFETY_STOP and POSE_UNCERTAIN (the guard's); None otherwise.
    pose : Pose2D
        Odometry pose at the end.
    goal_xy : (float, float) or None [m]
        Where the robot was sent (for ``go_near``, the cell of the ring it chose last).
    final_heading : float [rad] or None
    replans : int
        Paths planned after the first one (the path ahead was blocked, or an escape).
    frames : int
        Stereo frames integrated while driving (and in a walled-in robot's scan).
    distance_m : float [m]
        Path length driven (odometry).
    elapsed_s : float [s]
        Robot time from the request to the end.
    position_error_m : float [m]
        Distance from the end pose to ``goal_xy`` (odometry; inf without a goal).
    heading_error_rad : float [rad] or None
        Wrapped final heading error (odometry), None without a final heading.
    """

    outcome: NavOutcome
    reason: str | None
    pose: Pose2D
    goal_xy: tuple[float, float] | None
    final_heading: float | None
    replans: int
    frames: int
    distance_m: float
    elapsed_s: float
    position_error_m: float
    heading_error_rad: float | None

    @property
    def arrived(self) -> bool:
        return self.outcome is NavOutcome.ARRIVED


def check_timeout(timeout: float) -> None:
    """Refuse a timeout [s] that is not a finite number > 0 (ValueError)."""
    if not (isinstance(timeout, (int, float)) and math.isfinite(timeout) and timeout > 0):
        raise ValueError(f"timeout must be a finite number > 0 s, got {timeout!r}")


# -- where a request goes --------------------------------------------------------------------------------
class Destination(Protocol):
    """Where a request sends the robot: how to plan there and what the follower drives.

    ``plan(grid, start_xy)`` plans on the inflated grid; ``waypoints(wp)`` and ``heading(wp)`` turn the
    Replanner's waypoints into what the follower drives and its final heading; ``still_clear(wp)``
    checks what the Replanner does not; ``face_target`` asks for a last turn towards a point from where
    the robot stopped; ``requested`` is the goal and heading reported when there is no path at all.
    """

    face_target: tuple[float, float] | None
    requested: tuple[tuple[float, float] | None, float | None]

    def plan(self, grid: CostGrid, start) -> PathResult: ...

    def waypoints(self, wp: np.ndarray) -> np.ndarray: ...

    def heading(self, wp: np.ndarray) -> float | None: ...

    def still_clear(self, wp: np.ndarray) -> bool: ...


class ToGoal:
    """:meth:`Navigator.go_to`'s destination: a goal point and an optional final heading.

    A goal inside the grown obstacles that the footprint itself fits (``config.goal_approach``) is
    reached by planning to the nearest open cell and driving the rest straight.
    """

    face_target = None

    def __init__(self, nav: Navigator, goal_xy: tuple[float, float], final_heading: float | None):
        self.nav = nav
        self.goal_xy = goal_xy
        self.final_heading = final_heading
        self.goal = np.array(goal_xy)
        self.goal_cell = nav.spec.cells_of(self.goal[None, :])[0][0]
        self.requested = (goal_xy, final_heading)

    def plan(self, grid: CostGrid, start) -> PathResult:
        result = astar(grid, start, self.goal_xy)
        if result.status is PathStatus.GOAL_IN_OBSTACLE and self.nav.config.goal_approach > 0:
            # the goal lies in the grown obstacles; if the footprint fits there, plan to the nearest
            # open cell and drive the last stretch straight
            near = astar_to_region(grid, start, self.goal_xy, self.nav.config.goal_approach)
            if near.found and self.nav.footprint_clear(near.points_xy[-1], self.goal):
                return near
        return result

    def _in_goal_cell(self, points: np.ndarray) -> bool:
        return tuple(self.nav.spec.cells_of(points)[0][0]) == tuple(self.goal_cell)

    def waypoints(self, wp: np.ndarray) -> np.ndarray:
        if self._in_goal_cell(wp[-1:]):
            wp = wp.copy()
            wp[-1] = self.goal  # the exact goal, not its cell's centre
            return wp
        return np.vstack([wp, self.goal[None, :]])  # the straight last stretch into the grown zone

    def heading(self, wp: np.ndarray) -> float | None:
        return self.final_heading

    def still_clear(self, wp: np.ndarray) -> bool:
        if len(wp) < 2 or self._in_goal_cell(wp[-2:-1]):
            return True  # the A* path reaches the goal's own cell: the Replanner checks it all
        return self.nav.footprint_clear(wp[-2], wp[-1])


class NearTarget:
    """:meth:`Navigator.go_near`'s destination: any cell of the ring ``[min_distance, max_distance]``
    [m] around a target, facing the target at the end."""

    requested = (None, None)

    def __init__(self, target_xy: tuple[float, float], min_distance: float, max_distance: float):
        self.target_xy = target_xy
        self.min_distance, self.max_distance = min_distance, max_distance
        self.face_target = target_xy

    def plan(self, grid: CostGrid, start) -> PathResult:
        return astar_to_region(grid, start, self.target_xy, self.max_distance, self.min_distance)

    def waypoints(self, wp: np.ndarray) -> np.ndarray:
        return wp

    def heading(self, wp: np.ndarray) -> float | None:
        return heading_towards(wp[-1], self.target_xy)

    def still_clear(self, wp: np.ndarray) -> bool:
        return True  # the Replanner checks the whole path


# -- the loop ------------------------------------------------------------------------------------------
_OUTCOMES = {
    DriveOutcome.ARRIVED: NavOutcome.ARRIVED,
    DriveOutcome.TIMEOUT: NavOutcome.TIMEOUT,
    DriveOutcome.NO_PATH: NavOutcome.NO_PATH,
    DriveOutcome.ABORTED: NavOutcome.NO_PATH,
}


class DriveLoop:
    """One request (module docstring): plan, look, drive while observing and replanning, face, report.

    Parameters
    ----------
    nav : Navigator
        Its robot, config, costmap (``observe``, ``planning_grid``) and path checks.
    destination : Destination
    timeout : float [s]
        Robot time after which the request ends with TIMEOUT.

    Attributes
    ----------
    waypoints : ndarray, shape (n, 2) [m]
        The path the follower drives (W).
    heading : float [rad] or None
        Its final heading.
    replans, frames, rescans : int
        Paths planned after the first one; stereo frames integrated; scans of a walled-in robot.
    """

    def __init__(self, nav: Navigator, destination: Destination, timeout: float):
        self.nav, self.destination = nav, destination
        self.robot, self.config = nav.robot, nav.config
        self.t0 = self.robot.now()
        self.t_end = self.t0 + timeout
        self.pose0 = self.robot.odometry()
        self.bumps0 = self._bumps()
        self.replanner = Replanner(destination.plan)
        self.waypoints = np.zeros((0, 2))
        self.heading: float | None = None
        self.step = 0
        self.frames = 0
        self.replans = 0
        self.rescans = 0  # scans when walled in by marks (_sense_again_when_walled_in)
        self.outcome: NavOutcome | None = None  # set by a step that aborts the drive
        self.reason: str | None = None
        self.follower: PathFollower | None = None
        self.k_frame = max(1, round(self.config.frame_period / self.config.control_dt))

    def run(self) -> NavResult:
        """Plan, look, drive, face; a safety stop ends the request with SAFETY_STOP."""
        pose0 = self.pose0
        d = self._replan(pose0)
        if d.path.status is PathStatus.START_IN_OBSTACLE:
            d = self._sense_again_when_walled_in(d)
        if not d.path.found:
            goal, heading = self.destination.requested
            return self._finish(NavOutcome.NO_PATH, d.path.reason, pose0, goal, heading)
        self._adopt(d.waypoints)
        try:
            blocked = self._look_before_driving()
            if blocked is not None:
                return self._finish(NavOutcome.NO_PATH, blocked, pose0, self.waypoints[-1], self.heading)
            res = self._drive()
            dist = res.distance_m
            res = self._face_target(res)
            outcome, reason = self._outcome_of(res)
            return self._finish(outcome, reason, res.pose, self.waypoints[-1], self.heading, dist)
        except SafetyStop as e:
            with contextlib.suppress(Exception):
                self.robot.stop()
            pose = self.robot.odometry()
            return self._finish(NavOutcome.SAFETY_STOP, str(e), pose, self.waypoints[-1], self.heading)

    # -- the steps ------------------------------------------------------------------------------------
    def _adopt(self, wp: np.ndarray) -> None:
        """Drive the Replanner's waypoints ``wp`` from now on (also shown as ``nav.planned_path``)."""
        self.waypoints, self.heading = self.destination.waypoints(wp), self.destination.heading(wp)
        self.nav.planned_path = self.waypoints

    def _sense_again_when_walled_in(self, d: ReplanDecision) -> ReplanDecision:
        """No way out of the grown obstacles round the robot, not even the escape's: but it drove in,
        so some of those marks are wrong (made while the pose estimate was off, and left round the
        robot when a correction moved it; docs/tuning/localizer-odometry-told.md). Forget the marks
        within the escape's reach, scan all round to mark again what is really there, and plan again;
        the look before driving then checks the way ahead as usual. ``d`` unchanged when nothing there
        was marked."""
        p = self.pose0
        if self.nav.costmap.forget_disc((p.x, p.y), self.replanner.escape_radius) == 0:
            return d
        self.frames += len(self.nav.scan().observations)
        self.rescans += 1
        return self._replan(p)

    def _look_before_driving(self) -> str | None:
        """Look towards the path ahead, then replan on what the head saw; the reason when the path is
        blocked close ahead (a blockage farther along is decided on the way)."""
        pose0 = self.pose0
        self._point_head(pose0, wait=True)
        self._observe()
        d = self._replan(pose0)
        if d.replanned and d.path.found:
            self.replans += 1
            self._adopt(d.waypoints)
        elif d.replanned and not self.nav.path_ahead_clear(self.waypoints, pose0, self.config.confirm_range):
            return d.path.reason
        return None

    def _drive(self) -> DriveResult:
        """Follow the path to the end, with :meth:`_on_step` at every control step."""
        cfg = self.config
        self.follower = self._new_follower()
        return drive_to(
            self.robot,
            self.waypoints,
            self.heading,
            cfg.control_dt,
            max(self.t_end - self.robot.now(), cfg.control_dt),
            follower=self.follower,
            on_step=self._on_step,
        )

    def _on_step(self, pose: Pose2D, t: float) -> StepUpdate | None:
        """At every control step: stop on a bump, keep the head on the path ahead, and every
        ``k_frame`` steps observe and check the path (:meth:`_check_path`)."""
        self.step += 1
        if self._bumps() > self.bumps0:
            self.outcome = NavOutcome.BUMPED
            return StepUpdate(abort=True)
        self._point_head(pose)
        if self.step % self.k_frame:
            return None
        return self._check_path(pose)

    def _check_path(self, pose: Pose2D) -> StepUpdate | None:
        """Ask the pose guard, integrate a frame and replan: a new path for the follower, or an abort when
        the guard says the pose is too uncertain (before the frame is integrated: it would be placed
        with that pose), or when there is no path and the blockage is within ``confirm_range``; None
        keeps to the path."""
        guard = self.nav.pose_guard
        why = guard() if guard is not None else None
        if why is not None:
            self.outcome, self.reason = NavOutcome.POSE_UNCERTAIN, why
            return StepUpdate(abort=True)
        self._observe()
        if self.follower.status in _AT_GOAL:
            return None  # turning in place at the goal: nothing ahead to check
        d = self._replan(pose)
        if d.replanned and d.path.found:
            self.replans += 1
            self._adopt(d.waypoints)
            return StepUpdate(waypoints=self.waypoints, final_heading=self.heading)
        if d.replanned:
            failure = d.path.reason
        elif not self.destination.still_clear(self.waypoints):
            failure = PathStatus.GOAL_IN_OBSTACLE.name
        else:
            return None
        # No path on this map. Far cells come from noisy far views that nearer ones may clear:
        # keep to the old path while its next confirm_range metres are clear (the Replanner
        # plans again at the next frame), and give up when the blockage is that close.
        if self.nav.path_ahead_clear(self.waypoints, pose, self.config.confirm_range):
            return None
        self.outcome, self.reason = NavOutcome.NO_PATH, failure
        return StepUpdate(abort=True)

    def _observe(self) -> None:
        """Capture a stereo frame and integrate it into the navigator's costmap."""
        self.nav.observe(self.robot.capture_stereo())
        self.frames += 1

    def _replan(self, pose: Pose2D) -> ReplanDecision:
        """Let the Replanner check the path from ``pose`` on the current costmap (it plans again when
        the path ahead is blocked)."""
        return self.replanner.update(self.nav.planning_grid(), pose)

    def _face_target(self, res: DriveResult) -> DriveResult:
        """After an arrival, turn in place to face the destination's target (if any, and time is left)."""
        target = self.destination.face_target
        if res.outcome is not DriveOutcome.ARRIVED or target is None or not self.t_end > self.robot.now():
            return res
        pose = res.pose
        self.heading = heading_towards((pose.x, pose.y), target)
        return drive_to(
            self.robot,
            np.array([[pose.x, pose.y]]),
            self.heading,
            self.config.control_dt,
            self.t_end - self.robot.now(),
            follower=self._new_follower(),
        )

    def _outcome_of(self, res: DriveResult) -> tuple[NavOutcome, str | None]:
        """A bump first, then what a step decided, then how the drive ended."""
        if self._bumps() > self.bumps0:
            return NavOutcome.BUMPED, None
        if self.outcome is not None:
            return self.outcome, self.reason
        return _OUTCOMES[res.outcome], None

    def _finish(self, outcome: NavOutcome, reason, pose: Pose2D, goal, heading, dist=0.0) -> NavResult:
        g = None if goal is None else (float(goal[0]), float(goal[1]))
        pos_err = math.inf if g is None else math.hypot(g[0] - pose.x, g[1] - pose.y)
        head_err = None if heading is None else wrap_angle(heading - pose.theta)
        return NavResult(
            outcome,
            reason,
            pose,
            g,
            heading,
            self.replans,
            self.frames,
            dist,
            self.robot.now() - self.t0,
            pos_err,
            head_err,
        )

    def _new_follower(self) -> PathFollower:
        cfg = self.config
        return PathFollower(
            self.robot.base_limits,
            goal_tolerance_xy=cfg.goal_tolerance_xy,
            goal_tolerance_theta=cfg.goal_tolerance_theta,
        )

    def _bumps(self) -> int:
        """The base's bump count (:attr:`lab.robot.Robot.bumps`: passed on by any wrapper)."""
        return int(self.robot.bumps)

    def _point_head(self, pose: Pose2D, wait: bool = False) -> None:
        """Pan the head towards the path ``look_ahead`` metres ahead (along the final heading at the end)."""
        cfg, robot = self.config, self.robot
        xy = np.array([pose.x, pose.y])
        p = point_ahead(self.waypoints, xy, cfg.look_ahead)
        if np.hypot(*(p - xy)) > 0.3:
            bearing = math.atan2(p[1] - xy[1], p[0] - xy[0])
        elif self.heading is not None:
            bearing = self.heading
        else:
            bearing = pose.theta + robot.pan_tilt().pan_target
        lim = robot.pan_tilt_limits
        pan = min(max(wrap_angle(bearing - pose.theta), lim.pan_min), lim.pan_max)
        robot.command_pan_tilt(pan, cfg.tilt)
        if wait:
            robot.wait_pan_tilt(timeout=2.0 * (lim.pan_max - lim.pan_min) / lim.min_speed)


#: Follower states in which the robot turns in place at the goal (no path ahead to check).
_AT_GOAL = (FollowStatus.FINAL_TURN, FollowStatus.ARRIVED)
