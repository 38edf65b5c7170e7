"""The camera levelled against the floor (:mod:`lab.navigation.level`): the solver recovers the mounts
that tilt the floor's normal, and in the simulator the levelled camera's vertical is the true one to a
fraction of the bracket's error."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lab.geometry import Pose2D
from lab.mounts import HeadMounts, MountedCamera, mounted_G_RC
from lab.navigation.level import ANGLES, FloorView, LevelConfig, NotLevelled, level_camera, solve_level
from lab.robot import StereoCamera

CAMERA = StereoCamera.from_fov()


def _views(mounts: HeadMounts, pans_deg, tilts_deg, noise_rad=0.0, rng=None) -> list[FloorView]:
    """The floor's normal each view would measure through ``mounts`` (exact, or turned by noise)."""
    out = []
    for t in tilts_deg:
        for p in pans_deg:
            pan, tilt = math.radians(p), math.radians(t)
            G = mounted_G_RC(
                pan, tilt, CAMERA.mount_R, CAMERA.camera_offset_P, mounts.head_rpy, mounts.camera_rpy, 0.0,
                mounts.tilt_zero,
            )  # fmt: skip
            n = G[:3, :3].T @ np.array([0.0, 0.0, 1.0])
            if noise_rad:
                n = n + rng.normal(0.0, noise_rad, 3)
                n /= np.linalg.norm(n)
            out.append(FloorView(pan, tilt, tuple(n), 5000))
    return out


DRAWN = HeadMounts(
    head_rpy=(math.radians(-0.6), math.radians(0.35), 0.0),
    camera_rpy=(math.radians(0.4), 0.0, math.radians(-0.8)),
    tilt_zero=math.radians(-1.1),
)


def _angles(m: HeadMounts) -> np.ndarray:
    return np.degrees([m.head_rpy[0], m.head_rpy[1], m.tilt_zero, m.camera_rpy[0], m.camera_rpy[2]])


def test_exact_normals_give_back_the_mounts_that_tilted_them():
    cfg = LevelConfig()
    lv = solve_level(_views(DRAWN, cfg.pans_deg, cfg.tilts_deg), CAMERA, cfg)
    # the prior (1 deg) pulls a little: the head's angles and the tilt's zero to 0.001 deg; the camera's
    # roll and yaw, which the floor tells apart only through the two tilts' sines, to 0.02 deg
    np.testing.assert_allclose(_angles(lv.mounts)[:3], _angles(DRAWN)[:3], atol=0.002)
    np.testing.assert_allclose(_angles(lv.mounts)[3:], _angles(DRAWN)[3:], atol=0.025)
    assert lv.rms_deg < 0.01 < lv.rms_before_deg and lv.views == 14
    assert lv.mounts.estimated == ANGLES and lv.mounts.pan_zero == 0.0 and lv.mounts.head_rpy[2] == 0.0


def test_noisy_normals_are_recovered_within_the_stated_deviations():
    """0.1 deg of noise on each view's normal: every angle within 3 of its stated deviations."""
    cfg = LevelConfig()
    rng = np.random.default_rng(7)
    lv = solve_level(_views(DRAWN, cfg.pans_deg, cfg.tilts_deg, math.radians(0.1), rng), CAMERA, cfg)
    sd = np.degrees(
        [*lv.mounts.std["head_rpy"][:2], lv.mounts.std["tilt_zero"], *lv.mounts.std["camera_rpy"][::2]]
    )
    err = np.abs(_angles(lv.mounts) - _angles(DRAWN))
    assert np.all(sd > 0) and np.all(err <= 3.0 * sd), (err, sd)


def test_one_pan_cannot_tell_the_heads_tilt_from_the_cameras_and_says_so():
    """From one pan the head's pitch and the tilt's zero are one rotation: the prior shares it out and the
    stated deviations stay near the prior's, instead of claiming what the views cannot tell."""
    cfg = LevelConfig(pans_deg=(0.0,), tilts_deg=(-20.0, -30.0, -40.0, -25.0, -35.0, -45.0), min_views=3)
    lv = solve_level(_views(DRAWN, cfg.pans_deg, cfg.tilts_deg), CAMERA, cfg)
    assert lv.mounts.std["tilt_zero"] > math.radians(0.5) and lv.mounts.std["head_rpy"][1] > math.radians(0.5)


