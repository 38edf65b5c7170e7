"""A colour detection of a moving object kept as a track and followed with the head
(lab.search.follow.reobserve): in the simulated lab room a book drives on its carrier at 0.1 m/s while
the robot stands 2.5 m away; one frame's colour peak starts the track, and re-observations every few
seconds (the head aimed at the predicted point, the blob found near the predicted pixel, real stereo)
keep it within 0.3 m of the book's true position at that moment, while the position where it was seen
is farther. Seeded, realistic sensing."""

from __future__ import annotations

import numpy as np
from moving_scenes import facing_on_the_floor

from lab.geometry import se3_inv, transform_points
from lab.runs.robots import make_robot
from lab.runs.search import map_spec
from lab.scene import load_scene
from lab.search.colour_track import ColourTrack, ColourTrackConfig, measurement_xy
from lab.search.follow import reobserve
from lab.search.global_search import GlobalSearchConfig, object_likelihood_ratio, process_view
from lab.search.probability_map import ProbabilityMap
from lab.search.tracking import aim_at
from lab.sim import RenderSettings, SimWorld
from lab.sim.moving_object import MovingKind, MovingObjectConfig, make_moving_object
from lab.training.search import search_database
from lab.vision.colour import colour_histogram

OBJECT, SEED, RANGE_M, SPEED = "book", 7, 2.5, 0.1
LOOKS, EVERY_S = 10, 3.0


def first_look(robot, db, aim_W, gcfg):
    """One frame aimed at ``aim_W`` and its used colour peaks, as the global search finds them (the
    ratio histogram against the frame's own colours)."""
    p_R = transform_points(se3_inv(robot.odometry().G()), np.asarray(aim_W, float))
    robot.command_pan_tilt(*aim_at(p_R, robot.camera, robot.pan_tilt_limits))
    robot.wait_pan_tilt()
    frame = robot.capture_stereo()
    space = db.meta.get("colour_space", "rg")
    bg = colour_histogram(frame.left, space=space, bins=db.histogram.shape[0])
    model = object_likelihood_ratio(db.histogram, bg, gcfg.ratio_eps)
    pmap = ProbabilityMap(map_spec(load_scene("lab_room")))
    view = process_view(frame, model, space, pmap, gcfg)
    return frame, model, space, [p for p in view.peaks if p.used]


def test_a_colour_detection_of_a_driving_book_is_followed_by_the_head():
    scene, (ox, oy, oz), start = facing_on_the_floor(OBJECT, SEED, RANGE_M)  # the robot facing the book
    db = search_database(OBJECT)
    cfg = ColourTrackConfig()
    with SimWorld(scene, RenderSettings(supersample=2)) as w:
        with make_robot(world=w, start=start, seed=SEED, sensing="realistic") as run:
            robot = run.robot
            robot.enable()
            mover = MovingObjectConfig(MovingKind.RANDOM, SPEED, 5.0)
            m = make_moving_object(w, OBJECT, mover, np.random.default_rng([SEED, 50]))
            frame, model, space, used = first_look(robot, db, (ox, oy, oz), GlobalSearchConfig())
            assert used, "the book's colours gave no peak"
            # the global search keeps a track for every used peak; the test follows the book's
            truth0 = m.G_WO_at(frame.t)[:2, 3]
            peak = min(used, key=lambda p: np.linalg.norm(p.p_W[:2] - truth0))
            p_W, R = measurement_xy(frame, peak.uv, peak.disparity, cfg)
            assert np.linalg.norm(p_W[:2] - truth0) < 0.3
            track = ColourTrack(p_W, R, frame.t, SPEED, cfg)
            seen = 0
            for _ in range(LOOKS):
                t_next = robot.now() + EVERY_S
                while robot.now() < t_next:
                    robot.step(0.1)
                seen += reobserve(robot, track, model, db)
            truth = m.G_WO_at(track.t)[:2, 3]
    err = float(np.linalg.norm(track.position_at(track.t) - truth))
    last_seen = float(np.linalg.norm(np.asarray(track.start_xy) - truth))
    assert track.frames == LOOKS and seen == track.updates >= LOOKS // 2
    assert err < 0.3, (err, last_seen)
    assert last_seen > 0.3 and last_seen > 2 * err, (err, last_seen)
