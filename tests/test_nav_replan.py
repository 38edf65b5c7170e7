"""Path simplification, blockage checks and replanning, up to a drive where an obstacle appears."""

import math

import numpy as np
import pytest
from nav_fakes import KinematicRobot
from nav_scenes import Box, Floor, random_grid, stereo_view

from lab.geometry import Pose2D
from lab.navigation.astar import PathStatus, astar, astar_cells
from lab.navigation.costmap import Costmap
from lab.navigation.follower import DriveOutcome, StepUpdate, drive_to
from lab.navigation.grid import GridSpec
from lab.navigation.ground import fit_ground_plane
from lab.navigation.paths import Replanner, first_blocked_index, segment_is_clear, simplify_path
from lab.robot import BaseLimits, StereoCamera

LIMITS = BaseLimits()


def test_simplified_paths_stay_clear_and_are_no_longer():
    rng = np.random.default_rng(4)
    n = 0
    for _ in range(80):
        grid = random_grid(rng, res=0.1)
        free = np.argwhere(np.isfinite(grid.cost))
        if len(free) < 2:
            continue
        r = astar_cells(grid, free[rng.integers(len(free))], free[rng.integers(len(free))])
        if not r.found:
            continue
        W = simplify_path(r, grid)
        np.testing.assert_array_equal(W[0], r.points_xy[0])
        np.testing.assert_array_equal(W[-1], r.points_xy[-1])
        assert len(W) <= len(r.points_xy)
        for a, b in zip(W[:-1], W[1:], strict=True):
            assert segment_is_clear(grid, a, b)
        length = np.linalg.norm(np.diff(W, axis=0), axis=1).sum()
        assert length <= r.length + 1e-9
        n += 1
    assert n >= 40


def open_room(res=0.1, shape=(60, 40)):
    spec = GridSpec((0.0, 0.0), res, shape)
    occ = np.zeros(shape, dtype=bool)
    occ[[0, -1], :] = True
    occ[:, [0, -1]] = True
    return spec, occ


def test_obstacle_on_the_path_triggers_a_replan_that_avoids_it():
    spec, occ = open_room()
    radius = LIMITS.radius + spec.resolution
    goal = (5.5, 2.0)
    rp = Replanner(lambda g, s: astar(g, s, goal))
    first = rp.update(Costmap.from_occupancy(spec, occ).inflated(radius), (0.5, 2.0))
    assert first.replanned and first.reason == "initial" and first.path.found
    assert len(first.waypoints) == 2  # open room: one straight segment

    same = rp.update(Costmap.from_occupancy(spec, occ).inflated(radius), Pose2D(1.0, 2.0, 0.0))
    assert not same.replanned and same.reason == "clear" and same.path is first.path

    occ2 = occ.copy()
    occ2[30:34, 17:24] = True  # a box across the straight line, x 3.0-3.4, y 1.7-2.4
    grid2 = Costmap.from_occupancy(spec, occ2).inflated(radius)
    assert first_blocked_index(first.waypoints, grid2) == 0
    new = rp.update(grid2, Pose2D(1.0, 2.0, 0.0))
    assert new.replanned and new.reason == "blocked" and new.blocked_index == 0
    assert new.path.found and new.path.cost > first.path.cost
    assert first_blocked_index(new.waypoints, grid2) is None
    cells = new.path.cells
    assert np.isfinite(grid2.cost[cells[:, 0], cells[:, 1]]).all()

    # an obstacle behind the robot does not trigger anything
    occ3 = occ2.copy()
    occ3[5:8, 18:22] = True
    assert not rp.update(Costmap.from_occupancy(spec, occ3).inflated(radius), Pose2D(2.0, 1.2, 0.0)).replanned


def test_unreachable_goal_is_reported_and_retried():
    spec, occ = open_room()
    occ[40, :] = True  # a wall across the room
    radius = LIMITS.radius + spec.resolution
    rp = Replanner(lambda g, s: astar(g, s, (5.5, 2.0)))
    d = rp.update(Costmap.from_occupancy(spec, occ).inflated(radius), (0.5, 2.0))
    assert d.replanned and not d.path.found and d.path.reason == "UNREACHABLE" and len(d.waypoints) == 0
    occ[40, 15:25] = False  # a door opens
    d = rp.update(Costmap.from_occupancy(spec, occ).inflated(radius), (0.5, 2.0))
    assert d.replanned and d.reason == "retry" and d.path.found
    with pytest.raises(ValueError, match="pose"):
        rp.update(Costmap.from_occupancy(spec, occ).inflated(radius), (math.nan, 2.0))


