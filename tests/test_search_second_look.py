"""The local search's second look (issue 22): before a cell is declared empty, the colour peaks near it
are looked at again on a region enlarged twice. Against the simulator's truth: the enlarged pair
triangulates to the depth buffer as the original does, and a book lying on the floor that the 9 views
miss (a tuning seed's stand from ``benchmarks/bench_local_search.py``) is found with its true pose. The
search agent's side look (:func:`lab.search.local_search.look_at_points`): a book standing on the shelf
with its spine to the room, which the whole local search misses from in front, is found with its true
pose by the second look alone, from 35 degrees round its colour peak."""

import math
from dataclasses import replace

import numpy as np
import pytest

from lab.errors import ConfigError
from lab.geometry import Pose2D, se3_inv, transform_points
from lab.runs.search import map_spec, pose_errors
from lab.scene import load_scene
from lab.search.local_search import LocalSearchConfig, local_search, look_at_points
from lab.sim import RenderSettings, SimRobot, SimWorld
from lab.training.search import search_database
from lab.vision.roi import object_roi
from lab.vision.stereo import stereo_features, upsampled_pair

SCENE = load_scene("lab_room")

#: The book on the floor and where the agent's approach stood the robot: tuning seed 1 of
#: ``benchmarks/bench_local_search.py`` (x, y, z_underside, yaw_deg) and (x, y, theta_deg), rounded. From
#: 1.2 m and 40 degrees above, the 9 views matched 0-2 right features (there: no start of 5 inliers;
#: here, from the rounded stand, a start that its refinement did not confirm).
BOOK_ON_FLOOR = ((-1.753, 2.159, 0.0, 6.791), (-1.268, 2.655, -123.5))


def _book_on_floor(config: LocalSearchConfig):
    place, (x, y, th) = BOOK_ON_FLOOR
    spec = map_spec(SCENE)
    target = spec.cell_to_world(*spec.world_to_cell(place[0], place[1]))  # the searched cell's centre
    db = search_database("book")
    with SimWorld(SCENE.with_pose("book", place), RenderSettings(supersample=2)) as w:
        robot = SimRobot(w, start=Pose2D(x, y, math.radians(th)), seed=1, sensing="realistic")
        robot.enable()
        res = local_search(robot, db, target, np.random.default_rng([1, 1]), config)
        return res, w.truth.G_W("book")


@pytest.fixture(scope="module")
def book_on_floor():
    return {
        "paper": _book_on_floor(replace(LocalSearchConfig(), second_look=None)),
        "second_look": _book_on_floor(LocalSearchConfig()),
    }


def test_the_nine_views_miss_the_book_on_the_floor(book_on_floor):
    res, _ = book_on_floor["paper"]
    assert not res.found
    assert len(res.views) == 9 and all(v.upsample == 1 for v in res.views), res.reason


def test_the_second_look_finds_it_with_its_true_pose(book_on_floor):
    res, G_true = book_on_floor["second_look"]
    assert res.found, res.reason
    assert res.views[-1].upsample == 2  # found by a second look, after the 9 views
    assert all(v.upsample == 1 for v in res.views[:9])
    pe, oe = pose_errors(res.G_WO, G_true)
    assert pe < 0.05 and oe < 10.0, (pe, oe)


