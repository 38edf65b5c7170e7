"""The carrier: a second differential-drive robot that carries a box (the identification paper's moving
object), integrated by its world at every step and moved by a mover (:mod:`lab.sim.movers`)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from lab.geometry import Pose2D, R_to_quat_xyzw, Rz, compose, se3, translation
from lab.scene import ModelSpec
from lab.sim.client import pybullet

if TYPE_CHECKING:
    from lab.sim.world import SimWorld

__all__ = ["Carrier"]


class Carrier:
    """A second differential-drive robot that carries a box: the moving object of the identification paper.

    Drive it with :meth:`set_velocity`; the world integrates it at every :meth:`SimWorld.step`. The box
    sits on top with its own yaw offset relative to the carrier's heading.
    """

    RADIUS = 0.18
    HEIGHT = 0.35

    def __init__(self, world: SimWorld, name: str, model: ModelSpec, pose: Pose2D, box_yaw: float = 0.0):
        self.world, self.name, self.model = world, name, model
        self.pose = pose
        self.box_yaw = float(box_yaw)
        self.v = 0.0
        self.omega = 0.0
        self.mover = None  # a lab.sim.movers.Mover, set by the caller
        self._placed_box_yaw = self.box_yaw
        pb = world.p
        base_col = pb.createCollisionShape(pybullet.GEOM_CYLINDER, radius=self.RADIUS, height=self.HEIGHT)
        base_vis = pb.createVisualShape(
            pybullet.GEOM_CYLINDER, radius=self.RADIUS, length=self.HEIGHT, rgbaColor=(0.15, 0.15, 0.18, 1)
        )
        self.base_id = pb.createMultiBody(0, base_col, base_vis, (pose.x, pose.y, self.HEIGHT / 2))
        self.box_id = world.create_textured_box(model.size, model.atlas, "atlas")
        world.register(f"{name}/base", self.base_id)
        world.register(name, self.box_id)
        self._place()

    def set_velocity(self, v: float, omega: float) -> None:
        """Forward speed [m/s] and turn rate [rad/s] of the carrier until changed."""
        self.v, self.omega = float(v), float(omega)

    def set_pose(self, pose: Pose2D, box_yaw: float | None = None) -> None:
        self.pose = pose
        if box_yaw is not None:
            self.box_yaw = float(box_yaw)
        self._place()

    @property
    def G_WO(self) -> np.ndarray:
        """True pose of the carried box (object frame O at the box centre) in the world."""
        return compose(
            self.pose.G(), translation(0, 0, self.HEIGHT + self.model.size[2] / 2), se3(Rz(self.box_yaw))
        )

    def _place(self):
        pb = self.world.p
        q = R_to_quat_xyzw(Rz(self.pose.theta))
        pb.resetBasePositionAndOrientation(self.base_id, (self.pose.x, self.pose.y, self.HEIGHT / 2), q)
        G = self.G_WO
        pb.resetBasePositionAndOrientation(self.box_id, G[:3, 3], R_to_quat_xyzw(G[:3, :3]))
        self._placed_box_yaw = self.box_yaw

    def advance(self, dt: float) -> None:
        """Move by the current velocity for ``dt`` [s] (after the mover, if any, has set it)."""
        if self.mover is not None:
            self.mover.step(self.world.t, dt)
        if self.v == 0.0 and self.omega == 0.0:
            if self.box_yaw != self._placed_box_yaw:
                self._place()
            return
        x, y, th = self.pose.x, self.pose.y, self.pose.theta
        th_mid = th + 0.5 * self.omega * dt
        self.pose = Pose2D(
            x + self.v * dt * math.cos(th_mid),
            y + self.v * dt * math.sin(th_mid),
            math.atan2(math.sin(th + self.omega * dt), math.cos(th + self.omega * dt)),
        )
        self._place()
