"""A bump reaches the navigator through the search's wrapper: driving into an obstacle it could not see
(dropped low, right in front of the base) ends the drive with BUMPED, the base stopped."""

from __future__ import annotations

import math

from lab.geometry import Pose2D
from lab.navigation import Navigator, NavOutcome, room_bounds
from lab.robot import StereoCamera
from lab.scene import load_scene
from lab.search.budget import BudgetedRobot
from lab.sim import SimRobot, SimWorld


def test_driving_into_an_obstacle_through_the_budget_wrapper_ends_bumped():
    start, goal = Pose2D(0.0, -3.2, math.pi / 2), (0.0, 2.0)
    with SimWorld("lab_room") as world:
        robot = SimRobot(world, StereoCamera.from_fov(), start=start, seed=0)
        robot.enable()
        budgeted = BudgetedRobot(robot, max_time_s=60.0)  # what the search hands the navigator
        nav = Navigator(budgeted, bounds=room_bounds(load_scene("lab_room")))
        step = robot.step
        dropped = []

        def step_and_drop(dt):
            step(dt)
            p = world.truth.robot_pose()
            if not dropped and p.y - start.y > 0.05:  # under way: a low box just ahead of its front
                d = robot.base_limits.radius + 0.12
                world.add_box(
                    "low_box", (0.4, 0.2, 0.12), (p.x + d * math.cos(p.theta), p.y + d * math.sin(p.theta))
                )
                dropped.append(p)

        robot.step = step_and_drop
        res = nav.go_to(goal, math.pi / 2, timeout=40.0)
        assert dropped, "the robot never set off"
        assert world.truth.collisions >= 1 and budgeted.bumps == robot.bumps == world.truth.collisions
        assert res.outcome is NavOutcome.BUMPED, res
        p0 = world.truth.robot_pose()
        robot.step(0.5)
        p1 = world.truth.robot_pose()
        assert math.hypot(p1.x - p0.x, p1.y - p0.y) < 0.005  # stopped
