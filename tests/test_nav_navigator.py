"""The navigator's geometric checks on a known map (no camera needed): the footprint against obstacle
cells, the path ahead while a replan is pending, and the default grid."""

import math

import numpy as np
import pytest
from nav_fakes import KinematicRobot

from lab.errors import ConfigError
from lab.geometry import Pose2D
from lab.navigation import Costmap, GridSpec, Navigator, NavigatorConfig, room_bounds
from lab.scene import load_scene


@pytest.fixture
def nav():
    spec = GridSpec((0.0, 0.0), 0.1, (40, 40))
    occ = np.zeros(spec.shape, dtype=bool)
    occ[20, 20] = True  # the square [2.0, 2.1) x [2.0, 2.1)
    n = Navigator(KinematicRobot(Pose2D(0.5, 2.05, 0.0)), spec)
    n.costmap = Costmap.from_occupancy(spec, occ)
    return n


def test_footprint_clearance_is_measured_to_the_obstacle_cells_edges(nav):
    need = nav.robot.base_limits.radius + nav.config.goal_clearance  # 0.25 m
    assert nav.footprint_clear((1.0, 2.05), (2.0 - need - 0.005, 2.05))
    assert not nav.footprint_clear((1.0, 2.05), (2.0 - need + 0.005, 2.05))
    # diagonally: the distance to the square's corner
    d = (need + 0.005) / math.sqrt(2.0)
    assert nav.footprint_clear((1.0, 1.0), (2.0 - d, 2.0 - d))
    assert not nav.footprint_clear((1.0, 1.0), (5.0, 1.0))  # off the map


def test_the_path_ahead_is_checked_only_as_far_as_asked(nav):
    W = np.array([[0.5, 2.05], [3.5, 2.05]])
    assert nav.path_ahead_clear(W, Pose2D(0.6, 2.05, 0.0), 1.0)  # up to x = 1.6: 0.4 m off the box
    assert not nav.path_ahead_clear(W, Pose2D(0.6, 2.05, 0.0), 1.2)  # up to x = 1.8
    W2 = np.array([[0.5, 2.05], [1.2, 2.05], [1.2, 3.5]])  # turns away before the box
    assert nav.path_ahead_clear(W2, Pose2D(0.6, 2.05, 0.0), 3.0)


def test_the_grid_covers_the_scenes_floor_with_a_margin():
    assert room_bounds(load_scene("lab_room")) == (-3.0, -4.0, 3.0, 4.0)
    nav = Navigator(KinematicRobot(Pose2D(0.0, 0.0, 0.0)), bounds=room_bounds(load_scene("lab_room")))
    assert nav.spec.extent == pytest.approx((-3.5, 3.5, -4.5, 4.5))
    assert nav.spec.resolution == 0.1 and nav.radius == pytest.approx(0.3)
    small = Navigator(KinematicRobot(Pose2D(0.0, 0.0, 0.0)), bounds=(0, 0, 2, 1))
    assert small.spec.extent == pytest.approx((-0.5, 2.5, -0.5, 1.5))
    with pytest.raises(ConfigError, match="spec or bounds"):
        Navigator(KinematicRobot(Pose2D(0.0, 0.0, 0.0)), small.spec, bounds=(0, 0, 1, 1))
    with pytest.raises(ConfigError, match="workspace"):
        Navigator(KinematicRobot(Pose2D(0.0, 0.0, 0.0)))  # no world size is assumed
    with pytest.raises(ConfigError, match="max_range"):
        NavigatorConfig(max_range=math.nan)


def test_ground_plane_jumps_are_refused_until_they_persist(nav):
    rng = np.random.default_rng(0)
    G_WC = np.eye(4)
    G_WC[:3, 3] = (1.0, 1.0, 0.7)

    def floor(z):
        xy = rng.uniform(0.0, 3.0, (2000, 2))
        return np.column_stack([xy, z + rng.normal(0.0, 0.005, 2000)])

    plane, refit = nav._ground_plane(floor(0.0), G_WC)
    assert refit and abs(plane.z_at(1.0, 1.0)) < 0.01
    for _ in range(2):  # a level plane 0.12 m higher (a low platform filling the view): refused twice
        p, refit = nav._ground_plane(floor(0.12), G_WC)
        assert not refit and p is plane
    p, refit = nav._ground_plane(floor(0.12), G_WC)  # the third time in a row it is the floor
    assert refit and abs(p.z_at(1.0, 1.0) - 0.12) < 0.01


def test_marks_under_the_robot_are_cleared_so_it_can_escape(nav):
    """A landmark update moved the pose estimate onto obstacle marks made before it (a search robot at
    a vantage point): its own cell is lethal, every plan from it is START_IN_OBSTACLE and the escape's
    straight line starts in a lethal cell. Clearing the footprint (where the robot stands there is no
    obstacle) lets the escape drive out of the grown band; marks outside the footprint stay."""
    from lab.navigation.astar import PathStatus, astar
    from lab.navigation.paths import Replanner

    spec = nav.spec
    occ = np.zeros(spec.shape, dtype=bool)
    occ[3:8, 20:23] = True  # a band x [0.3, 0.8), y [2.0, 2.3): the robot at (0.5, 2.05) stands in it
    nav.costmap = Costmap.from_occupancy(spec, occ)
    nav._grid = None
    goal = (3.0, 1.0)
    rp = Replanner(lambda g, s: astar(g, s, goal))
    assert astar(nav.planning_grid(), (0.5, 2.05), goal).status is PathStatus.START_IN_OBSTACLE
    assert not rp.update(nav.planning_grid(), (0.5, 2.05)).path.found  # no escape either

    before = nav.costmap.obstacle
    n = nav.clear_under_robot()
    after = nav.costmap.obstacle
    X, Y = spec.cell_centers()
    under = np.hypot(X - 0.5, Y - 2.05) <= nav.robot.base_limits.radius
    assert n == int((before & under).sum()) > 0
    assert not (after & under).any() and np.array_equal(after, before & ~under)  # the rest is kept
    d = Replanner(lambda g, s: astar(g, s, goal)).update(nav.planning_grid(), (0.5, 2.05))
    assert d.path.found and d.reason == "escape"
    # nothing left under it: a second call changes nothing
    ev = nav.costmap.evidence
    assert nav.clear_under_robot() == 0 and np.array_equal(nav.costmap.evidence, ev)
    with pytest.raises(ConfigError, match="radius must be a finite number >= 0 m"):
        nav.costmap.clear_disc((0.5, 2.05), -0.1)
    with pytest.raises(ValueError, match="xy"):
        nav.costmap.clear_disc((math.nan, 2.05), 0.2)
