"""`--localization landmarks` on a robot: the robot config's landmark map and start pose (lab/runs/room.py).

Peers: the rehearsal's rendered world (the emulator's true base pose), the emulators' synthetic camera
(random dots: no poster can be seen in it), and the config loader's one-line errors.
"""

from __future__ import annotations

import dataclasses
import json
import math

import pytest
from hw_helpers import EMULATED_TOML, REPO

from lab.cli import main
from lab.errors import ConfigError
from lab.hardware.config import RoomConfig, load_config
from lab.runs.search import navigator_factory, run_search

LANDMARKS_TOML = REPO / "hardware" / "landmarks.toml"
REHEARSAL_TOML = REPO / "hardware" / "rehearsal.toml"


def _emulated_config(tmp_path, room: str = "", name: str = "robot.toml"):
    """hardware/emulated.toml written to ``tmp_path`` (its calibration path made absolute) with a
    ``[room]`` section's lines ``room``."""
    text = EMULATED_TOML.read_text().replace(
        'calibration = "calibration/', f'calibration = "{REPO / "hardware" / "calibration"}/'
    )
    p = tmp_path / name
    p.write_text(text + ("\n[room]\n" + room + "\n" if room else ""))
    return p


@pytest.mark.parametrize(
    "room, message",
    [
        ('landmarks = "nope.toml"', "[room] landmarks 'nope.toml' not found"),
        ("landmarks = 3", "[room] landmarks must be a string"),
        ("start = [1.0, 2.0]", "[room] start must be [x_m, y_m, heading_deg]"),
        ('start = [1.0, 2.0, "east"]', "[room] start must be [x_m, y_m, heading_deg]"),
        ("start_sigma = [0.0, 3.0]", "[room] start_sigma must be [sigma_m, sigma_deg] (2 numbers > 0)"),
        ("start_sigma = 0.05", "[room] start_sigma must be a list"),
        ("landmark = 'landmarks.toml'", "unknown key [room] 'landmark'"),
        ("survey = 3", "[room] survey must be a string"),
    ],
)
def test_bad_room_fields_are_one_line_naming_the_file_and_field(tmp_path, room, message):
    p = _emulated_config(tmp_path, room)
    with pytest.raises(ConfigError) as e:
        load_config(p)
    text = str(e.value)
    assert message in text and str(p) in text and "\n" not in text, text


def test_room_fields_are_read_and_the_map_resolved_beside_the_config(tmp_path):
    (tmp_path / "room.toml").write_text(LANDMARKS_TOML.read_text().replace("../worlds", str(REPO / "worlds")))
    cfg = load_config(_emulated_config(tmp_path, 'landmarks = "room.toml"\nstart = [0.5, -2.0, 80]'))
    assert cfg.room == RoomConfig(str((tmp_path / "room.toml").resolve()), (0.5, -2.0, 80.0), (0.10, 5.0))
    assert load_config(REPO / "hardware" / "robot.toml").room.landmarks == str(LANDMARKS_TOML.resolve())


def _cli_error(capsys, args) -> str:
    capsys.readouterr()
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    return err


def test_a_bad_landmark_file_or_start_is_one_line_before_any_port_is_opened(tmp_path, capsys):
    """The emulated config's ports do not exist here: each error comes before the robot is built."""
    from lab.training.landmarks import trained_landmark_map

    trained_landmark_map(LANDMARKS_TOML, progress=False)  # a cold cache would print its training lines first
    bad = LANDMARKS_TOML.read_text().replace("../worlds", str(REPO / "worlds"))
    bad = bad.replace('name = "poster_west"', 'name = "poster_north"')  # a duplicate name
    (tmp_path / "dup.toml").write_text(bad)
    cfg = _emulated_config(tmp_path, 'landmarks = "dup.toml"')
    search = ["search", "--object", "book", "--robot", str(cfg), "--localization", "landmarks"]
    err = _cli_error(capsys, search)
    assert "dup.toml landmark[1] name: duplicate landmark name 'poster_north'" in err, err
    good = _emulated_config(tmp_path, f'landmarks = "{LANDMARKS_TOML}"', name="good.toml")
    search = ["search", "--object", "book", "--robot", str(good), "--localization", "landmarks"]
    err = _cli_error(capsys, [*search, "--start", "4.0,0,90"])
    assert "--start (4, 0) is outside the room: x within +-3 m, y within +-4 m" in err, err
    err = _cli_error(capsys, ["search", "--object", "book", "--start", "0,-3,90"])
    assert "--start is where a robot stands in the room (with --robot)" in err, err
    with pytest.raises(SystemExit):
        main([*search, "--start", "1,2"])
    assert "--start must be 3 comma-separated numbers" in capsys.readouterr().err


