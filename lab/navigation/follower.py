r"""Following a planned path with a differential-drive base: pure pursuit with turning in place.

The control law, evaluated once per control step from the odometry pose ``(x, y, theta)``:

1. **Progress.** The pose is projected on the waypoint polyline; the arc length ``s`` of the
   projection only moves forward (a path that doubles back is not short-cut).
2. **Lookahead point.** ``p_L`` is the point at arc length ``s + L`` (``L`` the lookahead), but never
   past the next *corner* (a waypoint where the path turns by more than ``corner_angle``): the robot
   drives to a corner, turns there and goes on, instead of cutting it (cutting a corner by the
   lookahead would cut into the grown obstacles the path keeps clear of). A corner counts as passed
   once the robot is within ``corner_reach`` of it.
3. **Heading error** ``alpha = wrap(atan2(p_L - p) - theta)``. If ``|alpha|`` exceeds
   ``turn_in_place_angle`` the robot stops and turns in place (TURNING) until ``|alpha|`` is below
   ``resume_angle`` (hysteresis).
4. **Pure pursuit** otherwise (FOLLOWING): the arc through ``p_L`` tangent to the heading has curvature

   .. math:: \kappa = \frac{2 \sin\alpha}{\ell_d}, \qquad \ell_d = \|p_L - p\|,

   and the speed is the least of the cruise speed, the speed from which the base can still stop at the
   goal or the next corner, :math:`\sqrt{2 a\, d}` with :math:`a` half the acceleration limit, and the
   speed at which :math:`v|\kappa|` stays within the turn-rate limit; then :math:`\omega = v \kappa`.
   The base never drives backwards.
5. **At the goal** (within half the position tolerance, or within the tolerance and past it) the base
   stops and turns in place to the final heading (FINAL_TURN), then reports ARRIVED once its commanded
   speeds are zero and the heading is within half the heading tolerance. Aiming at half the tolerances
   leaves the other half for odometry and control error.

Every command is limited by the follower itself (not only by the robot): speeds to ``BaseLimits``
``max_speed`` / ``max_turn_rate``, and their change between calls to ``max_accel * dt`` /
``max_turn_accel * dt``, with ``dt`` from the times passed to :meth:`PathFollower.command` (the first
command after :meth:`PathFollower.reset` starts from standstill). Turns in place use

.. math:: \omega = \mathrm{sign}(e) \min\left(\omega_{max},\; k e,\; \sqrt{2 \dot\omega_b |e|}\right),
   \qquad \dot\omega_b = \dot\omega_{max} / 2,

for a heading error :math:`e`: the square-root term is the turn rate from which the base can still
brake to rest at the target angle.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum
from typing import NamedTuple

import numpy as np

from lab.geometry import Pose2D, wrap_angle
from lab.navigation.astar import PathResult
from lab.robot import BaseLimits, Robot

__all__ = [
    "FollowStatus",
    "Command",
    "PathFollower",
    "DriveOutcome",
    "DriveResult",
    "StepUpdate",
    "drive_to",
]


class FollowStatus(Enum):
    """What the follower is doing."""

    FOLLOWING = "following the path"
    TURNING = "turning in place towards the path"
    FINAL_TURN = "at the goal, turning to the final heading"
    ARRIVED = "arrived: position and heading within tolerance, stopped"
    NO_PATH = "no path to follow"


class Command(NamedTuple):
    """A velocity command: forward speed ``v`` [m/s], turn rate ``omega`` [rad/s], and the status."""

    v: float
    omega: float
    status: FollowStatus


def _check_pose(pose: Pose2D, name: str = "pose") -> None:
    if not all(math.isfinite(float(v)) for v in (pose.x, pose.y, pose.theta)):
        raise ValueError(f"{name} must be finite, got {pose!r}")


class PathFollower:
    """Pure-pursuit path follower for a differential drive (the control law is in the module docstring).

    Parameters
    ----------
    limits : BaseLimits
        The base's speed and acceleration limits; every command respects them.
    lookahead : float [m]
        Pure-pursuit lookahead distance ``L``.
    goal_tolerance_xy : float [m]
        Arrival tolerance on the position; the follower aims at half of it.
    goal_tolerance_theta : float [rad]
        Arrival tolerance on the final heading; the follower aims at half of it.
    cruise_speed : float [m/s], optional
        Top forward speed (default: ``limits.max_speed``).
    turn_in_place_angle, resume_angle : float [rad]
        Stop and turn in place above the first heading error, drive again below the second.
    corner_angle : float [rad]
        A waypoint where the path turns by more than this is a corner (see the module docstring).
    corner_reach : float [m]
        A corner is passed once the robot is this close to it.
    k_heading : float [1/s]
        Proportional gain of the turn-in-place controllers.
    min_speed : float [m/s]
        Creep speed close to the goal, so the braking profile does not stall short of it.
    """

    def __init__(
        self,
        limits: BaseLimits,
        lookahead: float = 0.3,
        goal_tolerance_xy: float = 0.1,
        goal_tolerance_theta: float = math.radians(10.0),
        *,
        cruise_speed: float | None = None,
        turn_in_place_angle: float = math.radians(50.0),
        resume_angle: float = math.radians(12.0),
        corner_angle: float = math.radians(30.0),
        corner_reach: float = 0.06,
        k_heading: float = 2.5,
        min_speed: float = 0.03,
    ):
        if not (lookahead > 0 and goal_tolerance_xy > 0 and goal_tolerance_theta > 0):
            raise ValueError("lookahead and goal tolerances must be > 0")
        if not 0 < resume_angle < turn_in_place_angle:
            raise ValueError("need 0 < resume_angle < turn_in_place_angle")
        self.limits = limits
        self.lookahead = float(lookahead)
        self.goal_tolerance_xy = float(goal_tolerance_xy)
        self.goal_tolerance_theta = float(goal_tolerance_theta)
        self.cruise_speed = min(limits.max_speed, cruise_speed if cruise_speed is not None else math.inf)
        self.turn_in_place_angle = float(turn_in_place_angle)
        self.resume_angle = float(resume_angle)
        self.corner_angle = float(corner_angle)
        self.corner_reach = float(corner_reach)
        self.k_heading = float(k_heading)
        self.min_speed = float(min_speed)
        # braking uses half the acceleration limits: margin for the discrete control step
        self._a_brake = 0.5 * limits.max_accel
        self._alpha_brake = 0.5 * limits.max_turn_accel
        self._W = np.zeros((0, 2))
        self._s = np.zeros(0)
        self._corners: list[float] = []
        self.final_heading: float | None = None
        self.reset()

    # -- state ---------------------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget the last command (the next one starts from standstill) and the progress."""
        self._v = 0.0
        self._omega = 0.0
        self._t: float | None = None
        self._progress = 0.0
        self._next_corner = 0
        self._phase = FollowStatus.FOLLOWING if len(self._W) else FollowStatus.NO_PATH

    def set_path(self, waypoints, final_heading: float | None = None) -> None:
        """Follow new waypoints (keeps the last command, so switching paths mid-drive stays smooth).

        Parameters
        ----------
        waypoints : ndarray, shape (n, 2) [m], or PathResult
            World waypoints in driving order (e.g. :func:`~lab.navigation.paths.simplify_path`).
        final_heading : float [rad], optional
            Heading to turn to at the end (e.g. facing a target cell); None: any heading.
        """
        if isinstance(waypoints, PathResult):
            waypoints = waypoints.points_xy
        W = np.asarray(waypoints, dtype=float).reshape(-1, 2)
        if not np.isfinite(W).all():
            raise ValueError("waypoints must be finite")
        if final_heading is not None and not math.isfinite(final_heading):
            raise ValueError(f"final_heading must be finite or None, got {final_heading!r}")
        if len(W) > 1:  # drop repeated points (zero-length segments)
            keep = np.concatenate([[True], np.linalg.norm(np.diff(W, axis=0), axis=1) > 1e-9])
            W = W[keep]
        self._W = W
        seg = np.linalg.norm(np.diff(W, axis=0), axis=1) if len(W) > 1 else np.zeros(0)
        self._s = np.concatenate([[0.0], np.cumsum(seg)])
        self._corners = []
        for k in range(1, len(W) - 1):
            d0, d1 = W[k] - W[k - 1], W[k + 1] - W[k]
            turn = abs(wrap_angle(math.atan2(d1[1], d1[0]) - math.atan2(d0[1], d0[0])))
            if turn > self.corner_angle:
                self._corners.append(float(self._s[k]))
        self.final_heading = None if final_heading is None else float(final_heading)
        self._progress = 0.0
        self._next_corner = 0
        self._phase = FollowStatus.FOLLOWING if len(W) else FollowStatus.NO_PATH

    @property
    def waypoints(self) -> np.ndarray:
        return self._W.copy()

    @property
    def status(self) -> FollowStatus:
        return self._phase

    @property
    def goal_xy(self) -> tuple[float, float] | None:
        return None if len(self._W) == 0 else (float(self._W[-1, 0]), float(self._W[-1, 1]))

    # -- geometry --------------------------------------------------------------------------------------
    def _point_at(self, s: float) -> np.ndarray:
        W, S = self._W, self._s
        if len(W) == 1 or s >= S[-1]:
            return W[-1].copy()
        k = int(np.searchsorted(S, s, side="right") - 1)
        k = min(max(k, 0), len(W) - 2)
        t = (s - S[k]) / (S[k + 1] - S[k])
        return W[k] + t * (W[k + 1] - W[k])

    def _project(self, p: np.ndarray) -> float:
        """Arc length of the nearest point of the path ahead of the current progress (within reach)."""
        W, S = self._W, self._s
        if len(W) < 2:
            return 0.0
        horizon = self._progress + 2.0 * self.lookahead + 0.5
        # the segment holding the progress (the last one once the progress reached the end)
        k0 = min(max(0, int(np.searchsorted(S, self._progress, side="right")) - 1), len(W) - 2)
        k1 = max(k0 + 1, int(np.searchsorted(S, horizon, side="right")))
        k1 = min(k1, len(W) - 1)
        a, b = W[k0:k1], W[k0 + 1 : k1 + 1]
        ab = b - a
        L2 = np.einsum("ij,ij->i", ab, ab)
        t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.maximum(L2, 1e-12), 0.0, 1.0)
        d = np.linalg.norm(a + t[:, None] * ab - p, axis=1)
        i = int(np.argmin(d))
        return float(S[k0 + i] + t[i] * np.sqrt(L2[i]))

    # -- limits ----------------------------------------------------------------------------------------
    def _turn_rate_towards(self, err: float) -> float:
        """Turn rate that brings a heading error ``err`` [rad] to zero and can brake in time."""
        mag = min(
            self.limits.max_turn_rate, self.k_heading * abs(err), math.sqrt(2 * self._alpha_brake * abs(err))
        )
        return math.copysign(mag, err)

    def _limited(self, v_des: float, omega_des: float, dt: float) -> tuple[float, float]:
        lim = self.limits
        v_des = min(max(v_des, -lim.max_speed), lim.max_speed)
        omega_des = min(max(omega_des, -lim.max_turn_rate), lim.max_turn_rate)
        dv, dw = lim.max_accel * dt, lim.max_turn_accel * dt
        v = min(max(v_des, self._v - dv), self._v + dv)
        w = min(max(omega_des, self._omega - dw), self._omega + dw)
        return v, w

    # -- the control step ------------------------------------------------------------------------------
    def command(self, pose: Pose2D, t: float) -> Command:
        """The velocity command for the odometry ``pose`` at time ``t`` [s] (see the module docstring).

        Raises
        ------
        ValueError
            ``pose`` or ``t`` is NaN or infinite, or ``t`` is earlier than the previous call's.
        """
        _check_pose(pose)
        if not math.isfinite(t):
            raise ValueError(f"t must be finite, got {t!r}")
        if self._t is not None and t < self._t:
            raise ValueError(f"t went backwards: {t} after {self._t}")
        dt = 0.0 if self._t is None else t - self._t
        self._t = t

        if len(self._W) == 0:
            return self._emit(*self._limited(0.0, 0.0, dt), FollowStatus.NO_PATH)

        p = np.array([pose.x, pose.y])
        goal = self._W[-1]
        to_goal = goal - p
        d_goal = float(np.hypot(*to_goal))

        if self._phase in (FollowStatus.FINAL_TURN, FollowStatus.ARRIVED):
            if d_goal > 1.5 * self.goal_tolerance_xy:  # pushed away from the goal: drive back
                self._phase = FollowStatus.FOLLOWING
            else:
                return self._final_turn(pose, dt)
        past_goal = math.cos(math.atan2(to_goal[1], to_goal[0]) - pose.theta) < 0.0
        at_end = self._progress >= self._s[-1] - self.lookahead
        if d_goal <= 0.5 * self.goal_tolerance_xy or (
            at_end and past_goal and d_goal <= self.goal_tolerance_xy
        ):
            self._phase = FollowStatus.FINAL_TURN
            return self._final_turn(pose, dt)

        # progress, corners and the lookahead point
        self._progress = max(self._progress, self._project(p))
        while self._next_corner < len(self._corners):
            s_c = self._corners[self._next_corner]
            near = np.hypot(*(self._point_at(s_c) - p)) <= self.corner_reach
            if self._progress >= s_c or near:
                self._next_corner += 1
                self._progress = max(self._progress, s_c)
            else:
                break
        s_target = self._progress + self.lookahead
        s_stop = float(self._s[-1])
        if self._next_corner < len(self._corners):
            s_stop = self._corners[self._next_corner]
            s_target = min(s_target, s_stop)
        p_L = self._point_at(s_target)
        d_L = float(np.hypot(*(p_L - p)))
        if d_L < 1e-6:
            alpha = 0.0
        else:
            alpha = wrap_angle(math.atan2(p_L[1] - p[1], p_L[0] - p[0]) - pose.theta)

        if self._phase is FollowStatus.TURNING and abs(alpha) <= self.resume_angle:
            self._phase = FollowStatus.FOLLOWING
        elif abs(alpha) > self.turn_in_place_angle:
            self._phase = FollowStatus.TURNING
        if self._phase is FollowStatus.TURNING:
            v, w = self._limited(0.0, self._turn_rate_towards(alpha), dt)
            return self._emit(v, w, FollowStatus.TURNING)

        # pure pursuit
        self._phase = FollowStatus.FOLLOWING
        kappa = 2.0 * math.sin(alpha) / max(d_L, 1e-3)
        d_stop = float(np.hypot(*(self._point_at(s_stop) - p)))
        # brake to the creep speed where the goal phase or the corner's turn begins
        d_stop -= 0.5 * self.goal_tolerance_xy if s_stop == self._s[-1] else self.corner_reach
        d_stop = max(d_stop, 0.0)
        v_des = min(self.cruise_speed, max(math.sqrt(2.0 * self._a_brake * d_stop), self.min_speed))
        if abs(kappa) > 1e-9:
            v_des = min(v_des, self.limits.max_turn_rate / abs(kappa))
        v, _ = self._limited(v_des, 0.0, dt)
        v, w = self._limited(v, v * kappa, dt)
        return self._emit(v, w, FollowStatus.FOLLOWING)

    def _final_turn(self, pose: Pose2D, dt: float) -> Command:
        if self.final_heading is None:
            err = 0.0
        else:
            err = wrap_angle(self.final_heading - pose.theta)
        done = abs(err) <= 0.5 * self.goal_tolerance_theta
        w_des = 0.0 if done else self._turn_rate_towards(err)
        v, w = self._limited(0.0, w_des, dt)
        if done and v == 0.0 and w == 0.0:
            self._phase = FollowStatus.ARRIVED
            return self._emit(0.0, 0.0, FollowStatus.ARRIVED)
        self._phase = FollowStatus.FINAL_TURN
        return self._emit(v, w, FollowStatus.FINAL_TURN)

    def _emit(self, v: float, w: float, status: FollowStatus) -> Command:
        self._v, self._omega = v, w
        return Command(v, w, status)


