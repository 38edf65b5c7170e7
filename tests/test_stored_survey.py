"""A room surveyed once (lab.localization.stored_survey): the tour's refined posters kept in a file, and a
later run that starts from them.

Peers: the synthetic lab room of ``tour_fakes`` (the true posters, drawn surveys, sightings with the
room's errors) and the least squares floor of :mod:`lab.localization.survey_limit`: a later robot that
sees one or two posters is placed by the whole constellation the tour tied together, not by those
posters' surveys.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest
from localization_helpers import NO_FLOOR
from tour_fakes import ROOM, Sightings, TourBase, in_room
from tour_fakes import survey_of as drawn_survey

from lab.errors import ConfigError
from lab.geometry import Pose2D
from lab.localization import LocalizationMode, LocalizedRobot, LocalizerConfig
from lab.localization.stored_survey import StoredSurvey, load_survey, survey_of
from lab.localization.survey_limit import survey_frame_error
from lab.localization.survey_tour import survey_stands, survey_tour

SURVEY_M, SURVEY_RAD = 0.015, math.radians(0.7)
CFG = LocalizerConfig(**NO_FLOOR)
START_SIGMA = np.diag([0.05**2, 0.05**2, math.radians(3.0) ** 2])  # the operator's start (issue 52)


def _robot(base: TourBase, mapped, rng) -> LocalizedRobot:
    robot = LocalizedRobot(base, "odometry", config=CFG, Sigma0=START_SIGMA, start_measured_by_hand=True)
    robot.mode, robot.observer = LocalizationMode.LANDMARKS, Sightings(base, mapped, rng)
    if mapped.joint_prior is not None:  # as LocalizedRobot does with a landmark map (it is set here by hand)
        robot.localizer.seed_posters(mapped)
    robot.log = lambda m: None
    return robot


def _toured(seed: int):
    """A drawn survey of the synthetic room, and the survey tour's posters (a StoredSurvey)."""
    rng = np.random.default_rng(7100 + seed)
    errors, mapped = drawn_survey(rng, SURVEY_M, SURVEY_RAD)
    base = TourBase(Pose2D(-1.5, -2.5, math.radians(30.0)), rng)
    robot = _robot(base, mapped, rng)
    robot.relocalize()
    stands = survey_stands(mapped, in_room, start_xy=robot.localizer.x[:2], config=CFG, cover=3)
    tour = survey_tour(robot, base.navigate, stands)
    assert all(tour.arrived)
    return errors, mapped, survey_of(robot.localizer, mapped, {"stands": len(stands)})


#: Where the later robot stands: the room's south-east corner, facing the east wall: a few posters in
#: view, the far ones seen by their bearings only.
CORNER = Pose2D(2.2, -3.2, math.radians(20.0))


def _placed(mapped, seed: int) -> float:
    """The position error [m] of a robot placed by hand at the corner (5 cm / 3 deg off) once it has
    looked round there."""
    rng = np.random.default_rng([7200, seed])
    off = rng.normal(0.0, [0.05, 0.05, math.radians(3.0)])
    base = TourBase(Pose2D(CORNER.x, CORNER.y, CORNER.theta), rng)
    base.wheels = np.array([CORNER.x + off[0], CORNER.y + off[1], CORNER.theta + off[2]])
    robot = _robot(base, mapped, rng)
    robot.relocalize(12, sigma_m=0.0, sigma_rad=0.0, passes=2)
    x = robot.localizer.x
    return math.hypot(x[0] - CORNER.x, x[1] - CORNER.y)


def test_a_room_surveyed_once_places_a_later_robot_by_every_poster():
    """Ten seeded rooms: the tour's posters, kept and loaded by a later run, place a robot at the room's
    corner with a median error under two thirds of the drawn survey's (which ties it to the few posters
    it sees), and within 0.5 cm of the floor all twelve posters' surveys leave there (the least squares
    frame of :mod:`lab.localization.survey_limit`): what a sighting cannot remove."""
    once, surveyed, floor = [], [], []
    for seed in range(10):
        errors, mapped, stored = _toured(seed)
        once.append(_placed(stored.applied_to(mapped), seed))
        surveyed.append(_placed(mapped, seed))
        names = sorted(errors)
        xy = [ROOM.get(n).centre_W[:2] for n in names]
        t = survey_frame_error(
            xy, np.array([errors[n] for n in names]), (CORNER.x, CORNER.y), SURVEY_M, SURVEY_RAD
        )
        floor.append(math.hypot(t[0], t[1]))
    once, surveyed, floor = (100 * np.array(v) for v in (once, surveyed, floor))
    print(
        f"at the corner: surveyed {np.round(surveyed, 2)}, once {np.round(once, 2)}, "
        f"floor {np.round(floor, 2)} cm"
    )
    assert np.median(once) < 2 / 3 * np.median(surveyed)
    assert np.median(np.abs(once - floor)) < 0.5


