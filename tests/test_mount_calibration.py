"""The camera's mounts estimated (issue 52): the model against the simulator's own, the least-squares
solve against drawn truth (synthetic, then the simulator's rendered images and the rehearsal's emulators),
the calibration file (round trip, corruption detected) and the hardware landmark file's survey sigma."""

from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from lab.errors import ConfigError
from lab.geometry import Pose2D, pan_tilt_G_RC, pan_tilt_G_RP, se3, se3_inv
from lab.localization.landmarks import Landmark
from lab.localization.mount_calibration import ESTIMATED, MountSighting, solve_mounts
from lab.mounts import CalibratedRobot, HeadMounts, MountedCamera, load_mounts, mounted_G_RC, save_mounts
from lab.robot import SIM_CAMERA
from lab.sim.room_errors import rotation_rpy

REPO = Path(__file__).resolve().parents[1]
CAMERA = SIM_CAMERA.camera(mount_R=(0.0, 0.0, 1.1))
DEG = math.radians(1.0)


def sim_style_G_RC(camera, pan, tilt, head_rpy, cam_rpy):
    """The simulator's composition of its drawn mounts (lab/sim/robot.py ``_G_WC``), written out here as
    the independent peer: the head rotated about the axes' intersection, the camera about its centre."""
    G_RC = pan_tilt_G_RC(pan, tilt, camera.mount_R, camera.camera_offset_P)
    m = np.asarray(camera.mount_R, float)
    G_RP = pan_tilt_G_RP(pan, tilt, m)
    G_PC = se3_inv(G_RP) @ G_RC
    o = G_PC[:3, 3]
    head = se3(None, m) @ se3(rotation_rpy(head_rpy)) @ se3(None, -m)
    return head @ G_RP @ se3(rotation_rpy(cam_rpy), o) @ se3(None, -o) @ G_PC


def test_the_mounted_kinematics_are_the_simulators_and_nominal_at_zero():
    rng = np.random.default_rng(3)
    for _ in range(20):
        pan, tilt = rng.uniform(-2.5, 2.5), rng.uniform(-0.7, 0.5)
        head, cam = rng.normal(0, DEG, 3), rng.normal(0, DEG, 3)
        mine = mounted_G_RC(pan, tilt, CAMERA.mount_R, CAMERA.camera_offset_P, head, cam)
        assert np.allclose(mine, sim_style_G_RC(CAMERA, pan, tilt, head, cam), atol=1e-12)
        zero = MountedCamera.of(CAMERA, HeadMounts()).G_RC(pan, tilt)
        assert np.allclose(zero, CAMERA.G_RC(pan, tilt), atol=1e-15)
    # a tilt zero is a tilt: the camera at tilt t with zero z is the nominal camera at t + z
    m = MountedCamera.of(CAMERA, HeadMounts(tilt_zero=0.01))
    assert np.allclose(m.G_RC(0.3, 0.1), CAMERA.G_RC(0.3, 0.11), atol=1e-15)


def _ring_of_posters(rng):
    out = []
    for i, a in enumerate(np.linspace(0, 2 * math.pi, 8)[:-1]):
        c = (3.0 * math.cos(a), 3.0 * math.sin(a), 1.5 + 0.3 * rng.standard_normal())
        out.append(Landmark(f"p{i}", c, a + math.pi / 2, (1.2, 0.02, 0.8), (-math.cos(a), -math.sin(a))))
    return out


def _synthetic_sightings(rng, head, cam, pan_zero, tilt_zero, base: Pose2D, sigma_m=0.003, sigma_deg=0.3):
    """Each poster in view at every pan (every 20 deg) and tilt of a pattern, its G_CL from the
    simulator-style camera, perturbed by the stated covariance."""
    posters = _ring_of_posters(rng)
    Sig = np.diag([sigma_m**2] * 3 + [math.radians(sigma_deg) ** 2] * 3)
    L = np.linalg.cholesky(Sig)
    out = []
    for pan in np.radians(np.arange(-160, 161, 20)):
        for tilt in np.radians([-8.0, 6.0, 18.0, 30.0]):
            G_WC = base.G() @ sim_style_G_RC(CAMERA, pan + pan_zero, tilt + tilt_zero, head, cam)
            for lm in posters:
                G_CL = se3_inv(G_WC) @ lm.G_WL
                u, v = CAMERA.project(G_CL[:3, 3][None])[0]
                if G_CL[2, 3] < 0.5 or not (0 < u < CAMERA.width and 0 < v < CAMERA.height):
                    continue
                n = L @ rng.standard_normal(6)
                G = G_CL.copy()
                G[:3, 3] += n[:3]
                G[:3, :3] = Rotation.from_rotvec(n[3:]).as_matrix() @ G[:3, :3]
                out.append(MountSighting(lm, pan, tilt, G, Sig))
    return out


