"""A robot walled in by marks that are not there drives out: the navigator forgets the marks within the
escape's reach, scans all round, and plans on what it saw (``DriveLoop._sense_again_when_walled_in``).

The marks are what a search robot at error scale 2 was left with (docs/tuning/localizer-odometry-told.md):
the lab room's table marked while the pose estimate was 45 cm off, its ghost ringing the robot once a
landmark update put the estimate right. Here the ghost is a ring of marks from the footprint's edge to
0.45 m, within the escape's 0.5 m reach, with no straight line out. The robot stands beside the real table,
whose corner is 0.36 m from its centre, so forgetting the marks forgets a real obstacle too: the scan
must mark it again.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from lab.geometry import Pose2D
from lab.navigation import Costmap, Navigator, NavOutcome, room_bounds
from lab.navigation.drive_loop import DriveLoop
from lab.robot import StereoCamera
from lab.scene import load_scene
from lab.sim import SimRobot, SimWorld

START = Pose2D(-1.65, -0.30, math.radians(122.0))
GOAL = (-0.3, -0.2)  # open floor, 1.35 m east
TABLE = (-2.6, -2.0, -1.6, -0.4)  # the lab room's table: x0, x1, y0, y1 [m]


def _walled_in(world: SimWorld) -> tuple[SimRobot, Navigator]:
    robot = SimRobot(world, StereoCamera.from_fov(), start=START, seed=0)
    robot.enable()
    nav = Navigator(robot, bounds=room_bounds(load_scene("lab_room")))
    X, Y = nav.spec.cell_centers()
    d = np.hypot(X - START.x, Y - START.y)
    x0, x1, y0, y1 = TABLE
    table = (X >= x0) & (X <= x1) & (Y >= y0) & (Y <= y1)  # marked where it is, as seen before
    ring = (d > robot.base_limits.radius) & (d <= 0.45)  # and its ghost round the robot, no line out
    nav.costmap = Costmap.from_occupancy(nav.spec, table | ring)
    return robot, nav


def _table_marked(nav: Navigator) -> bool:
    X, Y = nav.spec.cell_centers()
    x0, x1, y0, y1 = TABLE
    edge = (
        (X >= x0)
        & (X <= x1 + 0.1)
        & (Y >= y0)
        & (Y <= y1 + 0.1)
        & (np.hypot(X - START.x, Y - START.y) <= 0.5)
    )
    return bool((nav.costmap.obstacle & edge).any())


def test_a_robot_ringed_by_ghost_marks_scans_and_drives_out_without_touching_the_table():
    with SimWorld("lab_room") as world:
        robot, nav = _walled_in(world)
        res = nav.go_to(GOAL, 0.0, timeout=60.0)
        true = world.truth.robot_pose()
        print(f"\nwalled in: {res.outcome.name}, frames {res.frames}, collisions {world.truth.collisions}")
        assert res.outcome is NavOutcome.ARRIVED, res
        assert world.truth.collisions == 0
        assert math.hypot(true.x - GOAL[0], true.y - GOAL[1]) <= 0.10
        assert _table_marked(nav)  # the scan marked the real table's corner again


def test_without_the_scan_it_stays_walled_in(monkeypatch):
    monkeypatch.setattr(DriveLoop, "_sense_again_when_walled_in", lambda self, d: d)
    with SimWorld("lab_room") as world:
        robot, nav = _walled_in(world)
        res = nav.go_to(GOAL, 0.0, timeout=60.0)
        assert res.outcome is NavOutcome.NO_PATH and res.reason == "START_IN_OBSTACLE"
        assert world.truth.robot_pose() == pytest.approx(START, abs=1e-3)