# -- the loop against a Robot ----------------------------------------------------------------------------
class DriveOutcome(Enum):
    ARRIVED = "arrived"
    TIMEOUT = "timed out"
    ABORTED = "aborted by the step callback"
    NO_PATH = "no path to follow"


@dataclass(frozen=True)
class StepUpdate:
    """What a ``drive_to`` step callback may ask for: a new path (and heading), or to stop driving."""

    waypoints: np.ndarray | PathResult | None = None
    final_heading: float | None = None
    abort: bool = False


@dataclass(frozen=True)
class DriveResult:
    """How a :func:`drive_to` run ended.

    Attributes
    ----------
    outcome : DriveOutcome
    pose : Pose2D
        Odometry pose at the end.
    elapsed_s : float [s]
        Robot time from the first to the last step.
    steps : int
        Control steps (``drive`` calls).
    distance_m : float [m]
        Path length driven, from odometry.
    position_error_m : float [m]
        Distance from the end pose to the last waypoint (odometry).
    heading_error_rad : float [rad] or None
        Wrapped final heading error, or None without a final heading.
    """

    outcome: DriveOutcome
    pose: Pose2D
    elapsed_s: float
    steps: int
    distance_m: float
    position_error_m: float
    heading_error_rad: float | None


def drive_to(
    robot: Robot,
    path,
    final_heading: float | None = None,
    dt: float = 0.05,
    timeout: float = 60.0,
    *,
    follower: PathFollower | None = None,
    on_step: Callable[[Pose2D, float], StepUpdate | None] | None = None,
) -> DriveResult:
    """Drive ``robot`` along ``path`` and turn to ``final_heading``, one control step every ``dt``.

    Each step: read ``robot.odometry()`` and ``robot.now()``, call ``on_step`` (which may hand over a
    replanned path or abort), compute the follower's command, ``robot.drive(v, omega)`` (every step,
    so the robot's command watchdog never fires), ``robot.step(dt)``. The robot is stopped when the run
    ends, however it ends (an exception from the robot propagates after the stop).

    Parameters
    ----------
    robot : Robot
        Enabled; any implementation of :class:`lab.robot.Robot`.
    path : ndarray, shape (n, 2) [m], or PathResult
        Waypoints in the world frame (odometry's frame).
    final_heading : float [rad], optional
    dt : float [s]
        Control period; must be shorter than the robot's ``cmd_timeout_s``.
    timeout : float [s]
        Robot time after which the run gives up (also bounds the number of steps).
    follower : PathFollower, optional
        Default: ``PathFollower(robot.base_limits)``.
    on_step : callable ``(pose, t) -> StepUpdate or None``, optional
        Called before each command, e.g. to integrate a stereo frame into the costmap and replan. A new
        path replaces the current one (progress restarts on it); an empty one ends the run with
        NO_PATH; ``abort=True`` ends it with ABORTED.

    Returns
    -------
    DriveResult
    """
    _check_control_period(robot, dt, timeout)
    f = follower if follower is not None else PathFollower(robot.base_limits)
    f.set_path(path, final_heading)
    f.reset()
    max_steps = math.ceil(timeout / dt) + 1
    t0 = robot.now()
    pose = robot.odometry()
    distance, steps = 0.0, 0
    outcome = DriveOutcome.TIMEOUT
    try:
        if len(f.waypoints) == 0:
            outcome = DriveOutcome.NO_PATH
        while outcome is not DriveOutcome.NO_PATH and steps < max_steps:
            t = robot.now()
            new_pose = robot.odometry()
            distance += math.hypot(new_pose.x - pose.x, new_pose.y - pose.y)
            pose = new_pose
            if on_step is not None and _take_update(f, on_step(pose, t)):
                outcome = DriveOutcome.ABORTED
                break
            cmd = f.command(pose, t)
            if cmd.status in _FOLLOWER_ENDS:
                outcome = _FOLLOWER_ENDS[cmd.status]
                break
            if t - t0 >= timeout:
                break
            robot.drive(cmd.v, cmd.omega)  # every step, so the command watchdog never fires
            steps += 1
            robot.step(dt)
    finally:
        with contextlib.suppress(Exception):
            robot.stop()
    return _drive_result(f, outcome, pose, robot.now() - t0, steps, distance)