def test_hardware_check_reads_the_room_map_trains_it_and_says_where_to_stand(tmp_path):
    """`lab hardware check`'s room lines (lab.runs.room.check_room): the classroom's map is read and its
    posters trained (the cache's databases are those the runs load), a bad map is one FAIL line naming
    the file and field with the fix, no map says odometry alone, and the start is the one lab search
    assumes."""
    from lab.runs.room import check_room
    from lab.training.landmarks import trained_landmark_map

    def lines_of(cfg):
        out = []
        check_room(cfg, lambda ok, what, detail, fix="": out.append((ok, what, detail, fix)))
        return {what: (ok, detail, fix) for ok, what, detail, fix in out}

    room = lines_of(load_config(REPO / "hardware" / "robot.toml"))
    ok, detail, _ = room["landmark map"]
    assert ok and "12 posters (poster_north, poster_west" in detail and str(LANDMARKS_TOML) in detail
    assert len(trained_landmark_map(LANDMARKS_TOML, progress=False)) == 12  # trained: in the cache now
    ok, detail, _ = room["start"]
    assert ok and "lab search assumes (0 m, -3 m, 90 deg), from the search room's [robot] start" in detail
    assert "known to 5 cm and 3 deg" in detail

    bad = LANDMARKS_TOML.read_text().replace("../worlds", str(REPO / "worlds"))
    (tmp_path / "dup.toml").write_text(bad.replace('name = "poster_west"', 'name = "poster_north"'))
    dup = _emulated_config(tmp_path, 'landmarks = "dup.toml"\nstart = [0.5, -2.0, 80]')
    room = lines_of(load_config(dup))
    ok, detail, fix = room["landmark map"]
    assert not ok and "dup.toml landmark[1] name: duplicate landmark name 'poster_north'" in detail
    assert "Localize against the room's posters" in fix
    assert room["start"][0] and "(0.5 m, -2 m, 80 deg), from [room] start of" in room["start"][1]

    room = lines_of(load_config(_emulated_config(tmp_path, name="plain.toml")))
    assert room["landmark map"] == (
        True,
        "none ([room] landmarks): lab search and lab identify will localize by odometry alone",
        "",
    )


def test_hardware_check_reads_the_configs_room_survey(tmp_path):
    """``[room] survey`` in ``lab hardware check``'s room lines: a file not made yet, a corrupt one and one
    made on another map are each one FAIL line with the command that makes it again; a good one says
    what the tour that made it did."""
    import numpy as np

    from lab.localization.stored_survey import StoredSurvey
    from lab.runs.room import check_room
    from lab.training.landmarks import trained_landmark_map

    def lines_of(cfg):
        out = []
        check_room(cfg, lambda ok, what, detail, fix="": out.append((ok, what, detail, fix)))
        return {what: (ok, detail, fix) for ok, what, detail, fix in out}

    (tmp_path / "landmarks.toml").write_text(
        LANDMARKS_TOML.read_text().replace("../worlds", str(REPO / "worlds"))
    )
    cfg = load_config(_emulated_config(tmp_path, 'landmarks = "landmarks.toml"\nsurvey = "survey.json"'))
    ok, detail, fix = lines_of(cfg)["room survey"]
    assert not ok and "survey.json ([room] survey) is not made yet" in detail
    assert f"lab survey --robot {cfg.path}" in fix

    lms = list(trained_landmark_map(tmp_path / "landmarks.toml", progress=False))
    poses = np.array([lm.planar for lm in lms])
    C = np.kron(np.eye(len(lms)), np.diag([0.01**2, 0.01**2, math.radians(0.5) ** 2]))
    tour = {
        "stands": [[0.5, -2.0], [-0.5, 1.5], [1.0, 1.5]],
        "arrived": [True, True, False],
        "n_sightings": 40,
    }
    names = tuple(lm.name for lm in lms)
    StoredSurvey(names, poses, C, poses, "landmarks.toml", {"tour": tour}).save(tmp_path / "survey.json")
    ok, detail, _ = lines_of(cfg)["room survey"]
    assert ok and "12 posters as a tour of 2 of 3 stands placed them (40 sightings)" in detail

    text = (tmp_path / "survey.json").read_text()
    (tmp_path / "survey.json").write_text(text.replace('"n_sightings": 40', '"n_sightings": 41'))
    ok, detail, fix = lines_of(cfg)["room survey"]
    assert not ok and "corrupt" in detail and "lab survey --robot" in fix

    moved = poses + [0.05, 0.0, 0.0]
    StoredSurvey(names, moved, C, moved, "landmarks.toml", {"tour": tour}).save(tmp_path / "survey.json")
    ok, detail, fix = lines_of(cfg)["room survey"]
    assert not ok and "was made on another map" in detail and "lab survey --robot" in fix
    assert "room survey" not in lines_of(
        load_config(_emulated_config(tmp_path, 'landmarks = "landmarks.toml"'))
    )


