"""The local search (9 pan-tilt views, SIFT + EKF, 6D pose) with the robot placed at local-search range
in front of an object (test set-up from the truth), scored against the simulator's true pose."""

import math
from dataclasses import replace

import numpy as np
import pytest
from search_standin import stand_in_front

from lab.errors import ConfigError
from lab.geometry import Pose2D
from lab.robot import PanTiltLimits, StereoCamera
from lab.runs.search import pose_errors
from lab.scene import load_scene
from lab.search.local_search import LocalSearchConfig, aim_at, local_search, local_views, object_roi
from lab.search.pose_check import rest_tilt_deg
from lab.sim import RenderSettings, SimRobot, SimWorld
from lab.training.search import search_database

SCENE = load_scene("lab_room")
TEXTURED = ("cereal_box", "book", "toy_block")


def _shelf_front(name: str, yaw_deg: float) -> float:
    """x of an object on the shelf standing at its front edge (the shelf's top hides it from below)."""
    b, a = SCENE.body(name), math.radians(yaw_deg)
    hx = 0.5 * (abs(b.size[0] * math.cos(a)) + abs(b.size[1] * math.sin(a)))
    return -2.5 - hx - 0.01


def set_up(name: str, surface: str):
    """(placement, robot pose): the object's large +x face turned 15 degrees from the robot (floor and
    table) or square to it (shelf), the robot 0.7-0.75 m away facing it."""
    if surface == "floor":
        xy, normal, yaw, dist = (0.8, 0.6), -60.0, -45.0, 0.7
        z = 0.0
    elif surface == "table":  # table_a, approached from the room's side
        xy, normal, yaw, dist = (1.8, 2.6), -90.0, -75.0, 0.7
        z = 0.75
    else:
        yaw, normal, dist = 0.0, 0.0, 0.75
        xy, z = (_shelf_front(name, yaw), 2.5), 1.2
    pose = stand_in_front(SCENE, xy, normal, dist)
    return (xy[0], xy[1], z, yaw), Pose2D(pose.x, pose.y + (0.1 if surface == "shelf" else 0.0), pose.theta)


def run_local(name: str, surface: str, db_name: str | None = None, config: LocalSearchConfig | None = None):
    place, pose = set_up(name, surface)
    db = search_database(db_name or name)
    with SimWorld(SCENE.with_pose(name, place), RenderSettings(supersample=2)) as w:
        robot = SimRobot(w, start=pose, seed=0)
        robot.enable()
        res = local_search(robot, db, place[:2], np.random.default_rng(0), config)
        G_true = w.truth.G_W(name)
    return res, G_true


@pytest.fixture(scope="module")
def results():
    return {(n, s): run_local(n, s) for n in TEXTURED for s in ("floor", "table", "shelf")}


def test_textured_objects_found_with_their_6d_pose_at_three_heights(results):
    print("\nlocal search, robot at 0.7-0.75 m facing the object (position error, orientation error):")
    bad = []
    for (name, surface), (res, G_true) in results.items():
        if not res.found:
            print(f"  {name:10s} {surface:5s} NOT FOUND: {res.reason}")
            bad.append((name, surface, res.reason))
            continue
        pe, oe = pose_errors(res.G_WO, G_true)
        print(
            f"  {name:10s} {surface:5s} {pe * 100:5.2f} cm {oe:5.2f} deg  ({res.reason}; "
            f"{res.t_end - res.t_start:.1f} s, {len(res.views)} views)"
        )
        if pe > 0.05 or oe > 10.0:
            bad.append((name, surface, pe, oe))
    assert not bad, bad


def test_a_found_pose_rests_on_a_face_and_a_tilted_one_is_not_found(results):
    """Every found pose's tilt from resting on a face is at most its orientation error (the bound that
    makes the check safe) and within the default 10 degrees; with the check made impossibly strict,
    the same set-up's track is refused for its tilt and nothing is found."""
    for (name, surface), (res, G_true) in results.items():
        if res.found:
            _, oe = pose_errors(res.G_WO, G_true)
            tilt = rest_tilt_deg(res.G_WO[:3, :3])
            assert tilt <= oe + 1e-6 and tilt <= LocalSearchConfig().max_rest_tilt_deg, (
                name,
                surface,
                tilt,
                oe,
            )
    strict = replace(LocalSearchConfig(), max_rest_tilt_deg=1e-3)
    res, _ = run_local("toy_block", "table", config=strict)
    assert not res.found
    assert any("from resting on a face (at most 0.001)" in v.outcome for v in res.views), res.views
    with pytest.raises(ConfigError, match="max_rest_tilt_deg must be in"):
        LocalSearchConfig(max_rest_tilt_deg=0.0)


