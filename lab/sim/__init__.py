"""The simulator: the only package that imports pybullet.

``SimWorld`` loads a scene file (``worlds/*.toml``) into its own headless PyBullet client and renders
stereo views; ``SimRobot`` is the simulated robot behind the :class:`lab.robot.Robot` interface; ground
truth, for tests and scoring only, is reached through the read-only views ``SimWorld.truth`` and
``SimRobot.truth`` (which the world's reads).
"""

from lab.scene import Scene, list_worlds, load_scene
from lab.sim.robot import OdometryNoise, SimRobot
from lab.sim.sensing import (
    CameraErrors,
    OdometryErrors,
    PanTiltErrors,
    RoomErrors,
    SensingProfile,
    sensing_profile,
)
from lab.sim.world import Carrier, RenderSettings, SimWorld, box_model, load_box_models, viewpoint_G_WC

__all__ = [
    "CameraErrors",
    "Carrier",
    "OdometryErrors",
    "OdometryNoise",
    "PanTiltErrors",
    "RenderSettings",
    "RoomErrors",
    "Scene",
    "SensingProfile",
    "SimRobot",
    "SimWorld",
    "box_model",
    "list_worlds",
    "load_box_models",
    "load_scene",
    "sensing_profile",
    "viewpoint_G_WC",
]