def test_escape_from_a_grown_obstacle():
    spec, occ = open_room()
    occ[20:24, 18:22] = True
    grid = Costmap.from_occupancy(spec, occ).inflated(LIMITS.radius + spec.resolution)
    start = (1.85, 2.05)  # 0.15 m from the box: inside its grown zone, not in it
    assert astar(grid, start, (5.0, 2.0)).status is PathStatus.START_IN_OBSTACLE
    rp = Replanner(lambda g, s: astar(g, s, (5.0, 2.0)))
    d = rp.update(grid, start)
    assert d.replanned and d.reason == "escape" and d.path.found
    np.testing.assert_allclose(d.waypoints[0], start)
    assert not grid.blocked[d.path.cells[0, 0], d.path.cells[0, 1]]
    assert not rp.update(grid, start).replanned  # and it keeps that path while escaping


def test_drive_with_an_obstacle_appearing_on_the_path():
    """Closed loop: stereo frames -> ground plane -> costmap -> replanner -> follower -> robot.

    A box appears on the straight path after 2 s (about 1.5 m ahead of the robot); the robot sees it
    with the (ray-cast) stereo camera, replans around it and arrives, its footprint never touching it.
    """
    spec, occ = open_room()
    floor = Floor(0.01, math.radians(0.5), 0.0)
    walls = [
        Box(-0.5, 0.1, -0.5, 4.5, 1.0),
        Box(5.9, 6.5, -0.5, 4.5, 1.0),
        Box(-0.5, 6.5, -0.5, 0.1, 1.0),
        Box(-0.5, 6.5, 3.9, 4.5, 1.0),
    ]
    box = Box(3.03, 3.41, 1.62, 2.37, 0.5)
    cm = Costmap.from_occupancy(spec, occ, known=np.zeros_like(occ))  # only the walls are known
    radius = LIMITS.radius + spec.resolution
    goal = (5.3, 2.0)
    rp = Replanner(lambda g, s: astar(g, s, goal))
    rng = np.random.default_rng(0)
    camera = StereoCamera.from_fov(320, 240, 60.0, 0.12)  # the paper's 320 x 240 while navigating
    d0 = rp.update(cm.inflated(radius), (0.6, 2.0))
    log = []

    def on_step(pose, t):
        if round(t / 0.05) % 16:  # a stereo frame every 0.8 s
            return None
        scene = walls + ([box] if t >= 2.0 else [])
        P, _ = stereo_view(pose, floor, scene, rng, tilt=math.radians(-30.0), camera=camera)
        cm.integrate(P, fit_ground_plane(P, rng), sensor_origin_xy=pose)
        d = rp.update(cm.inflated(radius), pose)
        log.append((t, d.reason))
        return StepUpdate(waypoints=d.waypoints) if d.replanned else None

    robot = KinematicRobot(Pose2D(0.6, 2.0, 0.0), LIMITS)
    robot.enable()
    res = drive_to(robot, d0.waypoints, 0.0, timeout=60.0, on_step=on_step)
    assert res.outcome is DriveOutcome.ARRIVED and res.position_error_m <= 0.1
    reasons = [r for _, r in log]
    assert "blocked" in reasons, log
    assert all(t >= 2.0 for t, r in log if r == "blocked")
    T = np.array(robot.trajectory)
    dx = np.maximum(np.maximum(box.x0 - T[:, 0], T[:, 0] - box.x1), 0.0)
    dy = np.maximum(np.maximum(box.y0 - T[:, 1], T[:, 1] - box.y1), 0.0)
    assert np.hypot(dx, dy).min() >= LIMITS.radius
    # the box is in the costmap where it stands
    assert cm.obstacle[spec.world_to_cell(3.2, 2.0)]
