"""Survey a room once (``lab survey``): drive the survey tour and keep the refined posters in a file.

A map measured with a tape is off by 1-2 cm and about a degree per poster, and a search that starts
from it refines only the posters it happens to see. The survey tour
(:func:`lab.runs.room.survey_the_room`) ties every poster to the others, but costs minutes of the
robot's time, and a room's posters do not move between runs. So the tour is driven once, here, and its
refined posters with their joint covariance are written to a file
(:mod:`lab.localization.stored_survey`) that every later ``lab search --survey FILE`` starts from.

The robot is set up as a search's is (:mod:`lab.runs.session`): the simulator, a rehearsal or the real
robot stood at its start; its camera levelled first where a search's would be. In the simulator the
file's record also holds each poster's error against the scene before and after (evaluation only: the
robot never reads it).
"""

from __future__ import annotations

import contextlib
import math
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from lab.errors import ConfigError
from lab.localization import LocalizationMode
from lab.localization.stored_survey import StoredSurvey, survey_of
from lab.runs.robots import RobotKind, levelled, load_robot_config, robot_kind
from lab.runs.room import localize, room_landmarks, survey_the_room
from lab.runs.session import levels_by_default, start_of, trial_session
from lab.scene import load_scene

__all__ = ["SURVEY_COVER", "run_survey"]

#: Stands that see each poster well: a poster seen well from three places is placed by bearings that
#: cross, not by one stereo range; the tour is driven once per room, so its length is cheap.
SURVEY_COVER = 3


def run_survey(
    out: str | Path | None,
    seed: int = 0,
    *,
    world: str = "lab_room",
    sensing="realistic",
    robot_config=None,
    start=None,
    level: bool | None = None,
    progress: bool = False,
    cover: int = SURVEY_COVER,
) -> dict:
    """Drive the survey tour in the room of ``world`` (episode ``seed`` in the simulator, whose surveyed
    map it refines) and write the refined posters to ``out``; returns what ``lab survey --json`` writes:
    the file, the tour and the posters' stated deviations before and after (in the simulator also their
    errors against the scene). ``cover`` is the stands that see each poster well. ``out`` None: the robot
    config's ``[room] survey``, where its later runs look for it.

    Raises
    ------
    ConfigError
        No file to write (no ``out``, no ``[room] survey``), no landmark map, or a map taken as exact
        (nothing to refine: a profile without the room's survey error, or a landmark file without survey
        sigmas).
    """
    from lab.runs.search import TrialOptions, map_spec

    wall0 = time.perf_counter()
    scene = load_scene(world)
    hw = load_robot_config(robot_config)
    out = out if out is not None else hw.room.survey
    if not out:
        raise ConfigError(
            'where to write the survey: give --out FILE.json, or survey = "FILE.json" in the robot config\'s '
            "[room] (then its later runs start from it)"
        )
    kind = robot_kind(hw)
    room = room_landmarks(kind, hw, scene, "landmarks", progress, sensing=sensing, seed=seed)
    if room.mode is not LocalizationMode.LANDMARKS:
        raise ConfigError(f"nothing to survey: {room.note}")
    if not any(lm.surveyed for lm in room.landmarks):
        raise ConfigError(
            f"nothing to survey: the map {room.landmarks.source} is taken as exact (a sensing profile with "
            "the room's survey error, such as realistic, or a landmark file with survey_sigma_m)"
        )
    start_pose = start_of(kind, hw, scene, room, start)
    opts = TrialOptions(sensing=sensing)
    with contextlib.ExitStack() as stack:
        run, _ = trial_session(stack, kind, hw, scene, "", seed, opts, None)
        to_level = level if level is not None else levels_by_default(kind, sensing)
        base, camera_level = levelled(run.robot) if to_level else (run.robot, None)
        robot = localize(base, kind, room, start_pose, seed)
        tour = survey_the_room(robot, map_spec(scene), cover=cover)
        record = {"tour": tour, "camera_level": camera_level, "seed": int(seed), "robot": run.name}
        stored = survey_of(robot.localizer, room.landmarks, record)
    truth = None if kind is RobotKind.HARDWARE else _true_posters(scene)
    posters = _posters(stored, room.landmarks, truth)
    shape = None if truth is None else _shape(stored, truth)
    stored = replace(stored, record={**record, "posters": posters, "shape": shape})
    path = stored.save(out)
    return {
        "survey": str(path),
        "posters": posters,
        "shape": shape,
        "tour": tour,
        "camera_level": camera_level,
        "wall_time_s": round(time.perf_counter() - wall0, 3),
    }


def _true_posters(scene) -> dict:
    """The posters' true planar poses, by name: the scene's, which the simulator and a rehearsal render."""
    from lab.training.landmarks import landmark_map_from_scene

    return {lm.name: lm.planar for lm in landmark_map_from_scene(scene)}


def _shape(stored: StoredSurvey, truth: dict) -> dict:
    """How far the posters are off the scene before and after, split into the turn-and-shift of them all
    about the room's centre (the frame: what sightings cannot move, :mod:`lab.localization.survey_limit`)
    and what is left (the shape: RMS over the posters' positions) [cm, deg]. Evaluation only."""
    from lab.localization.survey_limit import survey_frame_error

    names = [n for n in stored.names if n in truth]
    xy = np.array([truth[n][:2] for n in names])
    out = {}
    for key, poses in (("before", stored.map_poses), ("after", stored.poses)):
        E = np.array([poses[stored.names.index(n)] - truth[n] for n in names])
        E[:, 2] = [math.remainder(float(a), 2 * math.pi) for a in E[:, 2]]
        t = survey_frame_error(xy, E, (0.0, 0.0), 0.015, math.radians(0.7))  # the weights: a ratio only
        fitted = np.column_stack([t[0] - t[2] * xy[:, 1], t[1] + t[2] * xy[:, 0]])
        rms = float(np.sqrt(np.mean(np.sum((E[:, :2] - fitted) ** 2, axis=1))))
        out[key] = {
            "frame": [round(100 * float(t[0]), 3), round(100 * float(t[1]), 3), round(math.degrees(t[2]), 3)],
            "shape_rms_cm": round(100 * rms, 3),
        }
    return out


def _posters(stored: StoredSurvey, landmarks, truth) -> dict:
    """Each poster's stated deviation before (its survey) and after (the tour), and with the ``truth``
    (the posters' true planar poses) its position and yaw error before and after [cm, deg]."""
    out = {}
    for i, name in enumerate(stored.names):
        lm = landmarks.get(name)
        sm, sr = stored.sigma(i)
        row = {
            "sigma_before": [round(100 * lm.survey_sigma_m, 3), round(math.degrees(lm.survey_sigma_rad), 3)],
            "sigma_after": [round(100 * sm, 3), round(math.degrees(sr), 3)],
        }
        if truth is not None and name in truth:
            for key, pose in (("error_before", stored.map_poses[i]), ("error_after", stored.poses[i])):
                d = pose - truth[name]
                yaw = math.remainder(float(d[2]), 2 * math.pi)
                row[key] = [round(100 * float(np.hypot(d[0], d[1])), 3), round(math.degrees(yaw), 3)]
        out[name] = row
    return out
