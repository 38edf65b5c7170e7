"""Candidate actions: the paper's *calcPossibleControlActions* (Sec. IV).

An action ``u+`` is a goal pose of the robot on a ring around the probability-weighted object estimate
(the paper's Fig. 6: "the equatorial ring is centered on the object"), every ``step_deg`` degrees, the
robot facing the object and the pan-tilt aimed at the object's centre, as the tracking loop will hold
it. The planner scores each action by the camera pose it leads to (:attr:`CandidateAction.G_WC`).

Goals that the caller's ``is_reachable(pose) -> bool`` rejects (inside an obstacle, no path on the
costmap, outside the room) are left out; :func:`reachable_on` builds such a predicate from a
:class:`lab.navigation.CostGrid` and the robot's pose. When no goal of the ring is reachable, the rings
of ``fallback_radii_m`` are tried in turn; when none has a reachable goal, :class:`RingBlocked` is
raised so that the caller can act on it (hold position and keep observing, scan, or replan from
elsewhere).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from lab.errors import ConfigError, LabError
from lab.geometry import Pose2D, se3_inv, transform_points, wrap_angle
from lab.robot import StereoCamera

__all__ = [
    "ActionConfig",
    "CandidateAction",
    "RingBlocked",
    "aim_pan_tilt",
    "calc_possible_control_actions",
    "reachable_on",
]


class RingBlocked(LabError, RuntimeError):
    """No goal on any candidate ring is reachable (the message names the radii tried)."""


@dataclass(frozen=True)
class ActionConfig:
    """The ring of candidate goals.

    Attributes
    ----------
    radius_m : float [m]
        Distance from the object's centre to the robot's centre (the training ring's camera distance
        is 1 m; the camera sits a few centimetres ahead of the robot's centre).
    step_deg : float
        Angle between neighbouring goals (10 degrees: 36 candidates, as the training ring).
    fallback_radii_m : tuple of float [m]
        Rings tried, in order, when no goal of the first is reachable.
    """

    radius_m: float = 1.0
    step_deg: float = 10.0
    fallback_radii_m: tuple[float, ...] = (0.8, 1.3)

    def __post_init__(self):
        for r in (self.radius_m, *self.fallback_radii_m):
            if not 0.3 <= r <= 5.0:
                raise ConfigError(f"ring radii must be within [0.3, 5] m, got {r}")
        if not 0 < self.step_deg <= 180 or (360.0 / self.step_deg) % 1 > 1e-9:
            raise ConfigError(f"step_deg must divide 360 (e.g. 10, 15, 30), got {self.step_deg}")


@dataclass(frozen=True)
class CandidateAction:
    """One candidate goal ``u+``.

    Attributes
    ----------
    index : int
        Position on its ring (0 at azimuth 0, counter-clockwise).
    azimuth : float [rad]
        Direction from the object's centre to the goal, in W.
    radius_m : float [m]
    pose : Pose2D
        The robot's goal pose in W, facing the object's centre.
    pan, tilt : float [rad]
        The pan-tilt state that aims the camera at the object's centre from there.
    G_WC : ndarray, shape (4, 4)
        The camera's pose at the goal (what the planner predicts the measurements from).
    """

    index: int
    azimuth: float
    radius_m: float
    pose: Pose2D
    pan: float
    tilt: float
    G_WC: np.ndarray = field(repr=False)


def aim_pan_tilt(camera: StereoCamera, pose: Pose2D, target_W, iterations: int = 4) -> tuple[float, float]:
    """Pan and tilt [rad] that put ``target_W`` on the optical axis of a robot at ``pose``.

    Starts from the direction seen from the pan axis and corrects for the camera's offset from the
    axes by a few fixed-point steps (x right and y down in C: pan -= atan2(x, z), tilt -= atan2(y, z)).
    """
    t_R = transform_points(se3_inv(pose.G()), np.asarray(target_W, dtype=float)[None])[0]
    m = np.asarray(camera.mount_R, dtype=float)
    pan = math.atan2(t_R[1] - m[1], t_R[0] - m[0])
    tilt = math.atan2(t_R[2] - m[2], math.hypot(t_R[0] - m[0], t_R[1] - m[1]))
    for _ in range(iterations):
        x, y, z = transform_points(se3_inv(camera.G_RC(pan, tilt)), t_R[None])[0]
        pan -= math.atan2(x, z)
        tilt -= math.atan2(y, z)
    return float(wrap_angle(pan)), float(tilt)


def _ring(centre_W, camera: StereoCamera, radius: float, step_deg: float) -> list[CandidateAction]:
    c = np.asarray(centre_W, dtype=float)
    # every goal sees the centre from the same place relative to the robot: one aim serves the ring
    pan, tilt = aim_pan_tilt(camera, Pose2D(c[0] - radius, c[1], 0.0), c)
    G_RC = camera.G_RC(pan, tilt)
    out = []
    for k, az in enumerate(np.radians(np.arange(0.0, 360.0, step_deg))):
        x, y = c[0] + radius * math.cos(az), c[1] + radius * math.sin(az)
        pose = Pose2D(float(x), float(y), float(wrap_angle(az + math.pi)))  # facing the centre
        out.append(CandidateAction(k, float(az), radius, pose, pan, tilt, pose.G() @ G_RC))
    return out


def calc_possible_control_actions(
    centre_W,
    camera: StereoCamera,
    config: ActionConfig | None = None,
    is_reachable: Callable[[Pose2D], bool] | None = None,
) -> tuple[CandidateAction, ...]:
    """The paper's *calcPossibleControlActions*: reachable goal poses on a ring around the object.

    Parameters
    ----------
    centre_W : array_like, shape (3,) [m]
        The probability-weighted object centre (:meth:`ModelHypotheses.object_centre_W`).
    camera : StereoCamera
        The robot's camera (its mounting gives the camera pose at each goal).
    config : ActionConfig, optional
    is_reachable : callable Pose2D -> bool, optional
        False for goals the robot cannot or must not reach; every goal is kept when omitted.

    Returns
    -------
    tuple of CandidateAction
        The reachable goals of the first ring (in ``radius_m``, then ``fallback_radii_m``) that has any.

    Raises
    ------
    RingBlocked
        No goal of any ring is reachable.
    ConfigError
        ``centre_W`` is not a finite 3-vector.
    """
    config = config or ActionConfig()
    c = np.asarray(centre_W, dtype=float)
    if c.shape != (3,) or not np.all(np.isfinite(c)):
        raise ConfigError(f"centre_W must be a finite (x, y, z) in metres, got {centre_W!r}")
    radii = (config.radius_m, *config.fallback_radii_m)
    for r in radii:
        ring = _ring(c, camera, r, config.step_deg)
        if is_reachable is not None:
            ring = [a for a in ring if is_reachable(a.pose)]
        if ring:
            return tuple(ring)
    tried = ", ".join(f"{r:g}" for r in radii)
    raise RingBlocked(
        f"every goal around the object at ({c[0]:.2f}, {c[1]:.2f}) is blocked or unreachable "
        f"(rings of radius {tried} m, every {config.step_deg:g} deg): hold position and keep observing, "
        f"or scan and replan"
    )


def reachable_on(grid, start: Pose2D) -> Callable[[Pose2D], bool]:
    """``is_reachable`` for :func:`calc_possible_control_actions` from a navigation cost grid.

    A goal is reachable when A* finds a path from ``start`` to it on ``grid``
    (a :class:`lab.navigation.CostGrid`, obstacles already grown by the robot's radius).
    """
    from lab.navigation import PathStatus, astar

    def is_reachable(pose: Pose2D) -> bool:
        return astar(grid, start, pose).status is PathStatus.FOUND

    return is_reachable
