"""Movers: what drives the carrier (the second robot that carries the box) in the identification runs.

The paper's object robot was driven by a human operator who turned the box so that its unique face
stayed hidden from the observing robot. :class:`EvasiveMover` plays that operator; the others are
baselines and tools. A mover is part of the world, like the operator: it may look at the true poses
(it "sees" the robot), which the identifying agent never can.

Every mover has ``step(t, dt)``, called by :meth:`SimWorld.step` before the carrier moves, and sets the
carrier's velocity and the box's yaw rate within its limits.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

import numpy as np

from lab.errors import ConfigError
from lab.geometry import wrap_angle

__all__ = [
    "MoverKind",
    "MoverLimits",
    "Mover",
    "StaticMover",
    "ScriptedMover",
    "RandomMover",
    "EvasiveMover",
    "TeleopMover",
    "make_mover",
]


class MoverKind(Enum):
    STATIC = "static"
    SCRIPTED = "scripted"
    RANDOM = "random"
    EVASIVE = "evasive"
    TELEOP = "teleop"


@dataclass(frozen=True)
class MoverLimits:
    """Speed [m/s], turn rate [rad/s] of the carrier, and turn rate [rad/s] of the box on it."""

    max_speed: float = 0.1
    max_turn_rate: float = 0.5
    max_box_turn_rate: float = 0.15


class Mover:
    """Base class: holds the carrier and its limits; subclasses decide the motion in :meth:`command`."""

    kind: MoverKind

    def __init__(self, carrier, limits: MoverLimits | None = None):
        self.carrier = carrier
        self.limits = limits or MoverLimits()
        self.box_rate = 0.0

    def command(self, t: float, dt: float) -> tuple[float, float, float]:
        """(v [m/s], omega [rad/s], box yaw rate [rad/s]) for the next ``dt``."""
        return 0.0, 0.0, 0.0

    def step(self, t: float, dt: float) -> None:
        L = self.limits
        v, omega, box_rate = self.command(t, dt)
        self.carrier.set_velocity(
            float(np.clip(v, -L.max_speed, L.max_speed)),
            float(np.clip(omega, -L.max_turn_rate, L.max_turn_rate)),
        )
        self.box_rate = float(np.clip(box_rate, -L.max_box_turn_rate, L.max_box_turn_rate))
        if self.box_rate:
            self.carrier.box_yaw = wrap_angle(self.carrier.box_yaw + self.box_rate * dt)


class StaticMover(Mover):
    kind = MoverKind.STATIC


class ScriptedMover(Mover):
    """Drives a fixed pattern: forward, turn, forward, ... (a slow square of side ``side`` metres)."""

    kind = MoverKind.SCRIPTED

    def __init__(self, carrier, limits=None, side: float = 0.6):
        super().__init__(carrier, limits)
        self.side = side

    def command(self, t, dt):
        L = self.limits
        t_side = self.side / L.max_speed
        t_turn = (math.pi / 2) / L.max_turn_rate
        phase = t % (t_side + t_turn)
        return (L.max_speed, 0.0, 0.0) if phase < t_side else (0.0, L.max_turn_rate, 0.0)


class RandomMover(Mover):
    """A random walk at the velocity level (seeded), kept within ``radius`` metres of its start."""

    kind = MoverKind.RANDOM

    def __init__(self, carrier, limits=None, seed: int = 0, radius: float = 0.8):
        super().__init__(carrier, limits)
        self.rng = np.random.default_rng(seed)
        self.home = (carrier.pose.x, carrier.pose.y)
        self.radius = radius
        self.v = 0.0
        self.omega = 0.0
        self.w_box = 0.0

    def command(self, t, dt):
        L = self.limits
        p = self.carrier.pose
        self.v = float(np.clip(self.v + 0.05 * self.rng.standard_normal() * math.sqrt(dt), 0.0, L.max_speed))
        self.omega = float(
            np.clip(
                self.omega + 0.3 * self.rng.standard_normal() * math.sqrt(dt),
                -L.max_turn_rate,
                L.max_turn_rate,
            )
        )
        self.w_box = float(
            np.clip(
                self.w_box + 0.1 * self.rng.standard_normal() * math.sqrt(dt),
                -L.max_box_turn_rate,
                L.max_box_turn_rate,
            )
        )
        dx, dy = p.x - self.home[0], p.y - self.home[1]
        if math.hypot(dx, dy) > self.radius:  # head home
            err = wrap_angle(math.atan2(-dy, -dx) - p.theta)
            return self.v, 2.0 * err, self.w_box
        return self.v, self.omega, self.w_box


class EvasiveMover(Mover):
    """The paper's operator: turns the box so its unique face points away from the observer.

    The box's unique face is its +X face. The mover turns the box (at most ``max_box_turn_rate``) so
    that +X points along the line from the observer to the box, i.e. away from it; it reacts with a
    delay of ``reaction_s`` seconds, as a person would.
    """

    kind = MoverKind.EVASIVE

    def __init__(self, carrier, observer_pose, limits=None, reaction_s: float = 0.5, gain: float = 1.5):
        super().__init__(carrier, limits)
        self.observer_pose = observer_pose  # callable returning the observer's true Pose2D
        self.reaction_s = reaction_s
        self.gain = gain
        self._seen: list[tuple[float, float, float]] = []

    def command(self, t, dt):
        o = self.observer_pose()
        self._seen.append((t, o.x, o.y))
        while len(self._seen) > 1 and self._seen[1][0] <= t - self.reaction_s:
            self._seen.pop(0)
        _, ox, oy = self._seen[0]
        p = self.carrier.pose
        away = math.atan2(p.y - oy, p.x - ox)  # world direction from the observer to the box
        box_world_yaw = p.theta + self.carrier.box_yaw
        err = wrap_angle(away - box_world_yaw)
        return 0.0, 0.0, self.gain * err


class TeleopMover(Mover):
    """Driven by calls (notebook widgets, the classroom demo): :meth:`set` holds until changed."""

    kind = MoverKind.TELEOP

    def __init__(self, carrier, limits=None):
        super().__init__(carrier, limits)
        self._cmd = (0.0, 0.0, 0.0)

    def set(self, v: float = 0.0, omega: float = 0.0, box_rate: float = 0.0) -> None:
        for name, x in (("v", v), ("omega", omega), ("box_rate", box_rate)):
            if not math.isfinite(float(x)):
                raise ValueError(f"{name} must be finite, got {x!r}")
        self._cmd = (float(v), float(omega), float(box_rate))

    def command(self, t, dt):
        return self._cmd


def make_mover(
    kind: str | MoverKind, carrier, observer_pose=None, seed: int = 0, limits: MoverLimits | None = None
) -> Mover:
    """A mover by name: static, scripted, random, evasive or teleop."""
    try:
        kind = MoverKind(kind) if isinstance(kind, str) else kind
    except ValueError:
        raise ConfigError(
            f"unknown mover {kind!r}; movers: {', '.join(k.value for k in MoverKind)}"
        ) from None
    if kind is MoverKind.STATIC:
        return StaticMover(carrier, limits)
    if kind is MoverKind.SCRIPTED:
        return ScriptedMover(carrier, limits)
    if kind is MoverKind.RANDOM:
        return RandomMover(carrier, limits, seed=seed)
    if kind is MoverKind.EVASIVE:
        if observer_pose is None:
            raise ConfigError("the evasive mover needs the observer's pose (observer_pose)")
        return EvasiveMover(carrier, observer_pose, limits)
    return TeleopMover(carrier, limits)
