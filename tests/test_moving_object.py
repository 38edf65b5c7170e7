"""The searched-for object that moves (lab/sim/moving_object.py), in the lab room without rendering:
it moves at its speed, stays in the true free space and away from the robot, pauses, and the evasive
one leaves the camera's view when seen."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lab.errors import ConfigError
from lab.geometry import Pose2D
from lab.runs.placement import check_placement, random_placement
from lab.scene import load_scene
from lab.sim import SimRobot, SimWorld
from lab.sim.moving_object import MovingKind, MovingObjectConfig, make_moving_object

OBJECT = "book"  # a searchable object of the lab room


def room_with_object(seed: int):
    scene = load_scene("lab_room")
    name = OBJECT if OBJECT in scene.names("object") else scene.names("object")[0]
    place = random_placement(scene, name, np.random.default_rng(seed), surface="floor")
    return scene.with_pose(name, place), name


@pytest.mark.parametrize("seed", [1, 2])
def test_random_object_moves_at_its_speed_in_free_space_and_keeps_off_the_robot(seed):
    scene, name = room_with_object(seed)
    with SimWorld(scene) as w:
        robot = SimRobot(w)
        cfg = MovingObjectConfig(MovingKind.RANDOM, speed_mps=0.1, pause_s=2.0)
        m = make_moving_object(w, name, cfg, np.random.default_rng(seed))
        start = m.xy.copy()
        free = m.free.copy()
        xs = [m.xy.copy()]
        for _ in range(1200):  # 120 s
            robot.step(0.1)
            xs.append(m.xy.copy())
            G = w.truth.G_W(name)
            np.testing.assert_allclose(G[:2, 3], m.xy)  # the body is where the mover says
        xs = np.array(xs)
        steps = np.hypot(*np.diff(xs, axis=0).T)
        assert steps.max() <= 0.1 * 0.1 + 1e-9  # never faster than its speed
        assert (steps == 0).sum() > 15  # it pauses
        assert m.legs >= 3
        ij = np.floor((xs - m.spec.origin_xy) / m.GRID_M).astype(int)
        assert free[ij[:, 0], ij[:, 1]].all()  # in the true free space (grown by its clearance)
        rp = w.truth.robot_pose()
        assert np.hypot(xs[:, 0] - rp.x, xs[:, 1] - rp.y).min() > cfg.keep_away_m - 0.05
        # the track gives the truth at any earlier time
        assert np.allclose(m.G_WO_at(0.0)[:2, 3], start)
        assert np.allclose(m.G_WO_at(w.t)[:2, 3], m.xy)


def test_evasive_object_leaves_the_cameras_view():
    scene, name = room_with_object(1)
    sx, sy, _ = scene.robot_start
    ox, oy = scene.body(name).centre[:2]
    a = math.atan2(oy - sy, ox - sx)
    x, y = ox - 2.5 * math.cos(a), oy - 2.5 * math.sin(a)  # 2.5 m short of it, on the line from the start
    with SimWorld(scene) as w:
        robot = SimRobot(w, start=Pose2D(x, y, a))  # facing the object
        cfg = MovingObjectConfig(MovingKind.EVASIVE, speed_mps=0.2, pause_s=1000.0)
        m = make_moving_object(w, name, cfg, np.random.default_rng(0))
        assert m.seen()
        off0 = abs(math.atan2(m.xy[1] - y, m.xy[0] - x) - a)  # its angle off the robot's heading
        for _ in range(300):  # 30 s
            robot.step(0.1)
        assert m.evasions >= 1
        assert not m.seen()  # out of the camera's view cone
        assert abs(math.atan2(m.xy[1] - y, m.xy[0] - x) - a) > off0 + math.radians(
            20
        )  # away from the line of sight


def test_an_unseen_random_object_keeps_its_pause():
    scene, name = room_with_object(1)
    with SimWorld(scene) as w:
        robot = SimRobot(w)
        m = make_moving_object(w, name, MovingObjectConfig(pause_s=1000.0), np.random.default_rng(0))
        start = m.xy.copy()
        for _ in range(100):
            robot.step(0.1)
        np.testing.assert_array_equal(m.xy, start)


def test_bad_options_are_one_clear_error():
    with pytest.raises(ConfigError, match="speed"):
        MovingObjectConfig(speed_mps=0.0)
    with pytest.raises(ConfigError, match="pause"):
        MovingObjectConfig(pause_s=-1.0)


def test_it_never_drives_towards_a_robot_that_came_within_its_keep_away_distance():
    """A leg chosen before the robot arrived would run into it: the object stops where a step would
    bring it nearer than ``keep_away_m`` to the robot's base (it drove right up to a searching robot
    that stood still, which then drove into what its camera could not see so close), and a leg that
    leads away from the robot is still driven."""
    scene, name = room_with_object(1)
    ox, oy = scene.body(name).centre[:2]
    with SimWorld(scene) as w:
        cfg = MovingObjectConfig(MovingKind.RANDOM, speed_mps=0.2, pause_s=1000.0)
        m = make_moving_object(w, name, cfg, np.random.default_rng(0))
        robot_at = (ox + 1.5, oy)  # the robot, 1.5 m away on +x: the leg below runs through it
        SimRobot(w, start=Pose2D(*robot_at, math.pi))
        m.goal = np.array([ox + 3.0, oy])
        for _ in range(100):  # 10 s: 2 m at 0.2 m/s, if nothing stopped it
            w.robot.step(0.1)
        d = math.hypot(m.xy[0] - robot_at[0], m.xy[1] - robot_at[1])
        assert m.goal is None  # the leg ended
        assert cfg.keep_away_m - 0.2 * 0.1 < d  # it stopped at the distance, within a step
        assert d < cfg.keep_away_m + 0.2 * 0.1 + 1e-9
        m.goal = np.array([ox - 0.5, oy])  # away from the robot: allowed
        x0 = m.xy.copy()
        for _ in range(10):
            w.robot.step(0.1)
        assert m.xy[0] < x0[0] - 0.15


TOPS = [
    ("book", "table_a", (2.2, 2.6, 0.75, 20.0), "cereal_box"),  # the cereal box stands on table_a
    ("toy_block", "table_b", (-2.3, -1.3, 0.75, 10.0), "glossy_cup"),  # the glossy cup on table_b
]


@pytest.mark.parametrize("name,table,place,other", TOPS)
def test_on_a_tables_top_it_stays_on_the_top_over_a_long_random_walk(name, table, place, other):
    """The truth of a long walk on a table's top, checked by the placement checker (the peer that
    places objects and refuses one in mid-air or in another body): at every step the object stands
    wholly on that table's top, overlapping nothing, at the top's height; it drives the length of
    the top, at its speed."""
    scene = load_scene("lab_room")
    scene = scene.with_pose(name, place)
    assert check_placement(scene, name, place).name == table  # a valid start
    with SimWorld(scene) as w:
        robot = SimRobot(w)
        cfg = MovingObjectConfig(MovingKind.RANDOM, speed_mps=0.2, pause_s=0.5)
        m = make_moving_object(w, name, cfg, np.random.default_rng(7))
        assert m.surface == table
        z0 = w.truth.G_W(name)[2, 3]
        xs = []
        for _ in range(6000):  # 600 s
            robot.step(0.1)
            xs.append(m.xy.copy())
        assert w.truth.G_W(name)[2, 3] == z0
    xs = np.array(xs)
    steps = np.hypot(*np.diff(xs, axis=0).T)
    assert steps.max() <= 0.2 * 0.1 + 1e-9
    assert m.legs >= 100 and m.path_length_m() > 30.0
    for x, y in xs[::5]:
        got = check_placement(scene, name, (x, y, place[2], place[3]), clearance_m=0.0)
        assert got.name == table
    body = scene.body(table)
    long_axis = int(np.argmax(body.size[:2]))
    assert np.ptp(xs[:, long_axis]) > 0.5 * body.size[long_axis]  # it drove the length of the top
    near = np.hypot(*(xs - scene.body(other).centre[:2]).T).min()
    assert near < 0.25  # and close by the other object on the top (and not into it: above)


def test_a_shelf_is_no_place_for_a_carrier():
    scene = load_scene("lab_room")  # the book stands on the shelf
    with SimWorld(scene) as w, pytest.raises(ConfigError, match="on the floor or on a table's top"):
        make_moving_object(w, "book", MovingObjectConfig(), np.random.default_rng(0))