def test_the_file_round_trips_and_a_corrupt_or_foreign_one_is_refused(tmp_path):
    """Saved and loaded, the survey is the same to the bit; the map it gives holds the refined poses, each
    poster stated to its marginal deviation, and the joint covariance in the map's order, which the
    localizer seeds at once. A file edited by hand, of another format, cut short, missing, or made on
    another map is refused in one line that names it."""
    errors, mapped, stored = _toured(0)
    path = stored.save(tmp_path / "survey.json")
    back = load_survey(path)
    assert back.names == stored.names and back.record == stored.record
    for k in ("poses", "covariance", "map_poses"):
        np.testing.assert_array_equal(getattr(back, k), getattr(stored, k))
    once = back.applied_to(mapped)
    assert once.names() == mapped.names()
    names, L = once.joint_prior
    for i, lm in enumerate(once):
        j = back.names.index(lm.name)
        np.testing.assert_allclose(lm.planar, back.poses[j])
        np.testing.assert_allclose(
            L[3 * i : 3 * i + 3, 3 * i : 3 * i + 3], back.covariance[3 * j : 3 * j + 3, 3 * j : 3 * j + 3]
        )
        assert lm.survey_sigma_m == pytest.approx(back.sigma(j)[0])
    assert max(back.sigma(j)[0] for j in range(len(back.names))) < SURVEY_M  # the tour tightened every poster
    robot = _robot(TourBase(Pose2D(0, 0, 0), np.random.default_rng(1)), once, np.random.default_rng(1))
    loc = robot.localizer
    assert len(loc.landmark_estimates()) == len(once)
    idx = np.concatenate([[loc.posters.index_of(lm) + k for k in range(3)] for lm in once])
    np.testing.assert_allclose(loc.P[np.ix_(idx, idx)], L)
    robot.relocalize()
    assert loc.history
    with pytest.raises(ValueError, match="before the first update"):
        loc.seed_posters(once)

    data = json.loads(path.read_text())
    data["poses"][0][0] += 0.01
    (tmp_path / "edited.json").write_text(json.dumps(data))
    with pytest.raises(ConfigError, match=r"edited.json: the survey file is corrupt"):
        load_survey(tmp_path / "edited.json")
    (tmp_path / "short.json").write_text(path.read_text()[:200])
    with pytest.raises(ConfigError, match=r"short.json: not a survey file \(unreadable JSON"):
        load_survey(tmp_path / "short.json")
    (tmp_path / "v0.json").write_text(json.dumps({**data, "version": 0}))
    with pytest.raises(ConfigError, match="not a survey file of format 'lab-room-survey' version 1"):
        load_survey(tmp_path / "v0.json")
    with pytest.raises(ConfigError, match=r"no such survey file \(make one with `lab survey"):
        load_survey(tmp_path / "none.json")
    _, other = drawn_survey(np.random.default_rng(5), SURVEY_M, SURVEY_RAD)
    with pytest.raises(ConfigError, match="was made on another map: poster_.* survey this room again"):
        back.applied_to(other)
    fewer = type(mapped)(mapped.landmarks[:-1], mapped.room_size, "fewer")
    with pytest.raises(ConfigError, match="the map fewer has .* survey this room again"):
        back.applied_to(fewer)
    with pytest.raises(ConfigError, match="taken as exact"):
        survey_of(loc, ROOM)
    with pytest.raises(ConfigError, match="symmetric positive definite"):
        StoredSurvey(back.names, back.poses, -back.covariance, back.map_poses)


def _lab(*args, timeout=600):
    return subprocess.run(
        [sys.executable, "-m", "lab", *args], capture_output=True, text=True, timeout=timeout
    )


