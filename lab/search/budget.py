"""The search's time budget: a :class:`~lab.robot.Robot` wrapper that refuses to step past a deadline.

:class:`BudgetedRobot` wraps the robot the :class:`~lab.search.agent.SearchAgent` drives: once its
clock passes the deadline, the next ``step`` raises :class:`SearchBudgetExceeded` -- inside the
navigator, a pan-tilt wait or a drive -- and the agent ends the run there ("time budget"). A
wall-clock limit can be added the same way. It also measures the path length from the wheel odometry
(a landmark correction of a localized pose is not distance driven) and keeps the pose the agent sees
as the trajectory for the figures.
"""

from __future__ import annotations

import math
import time

from lab.errors import ConfigError, LabError
from lab.robot import Robot, RobotWrapper

__all__ = ["BudgetedRobot", "SearchBudgetExceeded"]


class SearchBudgetExceeded(LabError):
    """The search's time budget ran out (raised from :meth:`BudgetedRobot.step`)."""


class BudgetedRobot(RobotWrapper):
    """A :class:`~lab.robot.Robot` that refuses to step past a deadline, and measures the path.

    Parameters
    ----------
    base : Robot
        The robot to drive (every call is passed on to it).
    max_time_s : float [s]
        Robot-clock budget from now.
    max_wall_s : float [s], optional
        Wall-clock budget from now.
    record_every_s : float [s]
        Spacing of the recorded odometry trajectory.
    """

    def __init__(self, base: Robot, max_time_s: float, max_wall_s: float | None = None, record_every_s=0.2):
        if not (math.isfinite(max_time_s) and max_time_s > 0):
            raise ConfigError(f"the time budget must be a finite number > 0 s, got {max_time_s!r}")
        super().__init__(base)
        self.t_start = base.now()
        self.deadline = self.t_start + float(max_time_s)
        self.wall_deadline = None if max_wall_s is None else time.perf_counter() + float(max_wall_s)
        self.path_length_m = 0.0  # the wheels' path: base.wheel_odometry()
        p = base.odometry()
        self._wheels = base.wheel_odometry()
        self.trajectory: list[tuple[float, float, float, float]] = [(self.t_start, p.x, p.y, p.theta)]
        self._record_every = record_every_s

    # budget and bookkeeping
    def check(self) -> None:
        """Raise :class:`SearchBudgetExceeded` once a budget is used up (what :meth:`step` does first):
        for work done on the robot underneath, which time passes on without this wrapper's step."""
        if self.base.now() >= self.deadline:
            raise SearchBudgetExceeded(f"time budget of {self.deadline - self.t_start:g} s used up")
        if self.wall_deadline is not None and time.perf_counter() >= self.wall_deadline:
            raise SearchBudgetExceeded("wall-clock budget used up")

    def step(self, dt: float) -> None:
        self.check()
        self.base.step(dt)
        w = self.base.wheel_odometry()
        self.path_length_m += math.hypot(w.x - self._wheels.x, w.y - self._wheels.y)
        self._wheels = w
        p = self.base.odometry()
        t = self.base.now()
        if t - self.trajectory[-1][0] >= self._record_every:
            self.trajectory.append((t, p.x, p.y, p.theta))

    @property
    def remaining_s(self) -> float:
        return self.deadline - self.base.now()
