"""The path follower and drive_to on a kinematic unicycle with the Robot interface (tests/nav_fakes.py).

Checked against ground truth: the true pose at the end (the fake's odometry is exact here), the true
trajectory against the obstacle cells, and every command as the follower issued it against BaseLimits.
"""

import math

import numpy as np
import pytest
from nav_fakes import KinematicRobot

from lab.geometry import Pose2D, wrap_angle
from lab.navigation.astar import astar, astar_to_region, heading_towards
from lab.navigation.costmap import Costmap
from lab.navigation.follower import (
    DriveOutcome,
    FollowStatus,
    PathFollower,
    StepUpdate,
    drive_to,
)
from lab.navigation.grid import GridSpec
from lab.navigation.paths import simplify_path
from lab.robot import BaseLimits

LIMITS = BaseLimits()
DT = 0.05


def clutter_map(rng, n=60, res=0.1, n_boxes=9):
    spec = GridSpec((0.0, 0.0), res, (n, n))
    occ = np.zeros(spec.shape, dtype=bool)
    occ[[0, -1], :] = True
    occ[:, [0, -1]] = True
    for _ in range(n_boxes):
        i, j = rng.integers(5, n - 5, size=2)
        a, b = rng.integers(2, 10, size=2)
        occ[i : i + a, j : j + b] = True
    return spec, occ


