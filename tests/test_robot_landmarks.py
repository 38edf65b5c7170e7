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
    assert unmapped["localization_note"].startswith("no landmark map for this robot ([room] landmarks")
    for d in (blind, unmapped):
        assert json.loads(json.dumps(d))["localization_error_m"] is None  # no truth on the real robot
    # the odometry's origin is the start in the room: --start, else the search room's [robot] start
    p, q = starts
    assert (p.x, p.y, math.degrees(p.theta)) == pytest.approx((0.4, -2.5, 80.0), abs=1e-9)
    assert (q.x, q.y, math.degrees(q.theta)) == pytest.approx((0.0, -3.0, 90.0), abs=1e-9)
