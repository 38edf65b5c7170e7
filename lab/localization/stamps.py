r"""The odometry at an image's time stamp: a short history of stamped readings, interpolated.

A USB camera's frame is 30-100 ms old when it arrives, and the robot is moving: at 0.3 m/s and
1 rad/s that is 3 cm and 6 deg between the image and the odometry read with it. The localizer's
landmark update and everything placed in the world from the frame must use the robot's pose at the
image's stamp. :class:`OdometryHistory` keeps the wheel odometry's recent readings with their stamps;
:meth:`OdometryHistory.at` gives the pose at any stamp between two of them by
:func:`interpolate_pose`, which moves along the constant-velocity arc joining them (the geodesic of
SE(2)), exact for a base driven at constant wheel speeds between the two readings:

.. math:: \xi = \log(G_a^{-1} G_b) = (v_x, v_y, \omega), \qquad
          G(t) = G_a \exp\!\Big(\frac{t - t_a}{t_b - t_a}\, \xi\Big)

with, for a twist :math:`(v, \omega)` scaled by :math:`s`, :math:`\exp(s\xi) = (V(s\omega)\, s v,\;
s\omega)` and :math:`V(\phi) = \frac{1}{\phi} \begin{bmatrix} \sin\phi & \cos\phi - 1 \\
1 - \cos\phi & \sin\phi \end{bmatrix}` (:math:`V(0) = I`).

:class:`PanTiltHistory` does the same for the head's angles, linearly: a head slewing at 60 deg/s is
3 deg past where a 50 ms old image shows it.
"""

from __future__ import annotations

import bisect
import math

import numpy as np

from lab.errors import ConfigError
from lab.geometry import Pose2D, wrap_angle
from lab.robot import PanTiltState

__all__ = ["OdometryHistory", "PanTiltHistory", "interpolate_pose"]


def _V(phi: float) -> np.ndarray:
    """``V(phi)`` of the module docstring: the exponential's translation matrix (a series near 0)."""
    if abs(phi) < 1e-6:
        return np.array([[1.0 - phi * phi / 6.0, -phi / 2.0], [phi / 2.0, 1.0 - phi * phi / 6.0]])
    s, c = math.sin(phi), math.cos(phi)
    return np.array([[s, c - 1.0], [1.0 - c, s]]) / phi


def interpolate_pose(t: float, a: tuple[float, Pose2D], b: tuple[float, Pose2D]) -> Pose2D:
    """The pose at ``t`` [s] on the constant-velocity arc from ``(t_a, pose_a)`` to ``(t_b, pose_b)``
    (see the module docstring); ``t`` outside ``[t_a, t_b]`` extrapolates along the same arc."""
    (ta, pa), (tb, pb) = a, b
    if not tb > ta:
        raise ValueError(f"interpolate_pose needs t_b > t_a, got t_a={ta!r}, t_b={tb!r}")
    c, s = math.cos(pa.theta), math.sin(pa.theta)
    d = np.array([c * (pb.x - pa.x) + s * (pb.y - pa.y), -s * (pb.x - pa.x) + c * (pb.y - pa.y)])
    w = wrap_angle(pb.theta - pa.theta)
    v = np.linalg.solve(_V(w), d)  # log: the twist whose exponential is G_a^-1 G_b
    f = (t - ta) / (tb - ta)
    p = _V(f * w) @ (f * v)  # exp(f xi): in pose_a's frame
    return Pose2D(pa.x + c * p[0] - s * p[1], pa.y + s * p[0] + c * p[1], wrap_angle(pa.theta + f * w))


class _StampedHistory:
    """Readings of the last ``span_s`` seconds with their stamps, and the reading at any stamp among
    them (:meth:`at`, by the subclass's :meth:`between`)."""

    def __init__(self, span_s: float = 2.0):
        if not (math.isfinite(span_s) and span_s > 0):
            raise ConfigError(f"{type(self).__name__} span_s must be a finite number > 0 [s], got {span_s!r}")
        self.span_s = float(span_s)
        self.t: list[float] = []
        self.poses: list = []

    def __len__(self) -> int:
        return len(self.t)

    def add(self, t: float, reading) -> None:
        """Keep a reading taken at ``t`` [s]; one older than the newest is ignored (readings come in
        order), one at the newest's stamp replaces it."""
        if self.t and t < self.t[-1]:
            return
        if self.t and t == self.t[-1]:
            self.poses[-1] = reading
            return
        self.t.append(float(t))
        self.poses.append(reading)
        while len(self.t) > 2 and self.t[1] < self.t[-1] - self.span_s:
            del self.t[0], self.poses[0]

    def at(self, t: float):
        """The reading at stamp ``t`` [s]: interpolated between the readings around it
        (:meth:`between`); before the oldest or after the newest reading, that reading (the history
        does not guess motion it has not seen)."""
        if not self.t:
            raise ValueError(f"{type(self).__name__}.at: no reading kept yet")
        if t <= self.t[0]:
            return self.poses[0]
        if t >= self.t[-1]:
            return self.poses[-1]
        i = bisect.bisect_right(self.t, t)  # t[i - 1] <= t < t[i]
        return self.between(t, (self.t[i - 1], self.poses[i - 1]), (self.t[i], self.poses[i]))

    def between(self, t: float, a, b):
        """The reading at ``t`` between readings ``a`` and ``b``, each ``(stamp, reading)``."""
        raise NotImplementedError


class PanTiltHistory(_StampedHistory):
    """The head's readings (:class:`~lab.robot.PanTiltState`, stamped by their ``t``) of the last
    ``span_s`` seconds; :meth:`at` interpolates the angles linearly (a head slewing at a constant
    speed), stamped ``t``."""

    def between(self, t: float, a, b) -> PanTiltState:
        (ta, sa), (tb, sb) = a, b
        f = (t - ta) / (tb - ta)
        return PanTiltState(
            sa.pan + f * (sb.pan - sa.pan),
            sa.tilt + f * (sb.tilt - sa.tilt),
            t,
            sb.pan_target,
            sb.tilt_target,
            sa.moving or sb.moving,
        )


class OdometryHistory(_StampedHistory):
    """The wheel odometry's readings of the last ``span_s`` seconds with their stamps, and the pose at
    any stamp among them (:meth:`at`).

    Parameters
    ----------
    span_s : float [s]
        How far back readings are kept (at least the two newest are always kept): well beyond a
        camera's latency.
    """

    def between(self, t: float, a, b) -> Pose2D:
        """:func:`interpolate_pose` between readings ``a`` and ``b``, ``(stamp, pose)``."""
        return interpolate_pose(t, a, b)