def test_a_view_whose_floor_disagrees_is_left_out():
    """Two views with their floor turned by 1.5 deg (a strip of floor by a wall): left out, and the rest
    solved as if they were not there."""
    cfg = LevelConfig()
    views = _views(DRAWN, cfg.pans_deg, cfg.tilts_deg)
    for k in (0, 7):
        n = np.asarray(views[k].normal_C)
        turned = n + np.array([math.radians(1.5), 0.0, 0.0])
        views[k] = FloorView(views[k].pan, views[k].tilt, tuple(turned / np.linalg.norm(turned)), 100)
    lv = solve_level(views, CAMERA, cfg)
    assert lv.dropped == 2 and lv.views == 12
    np.testing.assert_allclose(_angles(lv.mounts)[:3], _angles(DRAWN)[:3], atol=0.002)


def test_too_few_views_of_the_floor_is_a_clear_error():
    with pytest.raises(NotLevelled, match="only 2 views showed the floor, need at least 6"):
        solve_level(_views(DRAWN, (0.0, 50.0), (-20.0,)), CAMERA)


def test_the_simulators_drawn_mounts_are_levelled_out():
    """The simulator draws the head's and the camera's mounts at 0.5 deg (exact sensors otherwise): the
    camera's vertical, which the nominal kinematics have 0.5-1 deg off, is within 0.3 deg of the true one
    after levelling (0.2 at the median), at pans and tilts the levelling never looked at (the stereo
    floor's normal carries a few hundredths of a degree of its own, which the split between the head's
    pitch and the tilt's zero amplifies). The images are 0.1 s old when they arrive (error scale 2's
    latency): each view waits for the head to have stood still longer than that."""
    from lab.sim import RenderSettings, SimRobot, SimWorld
    from lab.sim.sensing import sensing_profile

    room = {"camera_mount_deg": 0.5, "head_mount_deg": 0.5, "latency_s": 0.1}
    sensing = sensing_profile({"profile": "ideal", "room": room})
    with SimWorld("lab_room", RenderSettings(supersample=2)) as w:
        robot = SimRobot(w, CAMERA, start=Pose2D(0.0, -3.0, math.pi / 2), seed=3, sensing=sensing)
        robot.enable()
        lv = level_camera(robot)
        levelled = MountedCamera.of(CAMERA, lv.mounts)
        before, after = [], []
        for tilt in (-30.0, 0.0, 15.0):
            for pan in (-120.0, -60.0, 0.0, 60.0, 120.0):
                robot.command_pan_tilt(math.radians(pan), math.radians(tilt))
                robot.wait_pan_tilt(timeout=20.0)
                rp = w.truth.robot_pose()
                R_RC_true = _Rz(-rp.theta) @ w.truth.G_WC()[:3, :3]
                st = robot.pan_tilt()
                up_true = R_RC_true.T[:, 2]
                for cam, out in ((CAMERA, before), (levelled, after)):
                    up = cam.G_RC(st.pan, st.tilt)[:3, :3].T[:, 2]
                    out.append(math.degrees(math.acos(min(1.0, float(up @ up_true)))))
    assert lv.views + lv.dropped == 14 and lv.views >= 12
    assert np.median(before) > 0.5 and np.median(after) < 0.2 and max(after) < 0.3, (before, after)


def _Rz(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def test_a_search_levels_only_a_camera_whose_mounts_the_profile_states_uncertain(tmp_path):
    """``lab search``'s default: ``realistic`` states half a degree per mount, so the floor levels it;
    a profile that states the mounts exact (``sensors``, ``ideal``, a sensing file with both mount sigmas
    0, issue 52's survey-and-start condition) has nothing for the levelling to find."""
    from lab.runs.robots import mounts_stated

    assert mounts_stated("realistic") and mounts_stated("room")
    assert not mounts_stated("sensors") and not mounts_stated("ideal")
    f = tmp_path / "exact_mounts.toml"
    f.write_text(
        '[sensing]\nprofile = "realistic"\n[sensing.room]\ncamera_mount_deg = 0.0\nhead_mount_deg = 0.0\n'
    )
    assert not mounts_stated(f)
    f.write_text('[sensing]\nprofile = "sensors"\n[sensing.room]\nhead_mount_deg = 0.3\n')
    assert mounts_stated(f)