def test_solver_recovers_half_degree_mounts_from_synthetic_sightings():
    """0.5 deg per axis (head and camera), pan-tilt zeros of a step: the observable angles within 0.05
    deg and within 3 stated sigmas; the unobservable yaw about the pan axis lands in the base's heading."""
    rng = np.random.default_rng(11)
    head = 0.5 * DEG * np.array([1.0, -1.0, 1.0])
    cam = 0.5 * DEG * np.array([-1.0, 1.0, 1.0])
    pz, tz = 0.05 * DEG, -0.05 * DEG
    base = Pose2D(0.1, -0.2, 0.3)
    s = _synthetic_sightings(rng, head, cam, pz, tz, base)
    res = solve_mounts(s, CAMERA, Pose2D(0.15, -0.25, 0.35), (0.1, 5 * DEG))
    truth = np.array([head[0], head[1], tz - cam[1], cam[0], cam[2]])
    err = np.degrees(res.theta - truth)
    print(dict(zip(ESTIMATED, err.round(4), strict=True)), np.degrees(res.std).round(4), res.chi2_dof)
    assert np.all(np.abs(err) < 0.05)
    assert np.all(np.abs(err) < 3 * np.degrees(res.std))
    assert 0.5 < res.chi2_dof < 1.5 and res.n_rejected == 0
    # head yaw + pan zero + the start's heading: one angle (to the second order of the small angles)
    assert math.degrees(res.start.theta - (base.theta + head[2] + pz)) == pytest.approx(0.0, abs=0.03)
    assert math.hypot(res.start.x - base.x, res.start.y - base.y) < 0.005


def test_solver_refuses_too_few_sightings():
    rng = np.random.default_rng(1)
    s = _synthetic_sightings(rng, np.zeros(3), np.zeros(3), 0.0, 0.0, Pose2D(0, 0, 0))[:5]
    with pytest.raises(ConfigError, match="at least 8 poster sightings, got 5"):
        solve_mounts(s, CAMERA, Pose2D(0, 0, 0), (0.1, 0.1))


# --- the file -------------------------------------------------------------------------------------------


def _mounts():
    return HeadMounts(
        head_rpy=(0.001, -0.002, 0.0),
        camera_rpy=(0.003, 0.0, -0.004),
        tilt_zero=0.005,
        std={
            "head_rpy": [1e-4, 2e-4, 0.0],
            "camera_rpy": [3e-4, 0.0, 4e-4],
            "pan_zero": 0.0,
            "tilt_zero": 5e-4,
        },
        estimated=ESTIMATED,
        robot='the "rehearsal"',
        created="2026-12-05T20:00:00Z",
    )


def test_calibration_file_round_trips(tmp_path):
    p = save_mounts(tmp_path / "cal" / "mounts.toml", _mounts())
    back = load_mounts(p)
    m = _mounts()
    assert np.allclose(back.head_rpy, m.head_rpy, atol=1e-9) and np.allclose(
        back.camera_rpy, m.camera_rpy, atol=1e-9
    )
    assert back.tilt_zero == pytest.approx(m.tilt_zero, abs=1e-9) and back.pan_zero == 0.0
    assert np.allclose(back.std["camera_rpy"], m.std["camera_rpy"], atol=1e-9)
    assert back.estimated == ESTIMATED and back.robot == m.robot and back.created == m.created
    assert [f.name for f in p.parent.iterdir()] == ["mounts.toml"]  # no temporary file left behind