def test_an_enlarged_pair_triangulates_to_the_depth_buffer():
    """A book on a table 0.85 m ahead (ideal sensing): the features of the region around it, from the pair
    enlarged twice with :func:`upsampled_pair`, lie on the rendered depth as closely as the original
    pair's, and their pixels map back to the original's by ``u = (u' + 1/2) / 2 - 1/2``."""
    place = (1.9, 2.45, 0.75, 90.0)  # on table_a, a cover towards the robot
    db = search_database("book")
    with SimWorld(SCENE.with_pose("book", place), RenderSettings(supersample=2)) as w:
        robot = SimRobot(w, start=Pose2D(1.9, 1.6, math.pi / 2), seed=0)
        robot.enable()
        robot.command_pan_tilt(0.0, math.radians(-15.0))
        robot.wait_pan_tilt()
        frame = robot.capture_stereo()
        depth = w.truth.depth(w.truth.G_WC(), frame.camera)
        G_CO = se3_inv(w.truth.G_WC()) @ w.truth.G_W("book")
    roi = object_roi(G_CO, db.extent, frame.camera, 10)
    assert roi is not None

    def depth_error(f, k):
        uv = np.rint((f.uv + 0.5) / k - 0.5).astype(int)  # the original image's pixel
        return np.abs(f.points_C[:, 2] - depth[uv[:, 1], uv[:, 0]])

    f1 = stereo_features(frame.left, frame.right, frame.camera, roi=roi)
    left, right, cam2, par2 = upsampled_pair(frame.left, frame.right, frame.camera, 2)
    assert left.shape == (2 * frame.camera.height, 2 * frame.camera.width, 3)
    p = transform_points(G_CO, np.zeros((1, 3)))  # the book's centre projects to corresponding pixels
    np.testing.assert_allclose(cam2.project(p), 2 * (frame.camera.project(p) + 0.5) - 0.5, atol=1e-9)
    f2 = stereo_features(left, right, cam2, par2, roi=tuple(2 * v for v in roi))
    assert len(f1) >= 10 and len(f2) >= len(f1)
    e1, e2 = depth_error(f1, 1), depth_error(f2, 2)
    assert np.median(e2) < 0.01 and np.median(e2) < 2 * np.median(e1) + 0.002, (np.median(e1), np.median(e2))
    # the covariances stay the original image's: the depth's standard deviation at the same depth
    z1, z2 = f1.points_C[:, 2], f2.points_C[:, 2]
    s1 = np.sqrt(f1.covariances[:, 2, 2]) / z1**2
    s2 = np.sqrt(f2.covariances[:, 2, 2]) / z2**2
    assert np.median(s2) == pytest.approx(np.median(s1), rel=0.05)


#: The book upright on the shelf (x, y, z_underside, yaw_deg) with its 5 cm spine towards the room (+x).
BOOK_SPINE_ON = (-2.7, 2.6, 1.2, 90.0)


def _stand_and_search(turn_deg: float, search):
    """The robot 0.75 m from the spine-on book, ``turn_deg`` round from the shelf's normal, facing it;
    ``search(robot)`` runs there. Returns its result and the book's true pose."""
    x, y, _, _ = BOOK_SPINE_ON
    a = math.radians(turn_deg)
    with SimWorld(SCENE.with_pose("book", BOOK_SPINE_ON), RenderSettings(supersample=2)) as w:
        start = Pose2D(x + 0.75 * math.cos(a), y + 0.75 * math.sin(a), math.pi + a)
        # realistic's sensors in an exact room: the miss from in front and the find from the side are
        # this scene's (with the room's mount errors the refinement from the side is not confirmed)
        robot = SimRobot(w, start=start, seed=1, sensing="sensors")
        robot.enable()
        return search(robot), w.truth.G_W("book")


def test_a_spine_on_book_missed_from_in_front_is_found_from_the_side():
    db = search_database("book")
    spec = map_spec(SCENE)
    target = spec.cell_to_world(*spec.world_to_cell(*BOOK_SPINE_ON[:2]))
    front, G_true = _stand_and_search(
        0.0, lambda robot: local_search(robot, db, target, np.random.default_rng([1, 1]))
    )
    # in front: all views and the second look miss, but the colour of the spine was seen at the book
    assert not front.found and len(front.views) >= 10, front.reason
    assert front.colour_peaks, front.reason
    peak = front.colour_peaks[0]
    assert np.linalg.norm(peak[:2] - G_true[:2, 3]) < 0.15, (peak, G_true[:3, 3])
    # 35 degrees round it: a cover turns towards the camera, and the second look at the peak finds it
    side, G_true = _stand_and_search(
        35.0, lambda robot: look_at_points(robot, db, front.colour_peaks, np.random.default_rng([1, 2]))
    )
    assert side.found, side.reason
    assert all(v.upsample == 2 for v in side.views)  # the second look alone: no 9 views
    pe, oe = pose_errors(side.G_WO, G_true)
    assert pe < 0.05 and oe < 10.0, (pe, oe)


def test_look_at_points_needs_a_point():
    with pytest.raises(ConfigError, match="at least one point"):
        look_at_points(None, None, [], np.random.default_rng(0))