def test_a_map_whose_posters_are_never_seen_falls_back_and_says_so(tmp_path, capsys):
    """The real robot's path on the emulators, whose synthetic random-dot camera shows no poster: with
    the room's map the run looks for its posters, sees none, and says the pose is odometry alone; without
    a map it says it has none. The robot stands where --start says."""
    from lab.hardware.emulators import start_emulators

    starts = []

    def attach(agent):
        starts.append(agent.robot.odometry())

    with start_emulators(tmp_path / "links") as emu:
        cfg = load_config(EMULATED_TOML).with_ports(base=emu.base_port, ptu=emu.ptu_port)
        cfg = dataclasses.replace(cfg, base=dataclasses.replace(cfg.base, stale_timeout_s=0.5))  # shared GIL
        kw = {"max_time": 3.0, "navigate": navigator_factory, "localization": "landmarks", "attach": attach}
        mapped = dataclasses.replace(cfg, room=RoomConfig(landmarks=str(LANDMARKS_TOML)))
        capsys.readouterr()
        blind = run_search("book", 0, robot_config=mapped, start=(0.4, -2.5, 80.0), **kw).to_json()
        err = capsys.readouterr().err
        unmapped = run_search("book", 0, robot_config=cfg, **kw).to_json()
        assert emu.create.wheel_speeds() == (0, 0)
    assert blind["localization"] == "landmarks" and blind["landmark_updates"] == 0
    assert blind["localization_note"] == "no landmark was seen: the pose is odometry alone"
    assert "lab: localization: no landmark was seen: the pose is odometry alone" in err
    assert unmapped["localization"] == "odometry" and unmapped["landmark_updates"] == 0
    # no poster seen: the odometry's calibration is still its prior (the nominal base); none on odometry
    cal = blind["odometry_calibration"]
    assert cal["turn_scale"] == 1.0 and cal["curvature_rad_per_m"] == 0.0
    assert cal["turn_scale_sd"] == pytest.approx(0.04, rel=0.2) and unmapped["odometry_calibration"] is None
    assert unmapped["localization_note"].startswith("no landmark map for this robot ([room] landmarks")
    for d in (blind, unmapped):
        assert json.loads(json.dumps(d))["localization_error_m"] is None  # no truth on the real robot
    # the odometry's origin is the start in the room: --start, else the search room's [robot] start
    p, q = starts
    assert (p.x, p.y, math.degrees(p.theta)) == pytest.approx((0.4, -2.5, 80.0), abs=1e-9)
    assert (q.x, q.y, math.degrees(q.theta)) == pytest.approx((0.0, -3.0, 90.0), abs=1e-9)


