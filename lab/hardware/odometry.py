"""Wheel odometry of a differential-drive base: unwrapping 16-bit encoder counts, and dead reckoning."""

from __future__ import annotations

import math

from lab.geometry import Pose2D, wrap_angle

__all__ = ["DiffDriveOdometry", "EncoderUnwrapper", "unwrap_delta"]


def unwrap_delta(old: int, new: int) -> int:
    """Signed change between two 16-bit encoder readings: ``((new - old + 32768) % 65536) - 32768``."""
    return ((int(new) - int(old) + 32768) % 65536) - 32768


class EncoderUnwrapper:
    """Turns a wrapping 16-bit count into an unbounded (Python int / int64) tick count."""

    def __init__(self):
        self._raw: int | None = None
        self.total = 0

    def rebase(self) -> None:
        """Forget the last raw reading (after a reconnect): the next one moves nothing."""
        self._raw = None

    def update(self, raw: int) -> int:
        """Feed a raw reading; return the change in ticks since the previous one."""
        d = 0 if self._raw is None else unwrap_delta(self._raw, raw)
        self._raw = int(raw) & 0xFFFF
        self.total += d
        return d


class DiffDriveOdometry:
    """Differential-drive dead reckoning from encoder ticks, exact for each constant-curvature step.

    ``ds = (dl + dr) / 2``, ``dtheta = (dr - dl) / wheel_base``, ``dl = ticks_l * pi * d / ticks_per_rev``;
    the robot moves the chord ``ds * sin(dtheta/2) / (dtheta/2)`` along the heading ``theta + dtheta/2``.
    Create 2: 508.8 ticks per revolution, 72 mm wheels, 235 mm axle.
    """

    def __init__(
        self, ticks_per_rev: float = 508.8, wheel_diameter: float = 0.072, wheel_base: float = 0.235
    ):
        self.m_per_tick = math.pi * wheel_diameter / ticks_per_rev
        self.wheel_base = wheel_base
        self.x = self.y = self.theta = 0.0

    def update(self, d_left_ticks: int, d_right_ticks: int) -> None:
        dl = d_left_ticks * self.m_per_tick
        dr = d_right_ticks * self.m_per_tick
        ds = 0.5 * (dl + dr)
        dth = (dr - dl) / self.wheel_base
        # exact for a constant-curvature step: the chord 2 R sin(dth/2) along the midpoint heading
        chord = ds if abs(dth) < 1e-9 else ds * math.sin(0.5 * dth) / (0.5 * dth)
        th_mid = self.theta + 0.5 * dth
        self.x += chord * math.cos(th_mid)
        self.y += chord * math.sin(th_mid)
        self.theta = wrap_angle(self.theta + dth)

    @property
    def pose(self) -> Pose2D:
        return Pose2D(self.x, self.y, self.theta)
