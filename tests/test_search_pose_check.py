"""The pose check before "found" (lab.search.pose_check) on rendered views, against the simulator's true
pose: the true pose is confirmed, a pose turned away from it is not."""

import math

import numpy as np
import pytest
from test_search_local import SCENE, set_up

from lab.errors import ConfigError
from lab.geometry import Rz, se3, se3_inv, transform_points
from lab.search.local_search import aim_at, make_matcher, object_roi
from lab.search.pose_check import PoseCheckConfig, check_pose, predicted_visible, rest_tilt_deg
from lab.sim import RenderSettings, SimRobot, SimWorld
from lab.training.search import search_database
from lab.vision.stereo import stereo_features


def _view(name: str, surface: str):
    """A frame of the object from its test set-up, the head aimed at it by the truth: the frame, the
    database and the true ``G_CO``."""
    place, pose = set_up(name, surface)
    db = search_database(name)
    with SimWorld(SCENE.with_pose(name, place), RenderSettings(supersample=2)) as w:
        robot = SimRobot(w, start=pose, seed=0)
        robot.enable()
        G_WO = w.truth.G_W(name)
        p_R = transform_points(se3_inv(pose.G()), G_WO[:3, 3])
        robot.command_pan_tilt(*aim_at(p_R, robot.camera, robot.pan_tilt_limits))
        robot.wait_pan_tilt()
        frame = robot.capture_stereo()
        G_CO = se3_inv(w.truth.G_WC()) @ G_WO
    return frame, db, G_CO


@pytest.fixture(scope="module")
def views():
    return {k: _view(*k) for k in (("cereal_box", "table"), ("book", "shelf"))}


def _check(frame, db, G_CO):
    roi = object_roi(G_CO, db.extent, frame.camera, 20)
    f = stereo_features(frame.left, frame.right, frame.camera, roi=roi, t=frame.t)
    return check_pose(f, make_matcher(db).match(f), db, G_CO, frame.camera, PoseCheckConfig(), roi)


@pytest.mark.parametrize("key", [("cereal_box", "table"), ("book", "shelf")])
def test_true_pose_is_confirmed_and_a_turned_one_is_not(views, key):
    frame, db, G_true = views[key]
    ok = _check(frame, db, G_true)
    assert ok.confirmed, ok.reason
    for deg in (45.0, -45.0, 180.0):  # turned about the object's vertical axis, the same centre
        bad = _check(frame, db, G_true @ se3(Rz(math.radians(deg))))
        assert not bad.confirmed, (deg, bad.reason)
        assert bad.n_explained < ok.n_explained


def test_visible_features_are_the_ones_in_front_and_in_the_image(views):
    """Turned 180 degrees the camera sees the object's other side: no feature predicted visible
    from the front is predicted visible from the back of a box (the faces are disjoint); and an
    object behind the camera has none in view."""
    frame, db, G_true = views[("cereal_box", "table")]
    front = predicted_visible(db, G_true, frame.camera, 30.0)
    back = predicted_visible(db, G_true @ se3(Rz(math.pi)), frame.camera, 30.0)
    assert front.sum() > 20 and not np.any(front & back)
    G_behind = G_true.copy()
    G_behind[:3, 3] *= -1.0
    assert not predicted_visible(db, G_behind, frame.camera, 30.0).any()


def test_bad_pose_check_config_is_one_clear_error():
    with pytest.raises(ConfigError, match="dist_m"):
        PoseCheckConfig(dist_m=0.0)


def test_rest_tilt_against_scipy_and_the_bound_by_the_orientation_error():
    """The tilt is the smallest angle between an object axis, turned into the world by SciPy's
    rotation, and the vertical; an upright box turned by an error rotation is tilted by at most the
    error's angle (so a tilt above the success criterion's 10 degrees means an error above it)."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(3)
    for _ in range(200):
        r = Rotation.random(random_state=rng)
        axes_W = r.apply(np.eye(3))  # the object's x, y, z axes in the world
        peer = min(math.degrees(math.acos(min(1.0, abs(a[2])))) for a in axes_W)
        assert rest_tilt_deg(r.as_matrix()) == pytest.approx(peer, abs=1e-5)
        # upright on one of its faces, any yaw, then an error of up to 40 degrees
        face = Rotation.from_euler(
            "ZYX", [rng.uniform(-180, 180), 90 * rng.integers(4), 90 * rng.integers(4)], degrees=True
        )
        err = Rotation.from_rotvec(rng.normal(size=3) * 0.3)
        assert rest_tilt_deg(face.as_matrix()) < 1e-6
        assert rest_tilt_deg((err * face).as_matrix()) <= math.degrees(err.magnitude()) + 1e-6
    with pytest.raises(ConfigError, match="3x3 rotation"):
        rest_tilt_deg(np.eye(4))