def test_lab_search_and_lab_survey_check_the_survey_against_the_runs_map(tmp_path):
    """``lab search --survey`` reads the file and checks it against the map of the run it starts: a survey
    of episode 1's room is refused in episode 2's (another draw of the surveyed map), in one line; so is
    a missing file. ``lab survey`` refuses a room whose map is taken as exact (``sensors``: nothing to
    refine)."""
    from lab.runs.robots import RobotKind
    from lab.runs.room import room_landmarks, with_stored_survey
    from lab.scene import load_scene

    scene = load_scene("lab_room")
    room = room_landmarks(RobotKind.SIM, None, scene, "landmarks", sensing="realistic", seed=1)
    lms = list(room.landmarks)
    C = np.kron(np.eye(len(lms)), np.diag([0.01**2, 0.01**2, math.radians(0.5) ** 2]))
    poses = np.array([lm.planar for lm in lms])
    stored = StoredSurvey(tuple(lm.name for lm in lms), poses, C, poses, room.landmarks.source)
    assert with_stored_survey(room, stored).stored_survey["posters"] == len(lms)
    path = stored.save(tmp_path / "room1.json")
    r = _lab("search", "--object", "book", "--seed", "2", "--survey", str(path))
    assert (
        r.returncode == 2 and "was made on another map" in r.stderr and "survey this room again" in r.stderr
    )
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr
    r = _lab("search", "--object", "book", "--survey", str(tmp_path / "none.json"))
    assert r.returncode == 2 and "no such survey file" in r.stderr, r.stderr
    r = _lab("survey", "--out", str(tmp_path / "s.json"), "--sensing", "sensors")
    assert r.returncode == 2 and "nothing to survey" in r.stderr and "taken as exact" in r.stderr, r.stderr
    assert not (tmp_path / "s.json").exists()


def test_a_robot_configs_room_survey_is_where_lab_survey_writes_and_later_runs_start(tmp_path):
    """``[room] survey`` in a robot config: resolved beside the config (it need not exist yet: ``lab
    survey`` makes it); ``lab survey`` without ``--out`` takes it as its file (here it goes on to refuse a
    robot with no landmark map, writing nothing), and without either refuses to start;
    a run on the landmarks starts from it unless ``--survey`` names another; a run on odometry ignores it;
    a configured file that is missing is one line naming it."""
    from dataclasses import replace

    from hw_helpers import EMULATED_TOML, REPO

    from lab.hardware.config import load_config
    from lab.runs.robots import RobotKind
    from lab.runs.room import room_landmarks, survey_to_use, with_stored_survey
    from lab.runs.survey import run_survey
    from lab.scene import load_scene

    text = EMULATED_TOML.read_text().replace(
        'calibration = "calibration/', f'calibration = "{REPO / "hardware" / "calibration"}/'
    )
    (tmp_path / "robot.toml").write_text(text + '\n[room]\nsurvey = "room/survey.json"\n')
    hw = load_config(tmp_path / "robot.toml")
    assert hw.room.survey == str((tmp_path / "room" / "survey.json").resolve())
    (tmp_path / "plain.toml").write_text(text)
    with pytest.raises(ConfigError, match="give --out FILE.json, or survey ="):
        run_survey(None, robot_config=tmp_path / "plain.toml")
    with pytest.raises(ConfigError, match="nothing to survey"):  # past the file: the robot has no map
        run_survey(None, robot_config=tmp_path / "robot.toml")
    assert not (tmp_path / "room").exists()

    scene = load_scene("lab_room")
    room = room_landmarks(RobotKind.SIM, None, scene, "landmarks", sensing="realistic", seed=1)
    odometry = room_landmarks(RobotKind.SIM, None, scene, "odometry", sensing="realistic", seed=1)
    assert survey_to_use(None, hw, room) == hw.room.survey
    assert survey_to_use(tmp_path / "other.json", hw, room) == tmp_path / "other.json"
    assert survey_to_use(None, hw, odometry) is None
    assert survey_to_use(None, replace(hw, room=replace(hw.room, survey="")), room) is None
    with pytest.raises(ConfigError) as e:
        with_stored_survey(room, survey_to_use(None, hw, room))
    assert "survey.json: no such survey file" in str(e.value) and "\n" not in str(e.value)