@pytest.mark.parametrize(
    "corrupt, message",
    [
        (lambda t: re.sub("tilt_zero_deg = .*", "tilt_zero_deg = 0.3", t), "checksum does not match"),
        (lambda t: t[: len(t) // 2], "not valid TOML|checksum"),
        (lambda t: t.rsplit("checksum", 1)[0], "checksum does not match"),
        (lambda t: t.replace("version = 1", "version = 2"), "version 2 is not supported"),
        (lambda t: t.replace('format = "lab-mounts"', 'format = "other"'), "not a mount calibration"),
        (lambda t: "[[", "not valid TOML"),
    ],
)
def test_a_corrupt_calibration_file_is_refused_in_one_line(tmp_path, corrupt, message):
    p = save_mounts(tmp_path / "mounts.toml", _mounts())
    p.write_text(corrupt(p.read_text()))
    with pytest.raises(ConfigError, match=message) as e:
        load_mounts(p)
    assert str(p) in str(e.value) and "\n" not in str(e.value)


def test_a_missing_file_and_an_implausible_angle_are_refused(tmp_path):
    with pytest.raises(ConfigError, match="not found .*lab hardware calibrate"):
        load_mounts(tmp_path / "none.toml")
    with pytest.raises(ConfigError, match="beyond 10 deg"):
        HeadMounts(camera_rpy=(0.0, 0.0, math.radians(12.0)))
    with pytest.raises(ConfigError, match="finite"):
        HeadMounts(tilt_zero=float("nan"))


# --- on the simulator and the rehearsal ------------------------------------------------------------------


def test_simulator_calibration_recovers_half_degree_mounts(tmp_path):
    """The simulated robot's camera rendered through mounts drawn at 0.5 deg per axis (head and camera,
    realistic's pan-tilt zeros and camera errors in an exact room); the routine sees the lab room's posters
    from its centre in real rendered images. Four angles within 0.1 deg; the camera's yaw, the weakest
    (seen only as a roll that grows with the tilt), within 3 of its stated sigmas, which are under 0.1."""
    from lab.runs.calibrate import calibrate

    sensing = {"profile": "sensors", "room": {"camera_mount_deg": 0.5, "head_mount_deg": 0.5}}
    out = tmp_path / "mounts.toml"
    run = calibrate(None, out=out, sensing=sensing, seed=2, start=(0.0, 0.0, 90.0), log=print)
    r = run.result
    truth = np.array([run.truth[k] for k in ESTIMATED])
    assert np.all(np.abs(np.degrees(truth)) > 0.02)  # there is something to recover on every axis
    err = np.degrees(r.theta - truth)
    std = np.degrees(r.std)
    assert np.all(np.abs(err[:4]) < 0.1), err  # measured: 0.007, 0.005, 0.035, 0.018 deg
    assert abs(err[4]) < 3 * std[4] and std[4] < 0.1, (err, std)  # measured: 0.118 +- 0.067 deg
    back = load_mounts(out)
    assert np.allclose(back.camera_rpy, r.mounts.camera_rpy, atol=1e-7) and back.robot == "sim"


def test_rehearsal_runs_the_calibration_end_to_end(tmp_path):
    """On the device emulators (hardware/rehearsal.toml) with the room rendered through [sim] mounts:
    the routine drives the real PTU protocol, writes the config's [camera] mounts file, and a robot made
    from that config then sees through the calibrated camera (a shorter pattern than the default)."""
    from lab.runs.calibrate import calibrate
    from lab.runs.robots import make_robot

    text = (REPO / "hardware" / "rehearsal.toml").read_text()
    text = text.replace('calibration = "calibration/', f'calibration = "{REPO}/hardware/calibration/')
    text = text.replace(
        "supersample = 1\n",
        "supersample = 2\nhead_mount_deg = [0.4, -0.5, 0.3]\ncamera_mount_deg = [-0.5, 0.4, 0.5]\n",
    )
    text = text.replace("mount_R = [0.0, 0.0, 0.7]\n", 'mount_R = [0.0, 0.0, 0.7]\nmounts = "mounts.toml"\n')
    cfg = tmp_path / "rehearsal.toml"
    cfg.write_text(text)
    pattern = {"pan": (-120, -80, -40, 0, 40, 80, 120), "tilt": (-8.0, 12.0, 30.0)}
    run = calibrate(cfg, sensing="sensors", start=(0.0, 0.0, 90.0), pattern_deg=pattern, log=print)
    assert run.path == tmp_path / "mounts.toml" and run.path.is_file()
    truth = np.array([run.truth[k] for k in ESTIMATED])
    assert np.degrees(truth) == pytest.approx([0.4, -0.5, -0.4, -0.5, 0.5])
    err = np.degrees(run.result.theta - truth)
    assert np.all(np.abs(err[:4]) < 0.1), err
    assert abs(err[4]) < 3 * np.degrees(run.result.std[4]), err
    with make_robot(cfg, scene="lab_room") as session:
        assert isinstance(session.robot, CalibratedRobot)
        assert session.robot.camera.mounts.tilt_zero == pytest.approx(run.result.theta[2], abs=1e-7)


def test_default_runs_see_through_the_nominal_camera(tmp_path):
    """No calibration (the simulator by default, a config whose mounts file does not exist): the robot
    is not wrapped and its camera is the plain StereoCamera, as before."""
    from lab.runs.robots import make_robot
    from lab.sim import SimWorld

    with SimWorld("lab_room") as w, make_robot(world=w, seed=0, sensing="realistic") as run:
        assert type(run.robot).__name__ == "SimRobot" and type(run.robot.camera) is type(CAMERA)
    with SimWorld("lab_room") as w, make_robot(world=w, seed=0, sensing="realistic", mounts=_mounts()) as run:
        frame = run.robot.capture_stereo()
        assert isinstance(frame.camera, MountedCamera) and frame.G_RC == pytest.approx(
            mounted_G_RC(
                0.0,
                0.0,
                frame.camera.mount_R,
                frame.camera.camera_offset_P,
                *dataclasses.astuple(_mounts())[:4],
            )
        )


# --- the hardware landmark file's survey sigma -----------------------------------------------------------


def _landmark_file(tmp_path, top: str = "", own: str = "") -> Path:
    tex = REPO / "worlds" / "textures" / "poster0.png"
    p = tmp_path / "landmarks.toml"
    p.write_text(
        f"room_size = [6.0, 8.0]\n{top}\n"
        f'[[landmark]]\nname = "a"\ntexture = "{tex}"\nsize = [1.4, 0.02, 1.0]\n'
        f"centre = [0.0, 3.94, 1.5]\n{own}\n"
        f'[[landmark]]\nname = "b"\ntexture = "{tex}"\nsize = [1.4, 0.02, 1.0]\n'
        f"centre = [1.0, 3.94, 1.5]\n"
    )
    return p


def test_landmark_file_survey_sigma_per_file_and_per_poster(tmp_path):
    from lab.training.landmarks import load_landmark_map

    m = load_landmark_map(
        _landmark_file(tmp_path, "survey_sigma_m = 0.02\nsurvey_sigma_deg = 1.0", "survey_sigma_m = 0.05")
    )
    a, b = m.landmarks
    assert (a.survey_sigma_m, b.survey_sigma_m) == (0.05, 0.02)
    assert a.survey_sigma_rad == b.survey_sigma_rad == pytest.approx(math.radians(1.0))
    assert a.surveyed and b.surveyed
    exact = load_landmark_map(_landmark_file(tmp_path))
    assert not any(lm.surveyed for lm in exact)
    hw = load_landmark_map(REPO / "hardware" / "landmarks.toml")
    assert all(
        lm.survey_sigma_m == 0.015 and lm.survey_sigma_rad == pytest.approx(math.radians(0.7)) for lm in hw
    )


@pytest.mark.parametrize(
    "top, own, message",
    [
        ("survey_sigma_m = -0.01", "", "survey_sigma_m: .* within \\[0, 0.5\\] m"),
        ("", "survey_sigma_deg = 45.0", r"landmark\[0\] \(a\) survey_sigma_deg: .* within \[0, 30\] deg"),
        ("", 'survey_sigma_m = "2 cm"', "survey_sigma_m: .*got '2 cm'"),
        ("survey_sigma_deg = true", "", "survey_sigma_deg: .*got True"),
        ("survey_sigma_deg = nan", "", "survey_sigma_deg: .*got nan"),
    ],
)
def test_bad_survey_sigmas_are_refused_naming_the_field(tmp_path, top, own, message):
    from lab.training.landmarks import load_landmark_map

    p = _landmark_file(tmp_path, top, own)
    with pytest.raises(ConfigError, match=message) as e:
        load_landmark_map(p)
    assert str(p) in str(e.value)


def _rehearsal_config(tmp_path, extra_sim: str = "", mounts: str = "") -> Path:
    text = (REPO / "hardware" / "rehearsal.toml").read_text()
    text = text.replace('calibration = "calibration/', f'calibration = "{REPO}/hardware/calibration/')
    text = text.replace("supersample = 1\n", f"supersample = 1\n{extra_sim}\n")
    text = text.replace("mount_R = [0.0, 0.0, 0.7]\n", f"mount_R = [0.0, 0.0, 0.7]\n{mounts}\n")
    p = tmp_path / "rehearsal.toml"
    p.write_text(text)
    return p


@pytest.mark.parametrize(
    "extra, message",
    [
        ("head_mount_deg = [0.4, 0.1]", r"\[sim\] head_mount_deg must be \[roll, pitch, yaw\]"),
        (
            "camera_mount_deg = [0.0, 0.0, 15.0]",
            r"camera_mount_deg .* within \[-10, 10\], got \[0.0, 0.0, 15.0\]",
        ),
    ],
)
def test_bad_rendered_mounts_are_refused(tmp_path, extra, message):
    from lab.hardware.config import load_config

    with pytest.raises(ConfigError, match=message):
        load_config(_rehearsal_config(tmp_path, extra))


def test_a_corrupt_mounts_file_of_a_config_stops_the_run_before_it_starts(tmp_path):
    from lab.runs.robots import make_robot

    cfg = _rehearsal_config(tmp_path, mounts='mounts = "cal/mounts.toml"')
    p = save_mounts(tmp_path / "cal" / "mounts.toml", _mounts())
    p.write_text(p.read_text().replace("version = 1", "version = 1\nrobot_extra = 1"))
    with pytest.raises(ConfigError, match="checksum does not match") as e:
        with make_robot(cfg, scene="lab_room"):
            pass
    assert str(p) in str(e.value)


def test_lab_search_refuses_a_corrupt_mounts_file_in_one_line(tmp_path, capsys):
    from lab.cli import main

    p = save_mounts(tmp_path / "mounts.toml", _mounts())
    p.write_text(p.read_text().replace("version = 1", "version = 3"))
    code = main(["search", "--object", "book", "--seed", "0", "--mounts", str(p), "--max-time", "1"])
    err = capsys.readouterr().err
    assert code != 0 and "version 3 is not supported" in err and str(p) in err


def test_check_reads_the_mounts_file_a_config_names(tmp_path):
    """`lab hardware check`'s line: not made yet passes (nominal kinematics), a good file shows its
    angles, a corrupt one fails with the fix (the rest of the check is not run here)."""
    from lab.hardware.cli import check_mounts
    from lab.hardware.config import load_config

    cfg = load_config(_rehearsal_config(tmp_path, mounts='mounts = "cal/mounts.toml"'))
    lines = []

    def line(ok, what, detail, fix=""):
        lines.append((ok, what, detail, fix))

    check_mounts(cfg, line)
    save_mounts(tmp_path / "cal" / "mounts.toml", _mounts())
    check_mounts(cfg, line)
    (tmp_path / "cal" / "mounts.toml").write_text("format = 1")
    check_mounts(cfg, line)
    (ok0, _, d0, _), (ok1, _, d1, _), (ok2, _, d2, fix) = lines
    assert ok0 and "not made yet" in d0
    assert ok1 and "[0.057, -0.115, 0.286, 0.172, -0.229] deg" in d1
    assert not ok2 and "not a mount calibration" in d2 and fix.startswith("lab hardware calibrate --config")


def test_lab_hardware_calibrate_without_a_landmark_map_is_one_line(capsys):
    """The emulated robot (random-dot camera, no [room] landmarks): nothing to calibrate against, said in
    one line before any device is touched."""
    from lab.cli import main

    code = main(["hardware", "calibrate", "--config", str(REPO / "hardware" / "emulated.toml")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert err[-1].startswith("lab hardware: error: lab hardware calibrate needs a landmark map")
