"""Movers of the carried box: limits hold, the evasive operator hides the unique face, teleop obeys."""

import math

import numpy as np
import pytest

from lab.errors import ConfigError
from lab.geometry import Pose2D, wrap_angle
from lab.sim import SimRobot, SimWorld, load_box_models
from lab.sim.movers import MoverLimits, make_mover


@pytest.fixture
def world():
    with SimWorld("arena") as w:
        yield w


def test_evasive_mover_turns_the_unique_face_away_within_its_turn_rate(world):
    c = world.add_carrier(load_box_models()[0], Pose2D(0.0, 0.0, 0.0), box_yaw=math.pi)  # +X faces -x
    robot = SimRobot(world, start=Pose2D(-1.2, 0.0, 0.0))
    c.mover = make_mover("evasive", c, observer_pose=world.truth.robot_pose)
    limit = c.mover.limits.max_box_turn_rate
    yaws = []
    for _ in range(300):
        robot.step(0.1)
        yaws.append(c.box_yaw)
    steps = np.abs(wrap_angle(np.diff(yaws)))
    assert steps.max() <= limit * 0.1 + 1e-9
    # the unique face (+X) now points away from the robot: along the robot -> box direction (+x)
    assert abs(wrap_angle(c.pose.theta + c.box_yaw - 0.0)) < math.radians(5)


def test_teleop_and_limits(world):
    c = world.add_carrier(load_box_models()[1], Pose2D(0.0, 0.0, 0.0))
    c.mover = make_mover("teleop", c, limits=MoverLimits(max_speed=0.1))
    c.mover.set(v=1.0)  # clamped to 0.1 m/s
    world.step(2.0)
    assert c.pose.x == pytest.approx(0.2, abs=1e-9)
    with pytest.raises(ValueError, match="v must be finite"):
        c.mover.set(v=float("nan"))


def test_random_and_scripted_movers_stay_near_home(world):
    c = world.add_carrier(load_box_models()[2], Pose2D(0.0, 0.0, 0.0))
    for kind in ("random", "scripted"):
        c.set_pose(Pose2D(0.0, 0.0, 0.0))
        c.mover = make_mover(kind, c, seed=3)
        for _ in range(600):
            world.step(0.1)
            assert math.hypot(c.pose.x, c.pose.y) < 1.3


def test_unknown_mover_names_the_choices(world):
    c = world.add_carrier(load_box_models()[3], Pose2D(0.0, 0.0, 0.0))
    with pytest.raises(
        ConfigError, match="unknown mover 'sneaky'; movers: static, scripted, random, evasive"
    ):
        make_mover("sneaky", c)
