"""The head's and the base's state at a frame's exposure time, from readings taken before and after it.

A camera delivers a frame some time after it was exposed (a rendered one: after the render); reading the
head or the odometry only afterwards would pair the image with a later angle or pose. The robot reads
both just before and just after the capture and interpolates to the frame's timestamp.
"""

from __future__ import annotations

import math

from lab.geometry import Pose2D
from lab.robot import PanTiltState

__all__ = ["pan_tilt_at", "pose_at"]


def _fraction(t: float, t0: float, t1: float) -> float:
    """Where ``t`` lies between ``t0`` and ``t1``, clamped to [0, 1]."""
    return 0.0 if t1 <= t0 else min(1.0, max(0.0, (t - t0) / (t1 - t0)))


def pan_tilt_at(t: float, a: PanTiltState, b: PanTiltState) -> PanTiltState:
    """The head's state at ``t`` [s], linearly between readings ``a`` (before the frame) and ``b`` (after).

    A camera delivers a frame some time after it was exposed (a rendered one: after the render); reading
    the head only afterwards would pair the image with a later head angle.
    """
    s = _fraction(t, a.t, b.t)
    return PanTiltState(
        a.pan + s * (b.pan - a.pan),
        a.tilt + s * (b.tilt - a.tilt),
        t,
        b.pan_target,
        b.tilt_target,
        a.moving or b.moving,
    )


def pose_at(t: float, a: tuple[float, Pose2D], b: tuple[float, Pose2D]) -> Pose2D:
    """The odometry pose at ``t`` [s], linearly between ``(t_a, pose_a)`` and ``(t_b, pose_b)``."""
    (ta, pa), (tb, pb) = a, b
    s = _fraction(t, ta, tb)
    dth = math.atan2(math.sin(pb.theta - pa.theta), math.cos(pb.theta - pa.theta))
    th = pa.theta + s * dth
    return Pose2D(pa.x + s * (pb.x - pa.x), pa.y + s * (pb.y - pa.y), math.atan2(math.sin(th), math.cos(th)))