def test_glossy_cup_is_not_found():
    """The featureless cup (the paper's penguin cup) on a table in front of the robot: no view has
    matches, so no start, no pose; not on the second look at its colour either."""
    res, _ = run_local("glossy_cup", "table")
    assert not res.found
    first, second = res.views[:9], res.views[9:]
    assert all(v.upsample == 1 for v in first)  # it looked everywhere before giving up
    assert len(second) <= LocalSearchConfig().second_look.n_looks and all(v.upsample == 2 for v in second)
    assert all(v.n_inliers == 0 for v in res.views), res.views


def test_another_object_is_not_taken_for_the_searched_one():
    """Facing the cereal box while searching for the book: the book's database must not yield a pose."""
    place, pose = set_up("cereal_box", "table")
    db = search_database("book")
    with SimWorld(SCENE.with_pose("cereal_box", place), RenderSettings(supersample=2)) as w:
        robot = SimRobot(w, start=pose, seed=0)
        robot.enable()
        res = local_search(robot, db, place[:2], np.random.default_rng(0))
    assert not res.found, res.reason


def test_views_cover_the_hemisphere_and_respect_the_limits():
    cfg = LocalSearchConfig()
    lim = PanTiltLimits()
    v = local_views(cfg, bearing=math.radians(120.0), limits=lim)
    assert len(v) == 9
    pans = {round(math.degrees(p)) for p, _ in v}
    assert pans == {round(min(120 + d, math.degrees(lim.pan_max))) for d in (-60, 0, 60)}
    assert {round(math.degrees(t)) for _, t in v} == {-35, 0, 31}


def test_aim_and_roi_geometry():
    cam = StereoCamera.from_fov(mount_R=(0.0, 0.0, 0.7))
    pan, tilt = aim_at(np.array([1.0, 1.0, 0.7]), cam)
    assert pan == pytest.approx(math.pi / 4) and tilt == pytest.approx(0.0)
    G_CO = np.eye(4)
    G_CO[:3, 3] = (0.0, 0.0, 1.0)  # a 20 cm cube 1 m straight ahead
    x, y, w, h = object_roi(G_CO, (0.2, 0.2, 0.2), cam, margin_px=10)
    assert abs((x + w / 2) - cam.cx) <= 1 and abs((y + h / 2) - cam.cy) <= 1
    assert w == pytest.approx(2 * 10 + 0.2 * cam.fx / 0.9, abs=3)  # the near face sets the extent
    G_CO[:3, 3] = (0.0, 0.0, -1.0)
    assert object_roi(G_CO, (0.2, 0.2, 0.2), cam, 10) is None  # behind the camera


def test_a_confirmed_track_above_the_bounds_is_refined_on_until_it_is_certain():
    """The book on the floor under a tight rotation bound (1 deg): its first track (15 inliers) ends its
    4 frames confirmed but at 1.3 deg. Refused when the refinement stops there (the paper's); refined on
    (up to 8 frames) the same track gets under the bound and is found, with its pose right."""
    tight = replace(LocalSearchConfig(), max_rotation_std_deg=1.0)
    paper, _ = run_local("book", "floor", config=replace(tight, max_refine_frames=tight.refine_frames))
    on, G_true = run_local("book", "floor", config=tight)
    first = [next(v for v in r.views if v.n_inliers) for r in (paper, on)]
    assert first[0].n_inliers == first[1].n_inliers  # the same start
    assert first[0].outcome.startswith("pose too uncertain")
    assert first[1].outcome.startswith("found") and on.found and on.rotation_std_deg <= 1.0
    pos_err, rot_err = pose_errors(on.G_WO, G_true)
    assert pos_err < 0.01 and rot_err < 3.0  # measured: 0.14 cm, 1.4 deg
    with pytest.raises(ConfigError, match="refine_frames <= max_refine_frames"):
        LocalSearchConfig(refine_frames=5, max_refine_frames=4)