def footprint_clearance(traj_xy: np.ndarray, spec: GridSpec, occ: np.ndarray) -> float:
    """Smallest distance [m] from the robot's centre to any obstacle cell's square."""
    c = spec.centers_of(np.argwhere(occ))
    h = spec.resolution / 2
    best = math.inf
    for chunk in np.array_split(traj_xy, max(1, len(traj_xy) // 2000)):
        dx = np.maximum(np.abs(chunk[:, None, 0] - c[None, :, 0]) - h, 0.0)
        dy = np.maximum(np.abs(chunk[:, None, 1] - c[None, :, 1]) - h, 0.0)
        best = min(best, float(np.sqrt(dx**2 + dy**2).min()))
    return best


def assert_commands_within_limits(commands, limits: BaseLimits):
    C = np.array(commands)
    t, v, w = C[:, 0], C[:, 1], C[:, 2]
    assert np.abs(v).max() <= limits.max_speed + 1e-12
    assert np.abs(w).max() <= limits.max_turn_rate + 1e-12
    # from standstill at the first command (dt = 0 there), then step by step
    assert abs(v[0]) <= 1e-12 and abs(w[0]) <= 1e-12
    dt = np.diff(t)
    assert (np.abs(np.diff(v)) <= limits.max_accel * dt + 1e-9).all()
    assert (np.abs(np.diff(w)) <= limits.max_turn_accel * dt + 1e-9).all()


def random_query(rng, spec, grid):
    free = np.argwhere(~grid.blocked)
    while True:
        s = spec.centers_of([free[rng.integers(len(free))]])[0] + rng.uniform(-0.04, 0.04, 2)
        g = spec.centers_of([free[rng.integers(len(free))]])[0]
        if np.hypot(*(s - g)) > 1.5 and not grid.blocked[spec.world_to_cell(*s)]:
            return s, g


@pytest.mark.parametrize("seed", range(24))
def test_drives_to_seeded_goals_among_obstacles(seed):
    rng = np.random.default_rng(seed)
    spec, occ = clutter_map(rng)
    grid = Costmap.from_occupancy(spec, occ).inflated(LIMITS.radius + spec.resolution)
    # the search robot's case (every third seed): stand 0.4-0.8 m from a target cell, facing it
    region = seed % 3 == 2
    while True:  # a reachable query (the boxes may split the map)
        s, g = random_query(rng, spec, grid)
        r = astar_to_region(grid, s, g, max_distance=0.8, min_distance=0.4) if region else astar(grid, s, g)
        if r.found:
            break
    goal_xy = r.points_xy[-1]
    heading = heading_towards(goal_xy, g) if region else float(rng.uniform(-math.pi, math.pi))
    waypoints = simplify_path(r, grid) if seed % 4 else r.points_xy  # raw staircases too
    robot = KinematicRobot(Pose2D(s[0], s[1], float(rng.uniform(-math.pi, math.pi))), LIMITS)
    robot.enable()
    res = drive_to(robot, waypoints, heading, dt=DT, timeout=90.0)

    assert res.outcome is DriveOutcome.ARRIVED, res
    x, y, th = robot.trajectory[-1]
    assert math.hypot(x - goal_xy[0], y - goal_xy[1]) <= 0.10
    assert abs(wrap_angle(th - heading)) <= math.radians(10.0)
    assert res.position_error_m <= 0.10 and abs(res.heading_error_rad) <= math.radians(10.0)
    # the footprint never touched an obstacle cell (so the centre never entered one either)
    assert footprint_clearance(np.array(robot.trajectory)[:, :2], spec, occ) >= LIMITS.radius
    assert_commands_within_limits(robot.commands, LIMITS)
    assert robot.watchdog_trips == 0 and len(robot.commands) == res.steps
    assert res.elapsed_s < 8.0 * r.length / LIMITS.max_speed + 10.0  # no dawdling: it makes progress


def test_turns_in_place_first_and_finishes_with_the_final_turn():
    f = PathFollower(LIMITS)
    f.set_path(np.array([[0.0, 0.0], [2.0, 0.0]]), final_heading=math.pi / 2)
    robot = KinematicRobot(Pose2D(0.0, 0.0, math.pi), LIMITS)  # facing away from the path
    robot.enable()
    statuses = []
    for _ in range(1000):
        cmd = f.command(robot.odometry(), robot.now())
        statuses.append(cmd.status)
        if cmd.status is FollowStatus.ARRIVED:
            break
        if cmd.status is FollowStatus.TURNING:
            assert abs(cmd.v) <= LIMITS.max_accel * DT + 1e-12  # stands (it started standing)
        robot.drive(cmd.v, cmd.omega)
        robot.step(DT)
    assert statuses[0] is FollowStatus.TURNING and statuses[-1] is FollowStatus.ARRIVED
    order = [s for k, s in enumerate(statuses) if k == 0 or s is not statuses[k - 1]]
    assert order == [
        FollowStatus.TURNING,
        FollowStatus.FOLLOWING,
        FollowStatus.FINAL_TURN,
        FollowStatus.ARRIVED,
    ]
    x, y, th = robot.trajectory[-1]
    assert math.hypot(x - 2.0, y) <= 0.1 and abs(wrap_angle(th - math.pi / 2)) <= math.radians(10)
    # once arrived it holds still
    cmd = f.command(robot.odometry(), robot.now() + DT)
    assert cmd == (0.0, 0.0, FollowStatus.ARRIVED)


def test_slows_down_before_the_goal():
    f = PathFollower(LIMITS)
    f.set_path(np.array([[0.0, 0.0], [3.0, 0.0]]))
    robot = KinematicRobot(Pose2D(0.0, 0.0, 0.0), LIMITS)
    robot.enable()
    log = []
    while True:
        p = robot.odometry()
        cmd = f.command(p, robot.now())
        if cmd.status is FollowStatus.ARRIVED:
            break
        log.append((p.x, cmd.v))
        robot.drive(cmd.v, cmd.omega)
        robot.step(DT)
    log = np.array(log)
    assert log[:, 1].max() == pytest.approx(LIMITS.max_speed)
    near = log[log[:, 0] > 2.9]
    assert near[:, 1].max() < 0.2  # within 10 cm of the goal it creeps
    assert abs(robot.trajectory[-1][0] - 3.0) <= 0.1


def test_bad_input_and_no_path():
    f = PathFollower(LIMITS)
    assert f.command(Pose2D(0.0, 0.0, 0.0), 0.0) == (0.0, 0.0, FollowStatus.NO_PATH)
    f.set_path([[0.0, 0.0], [1.0, 0.0]])
    with pytest.raises(ValueError, match="pose"):
        f.command(Pose2D(math.nan, 0.0, 0.0), 0.1)
    with pytest.raises(ValueError, match="t "):
        f.command(Pose2D(0.0, 0.0, 0.0), math.inf)
    f.command(Pose2D(0.0, 0.0, 0.0), 1.0)
    with pytest.raises(ValueError, match="backwards"):
        f.command(Pose2D(0.0, 0.0, 0.0), 0.5)
    with pytest.raises(ValueError, match="waypoints"):
        f.set_path([[0.0, math.nan]])
    with pytest.raises(ValueError, match="final_heading"):
        f.set_path([[0.0, 0.0]], final_heading=math.nan)


def test_drive_to_timeout_abort_and_watchdog_period():
    slow = BaseLimits(max_speed=0.01)
    robot = KinematicRobot(Pose2D(0.0, 0.0, 0.0), slow)
    robot.enable()
    res = drive_to(robot, np.array([[0.0, 0.0], [5.0, 0.0]]), dt=DT, timeout=2.0)
    assert res.outcome is DriveOutcome.TIMEOUT
    assert res.elapsed_s == pytest.approx(2.0, abs=DT + 1e-9)
    assert robot._v == 0.0 and robot._cmd == (0.0, 0.0)  # stopped at the end
    assert len(robot.commands) == res.steps and robot.watchdog_trips == 0

    robot = KinematicRobot(Pose2D(0.0, 0.0, 0.0), LIMITS)
    robot.enable()
    res = drive_to(
        robot, [[0.0, 0.0], [5.0, 0.0]], on_step=lambda pose, t: StepUpdate(abort=True) if t >= 1.0 else None
    )
    assert res.outcome is DriveOutcome.ABORTED and 0.9 <= res.elapsed_s <= 1.1
    assert res.distance_m == pytest.approx(robot.trajectory[-1][0], abs=0.05)

    with pytest.raises(ValueError, match="watchdog"):
        drive_to(robot, [[0.0, 0.0], [1.0, 0.0]], dt=0.5)
    assert drive_to(robot, np.zeros((0, 2))).outcome is DriveOutcome.NO_PATH


def test_drive_to_stops_the_robot_when_the_robot_raises():
    class Tripping(KinematicRobot):
        def step(self, dt):
            super().step(dt)
            if self.now() > 0.5:
                raise RuntimeError("bump")

    robot = Tripping(Pose2D(0.0, 0.0, 0.0), LIMITS)
    robot.enable()
    with pytest.raises(RuntimeError, match="bump"):
        drive_to(robot, [[0.0, 0.0], [3.0, 0.0]])
    assert robot._v == 0.0 and robot._cmd == (0.0, 0.0)


def test_pushed_off_after_the_end_of_its_path_it_steers_back_without_failing():
    """The caller may keep commanding after the follower reached the end of its path (the
    identification agent judges arrival with its own tolerances, and on hardware the watchdog can
    stop the base short): pushed off the goal, the follower steers back to it."""
    f = PathFollower(LIMITS)
    f.set_path(np.array([[0.0, 0.0], [1.0, 0.0]]))
    robot = KinematicRobot(Pose2D(0.0, 0.0, 0.0), LIMITS)
    robot.enable()
    for _ in range(1000):
        cmd = f.command(robot.odometry(), robot.now())
        if cmd.status is FollowStatus.ARRIVED:
            break
        robot.drive(cmd.v, cmd.omega)
        robot.step(DT)
    assert cmd.status is FollowStatus.ARRIVED
    pushed = KinematicRobot(Pose2D(1.3, 0.25, 0.0), LIMITS)  # beyond the end of the path, to the side
    pushed.enable()
    for _ in range(1000):
        cmd = f.command(pushed.odometry(), robot.now() + pushed.now())
        if cmd.status is FollowStatus.ARRIVED:
            break
        pushed.drive(cmd.v, cmd.omega)
        pushed.step(DT)
    p = pushed.odometry()
    assert cmd.status is FollowStatus.ARRIVED and math.hypot(p.x - 1.0, p.y) <= 0.1
