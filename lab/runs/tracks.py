"""The robot's path through a run, three ways: wheel odometry, the pose estimate, and the truth.

A run's figures draw the path the robot's wheels measured beside the one its localizer estimated
(:class:`~lab.localization.LocalizedRobot`) and, where it is known, the true one.
:class:`TrackedRobot` records them while the run goes: it wraps the localized robot the agent drives and,
at every ``step`` (no more often than ``record_every_s``), samples

* the **odometry**: the localized robot's base's pose (the wheel odometry, in the room's frame),
* the **estimate**: the localized robot's ``odometry()`` (the localized pose; in ``odometry`` mode the
  same as the odometry),
* the **truth**: ``truth_pose()``, a callable the run hands in (the simulator's or a rehearsal's true
  base pose; None on the real robot).

The truth is only recorded, for figures and scoring: nothing the agent calls returns it. A landmark
update moves the estimate without a step (in ``capture_stereo``); the next step's sample shows the jump.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from lab.errors import ConfigError
from lab.geometry import Pose2D
from lab.localization import LocalizedRobot
from lab.robot import RobotWrapper

__all__ = ["RobotTrack", "TrackedRobot"]


@dataclass(frozen=True)
class RobotTrack:
    """The robot's planar pose through a run, sampled at times ``t``.

    Attributes
    ----------
    t : ndarray, shape (n,) [s]
        The robot's clock at each sample.
    odometry : ndarray, shape (n, 3) [m, m, rad]
        Wheel odometry ``x, y, theta`` in the room's frame.
    estimate : ndarray, shape (n, 3) [m, m, rad]
        The pose the agent used: the localized pose with ``landmarks``, the odometry with ``odometry``.
    truth : ndarray, shape (n, 3) [m, m, rad], or None
        The true base pose (scoring and figures only); None where there is no truth (the real robot).
    localization : str
        ``odometry`` or ``landmarks`` (:class:`~lab.localization.LocalizationMode`).
    landmark_updates : int
        Landmark observations the localizer used by the end (0 with ``landmarks``: none was seen, and
        the estimate is dead reckoning from the start).
    """

    t: np.ndarray = field(repr=False)
    odometry: np.ndarray = field(repr=False)
    estimate: np.ndarray = field(repr=False)
    truth: np.ndarray | None = field(default=None, repr=False)
    localization: str = "odometry"
    landmark_updates: int = 0

    def __len__(self) -> int:
        return len(self.t)

    @property
    def localized(self) -> bool:
        """Whether the estimate is the landmark localizer's (not the odometry passed through)."""
        return self.localization == "landmarks"


class TrackedRobot(RobotWrapper):
    """A localized robot that records its :class:`RobotTrack` as it steps (see the module docstring).

    Parameters
    ----------
    robot : LocalizedRobot
        The robot the agent drives (every call is passed on to it).
    truth_pose : callable () -> Pose2D or None, optional
        The true base pose now, for the record only; None (or returning None): no truth.
    record_every_s : float [s]
        Least spacing of the samples on the robot's clock.
    """

    def __init__(
        self,
        robot: LocalizedRobot,
        truth_pose: Callable[[], Pose2D | None] | None = None,
        record_every_s: float = 0.2,
    ):
        if not isinstance(robot, LocalizedRobot):
            raise ConfigError(f"TrackedRobot records a LocalizedRobot's poses, got {type(robot).__name__}")
        every = record_every_s
        if not (isinstance(every, (int, float)) and math.isfinite(every) and every > 0):
            raise ConfigError(f"record_every_s must be a finite number of seconds > 0, got {every!r}")
        super().__init__(robot)
        self._truth_pose = truth_pose
        self._every = float(record_every_s)
        self._rows: list[tuple[float, ...]] = []
        self._has_truth = truth_pose is not None
        self.record(force=True)

    def record(self, force: bool = False) -> None:
        """Sample the three poses now (unless the last sample is less than ``record_every_s`` old)."""
        t = self.base.now()
        if not force and self._rows and t - self._rows[-1][0] < self._every:
            return
        odom = self.base.base.odometry()  # the localized robot's base: the wheel odometry
        est = self.base.odometry()
        true = self._truth_pose() if self._has_truth else None
        if true is None:
            self._has_truth = False  # a truth missing once is no truth for the track
        row = (t, odom.x, odom.y, odom.theta, est.x, est.y, est.theta)
        self._rows.append(row + ((true.x, true.y, true.theta) if true is not None else (math.nan,) * 3))

    def step(self, dt: float) -> None:
        self.base.step(dt)
        self.record()

    def relocalize(self, *args, **kwargs) -> bool:
        """The localized robot's active re-localization (it steps its base: no samples on the way), then
        a sample with the corrected estimate."""
        done = self.base.relocalize(*args, **kwargs)
        self.record(force=True)
        return done

    def relocalize_to_report(self, at_W=None) -> bool:
        """The localized robot's re-localization before a report, then a sample (as :meth:`relocalize`)."""
        done = self.base.relocalize_to_report(at_W)
        self.record(force=True)
        return done

    def track(self) -> RobotTrack:
        """What was recorded so far."""
        a = np.array(self._rows, dtype=float).reshape(-1, 10)
        return RobotTrack(
            a[:, 0].copy(),
            a[:, 1:4].copy(),
            a[:, 4:7].copy(),
            a[:, 7:10].copy() if self._has_truth else None,
            self.base.mode.value,
            self.base.localizer.n_updates,
        )
