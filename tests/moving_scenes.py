"""A moving object's scene for the simulator tests: the object at a seeded floor placement and the robot
``range_m`` from it on the side towards the room's centre, facing it (the set-up the moving local
search and the colour track's following share)."""

from __future__ import annotations

import math

import numpy as np

from lab.geometry import Pose2D
from lab.runs.placement import random_placement
from lab.scene import load_scene


def facing_on_the_floor(obj: str, seed: int, range_m: float):
    """``(scene, centre, start)``: the lab room with ``obj`` at the floor placement of
    ``default_rng(seed)``, the object's centre (x, y, z) [m] and the robot's start pose."""
    scene = load_scene("lab_room")
    place = random_placement(scene, obj, np.random.default_rng(seed), surface="floor")
    scene = scene.with_pose(obj, place)
    ox, oy, oz = scene.body(obj).centre
    a = math.atan2(-oy, -ox)  # towards the room's centre, so the robot stands on the open side
    start = Pose2D(ox + range_m * math.cos(a), oy + range_m * math.sin(a), a + math.pi)
    return scene, (ox, oy, oz), start