def test_rehearsed_search_corrects_a_start_measured_30cm_10deg_off(monkeypatch):
    """The rehearsal (emulators, the lab room rendered from their true state) told it stands 30 cm and
    10 deg from where it does: the first poster it sees corrects the start (the gate alone, with the
    start's 5 cm / 3 deg, would have rejected it), and the localized pose ends far closer to the rendered
    world's truth than the odometry placed at the told start."""
    from lab.navigation.navigator import NavigatorConfig
    from lab.search.config import SearchAgentConfig
    from lab.search.global_search import GlobalSearchConfig

    config = SearchAgentConfig(global_search=GlobalSearchConfig(pans_deg=(0.0,), tilts_deg=(-30.0,)))
    nav_config = NavigatorConfig(scan_pans=(0.0,))
    robots = []
    told = (0.25, -2.85, 100.0)  # the scene's start is (0, -3, 90 deg): 29 cm and 10 deg off
    res = run_search(
        "cereal_box",
        0,
        place=(0.0, -1.6, 0.0, -90.0),  # 1.4 m ahead
        max_time=20.0,  # wall time: the first poster is seen before the first drive, ~10 s in
        navigate=lambda robot, spec: navigator_factory(robot, spec, config=nav_config),
        config=config,
        robot_config=REHEARSAL_TOML,
        localization="landmarks",
        start=told,
        attach=lambda agent: robots.append(agent.robot.base),  # BudgetedRobot -> LocalizedRobot
    )
    d = json.loads(json.dumps(res.to_json()))
    hist = robots[0].localizer.history
    print({k: d[k] for k in ("found", "odometry_error_m", "localization_error_m", "landmark_updates")})
    print([(r.landmark, r.kind, round(r.nis, 1)) for r in hist])
    assert d["localization"] == "landmarks" and d["landmark_updates"] >= 1 and d["localization_note"] is None
    # the first sighting comes before the first drive (the search re-localizes before it drives): the
    # base still stands at the scene's start, which the reset pose must be near; the gate alone would
    # have rejected it (NIS > chi-square(3)'s 0.999 quantile, 16.3)
    first = next(r for r in hist if r.accepted)
    assert first.kind == "reset" and first.nis > 16.3
    assert math.hypot(first.x[0] - 0.0, first.x[1] + 3.0) < 0.06  # measured: 3 cm
    assert abs(math.degrees(first.x[2]) - 90.0) < 3.0  # measured: 0.3 deg
    assert d["odometry_error_m"] > 0.15  # the told start's error, turned by the drive (measured: 0.19)
    assert d["localization_error_m"] < 0.7 * d["odometry_error_m"]  # measured: 0.03-0.09 (4 runs)
    # as in the simulator, the robot's localizer estimates its camera's yaw on the base (the pan zero
    # and the brackets, [camera] mount_sigma_deg 0.7 with the pan-tilt's step) and its range scale (the
    # calibration's 0.5 % focal lengths and baseline), from the stated accuracies
    cam = robots[0].camera
    assert cam.pointing_std_deg == pytest.approx(math.hypot(0.05, 0.7))
    c = robots[0].localizer.config
    assert (c.camera_yaw_sigma_rad, c.range_scale_sigma) == (
        math.radians(cam.pointing_std_deg),
        cam.depth_scale_std,
    )
    est = d["camera_estimate"]
    print(est)
    assert est["yaw_sd_deg"] <= cam.pointing_std_deg and est["range_scale_sd"] <= cam.depth_scale_std


def test_identify_on_a_robot_uses_the_map_and_needs_a_start(tmp_path, capsys):
    """`lab identify --robot ... --localization landmarks` (identify's _localized) on the emulators with
    the synthetic camera: the config's map is used once a start is known (--start), nothing is seen in
    random dots and it says so; without a start on the real robot's path it falls back and says why."""
    from lab.hardware.emulators import start_emulators
    from lab.runs.identify import run_identify

    with start_emulators(tmp_path / "links") as emu:
        cfg = load_config(EMULATED_TOML).with_ports(base=emu.base_port, ptu=emu.ptu_port)
        cfg = dataclasses.replace(cfg, base=dataclasses.replace(cfg.base, stale_timeout_s=0.5))
        cfg = dataclasses.replace(cfg, room=RoomConfig(landmarks=str(LANDMARKS_TOML)))
        kw = {"max_actions": 0, "max_time_s": 3.0, "figures": False, "localization": "landmarks"}
        capsys.readouterr()
        placed = run_identify(1, 0, "static", "random", robot_config=cfg, start=(0.5, 1.0, 45.0), **kw)
        err = capsys.readouterr().err
        unplaced = run_identify(1, 0, "static", "random", robot_config=cfg, **kw)
    assert (
        "the robot starts at (0.500, 1.000) m, 45.0 deg in the room (--start; sigma 0.100 m, 5.0 deg)" in err
    )
    assert placed["localization"] == "landmarks" and placed["landmark_updates"] == 0
    assert placed["localization_note"] == "no landmark was seen: the pose is odometry alone"
    assert unplaced["localization"] == "odometry"
    assert unplaced["localization_note"].startswith("no start pose in the room for this robot (--start")
    assert placed["odometry_error_m"] is None and placed["localization_error_m"] is None  # no truth