#: Follower states that end a :func:`drive_to` run, and how.
_FOLLOWER_ENDS = {FollowStatus.ARRIVED: DriveOutcome.ARRIVED, FollowStatus.NO_PATH: DriveOutcome.NO_PATH}


def _check_control_period(robot: Robot, dt: float, timeout: float) -> None:
    """Refuse a control period ``dt`` [s] outside ``(0, robot.cmd_timeout_s)`` and a timeout [s] that is
    not a finite number > 0 (ValueError)."""
    if not (math.isfinite(dt) and 0 < dt < robot.cmd_timeout_s):
        raise ValueError(f"dt must be within (0, {robot.cmd_timeout_s}) s (the command watchdog), got {dt!r}")
    if not (math.isfinite(timeout) and timeout > 0):
        raise ValueError(f"timeout must be a finite number > 0 s, got {timeout!r}")


def _take_update(f: PathFollower, upd: StepUpdate | None) -> bool:
    """Hand a step callback's new path (and heading) to the follower; True when it asks to abort."""
    if upd is None:
        return False
    if upd.abort:
        return True
    if upd.waypoints is not None:
        heading = upd.final_heading if upd.final_heading is not None else f.final_heading
        f.set_path(upd.waypoints, heading)
    return False


def _drive_result(
    f: PathFollower, outcome: DriveOutcome, pose: Pose2D, elapsed_s: float, steps: int, distance_m: float
) -> DriveResult:
    """The :class:`DriveResult` of a run that ended at ``pose``, with its errors to the follower's goal."""
    goal = f.goal_xy
    pos_err = math.inf if goal is None else math.hypot(goal[0] - pose.x, goal[1] - pose.y)
    head_err = None if f.final_heading is None else wrap_angle(f.final_heading - pose.theta)
    return DriveResult(outcome, pose, elapsed_s, steps, distance_m, pos_err, head_err)
