"""``lab hardware calibrate``: the camera's mounts and the tilt's zero, estimated by a standing robot.

The robot stands at the room's start and turns its head over a pattern of pans and tilts
(:data:`PATTERN_DEG`). In each stereo frame it fits every poster of the landmark map the nominal
kinematics say it should see (:class:`~lab.localization.LandmarkObserver`, the localizer's own
perception of real images), and :func:`~lab.localization.mount_calibration.solve_mounts` solves for the
mounts from all the sightings. The estimates and their deviations are printed and written atomically to
the robot's calibration file (:func:`lab.mounts.save_mounts`), which later runs use
(:func:`lab.runs.robots.make_robot`: the config's ``[camera] mounts``, or ``lab search --mounts``).

The same routine runs on three robots, as the search does (:mod:`lab.runs.robots`): the simulator
(the ``realistic`` profile: the camera rendered through the episode's drawn mounts), a rehearsal
(``hardware/rehearsal.toml``: the device emulators, the room rendered from their true state through the
config's ``[sim] head_mount_deg`` / ``camera_mount_deg``) and the real robot. It never drives the base.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from lab.errors import ConfigError
from lab.geometry import Pose2D
from lab.localization import LandmarkObserver, LocalizerConfig
from lab.localization.mount_calibration import ESTIMATED, MountCalibration, MountSighting, solve_mounts
from lab.mounts import save_mounts
from lab.robot import Robot
from lab.runs.robots import PlacedRobot, RobotKind, load_robot_config, make_robot, robot_kind
from lab.runs.room import robot_start, room_landmarks, sim_start_sigma
from lab.scene import load_scene

__all__ = ["PATTERN_DEG", "CalibrationRun", "calibrate", "collect_sightings", "pattern", "report_lines"]

#: The head's pattern: every pan at every tilt [deg]. Several tilts tell the camera's yaw from a pan;
#: pans all round the room tilt the pan axis's errors into view.
PATTERN_DEG = {"pan": tuple(range(-150, 151, 20)), "tilt": (-8.0, 6.0, 18.0, 30.0)}


def pattern(limits, pattern_deg=None) -> list[tuple[float, float]]:
    """The (pan, tilt) [rad] of ``pattern_deg`` (default :data:`PATTERN_DEG`) inside the head's
    ``limits``, in a boustrophedon order (each tilt's row walked the other way than the last: the head
    never swings back round)."""
    pd = pattern_deg or PATTERN_DEG
    out = []
    for i, t in enumerate(pd["tilt"]):
        pans = pd["pan"] if i % 2 == 0 else tuple(reversed(pd["pan"]))
        for p in pans:
            pan, tilt = math.radians(p), math.radians(t)
            if limits.pan_min <= pan <= limits.pan_max and limits.tilt_min <= tilt <= limits.tilt_max:
                out.append((pan, tilt))
    return out


@dataclass
class CalibrationRun:
    """What :func:`calibrate` did: the result, the file written, and the truth where there is one."""

    result: MountCalibration
    path: Path | None
    n_frames: int
    robot: str
    truth: dict = field(default_factory=dict)  # the simulator's drawn angles [rad] (tests, tuning)


def collect_sightings(
    robot: Robot, observer: LandmarkObserver, start: Pose2D, settle_s: float = 0.3, pattern_deg=None
):
    """Turn the head over :func:`pattern` (``pattern_deg``) and fit the posters the nominal kinematics
    say are in view from the believed ``start``; returns ``(sightings, n_frames)``."""
    robot.enable()
    sightings: list[MountSighting] = []
    n = 0
    for pan, tilt in pattern(robot.pan_tilt_limits, pattern_deg):
        robot.command_pan_tilt(pan, tilt)
        robot.wait_pan_tilt()
        robot.step(settle_s)
        frame = robot.capture_stereo(after=robot.now())
        n += 1
        cands = observer.candidates(start.as_array(), frame)
        for ob in observer.observe(frame, cands):
            if ob.Sigma_rv is None:
                continue
            pt = frame.pan_tilt
            sightings.append(MountSighting(ob.landmark, pt.pan, pt.tilt, ob.G_CL, ob.Sigma_rv, frame.wheels))
    robot.command_pan_tilt(0.0, 0.0)
    robot.wait_pan_tilt()
    return sightings, n


def _sim_truth(robot) -> dict:
    """The simulated robot's drawn mounts as the solver's angles (see the solver's docstring): the tilt's
    zero absorbs the camera's pitch."""
    episode = robot.truth.sensing
    room, pt = episode.room, episode.pan_tilt
    head, cam = room.head_mount_rpy, room.camera_mount_rpy
    tz = (0.0 if pt is None else pt.tilt_offset) - cam[1]
    return dict(zip(ESTIMATED, (head[0], head[1], tz, cam[0], cam[2]), strict=True))


def calibrate(
    robot_config=None,
    *,
    out: str | Path | None = None,
    sensing="realistic",
    seed: int = 0,
    world: str = "lab_room",
    start=None,
    pattern_deg: dict | None = None,
    log: Callable[[str], None] = print,
) -> CalibrationRun:
    """Run the routine (module docstring) and write the file ``out`` (None: do not write).

    Parameters
    ----------
    robot_config : path or HardwareConfig, optional
        A robot config (a rehearsal or the real robot); None: the simulator.
    out : path, optional
        The calibration file (default on a robot: its config's ``[camera] mounts``).
    sensing, seed :
        The simulator's profile and episode (its drawn mounts), or a rehearsal camera's.
    world : str
        The scene the simulator (or a rehearsal) renders, with its posters and the robot's start.
    start : (x_m, y_m, heading_deg), optional
        Where the robot stands for the calibration (``--start``): in the simulator and a rehearsal it is
        placed there; on the real robot it is where the operator stood it (default: the config's
        ``[room] start``, else the scene's start). A spot that sees many posters within a few metres
        calibrates best.
    pattern_deg : dict, optional
        ``{"pan": [...], "tilt": [...]}`` [deg] instead of :data:`PATTERN_DEG` (a shorter one for a test).

    Raises
    ------
    ConfigError
        No landmark map, too few sightings, no place to write the file.
    """
    hw = load_robot_config(robot_config)
    kind = robot_kind(hw)
    if out is None and hw is not None and hw.camera.mounts:
        out = hw.camera.mounts
    scene = load_scene(world)
    if kind is RobotKind.REHEARSAL and start is not None:  # the rendered robot stands there
        scene = replace(scene, robot_start=tuple(float(v) for v in start))
    room = room_landmarks(kind, hw, scene, "landmarks", progress=True, sensing=sensing, seed=seed)
    if room.landmarks is None:
        raise ConfigError(f"lab hardware calibrate needs a landmark map: {room.note}")
    observer = LandmarkObserver(room.landmarks, LocalizerConfig(), np.random.default_rng([seed, 52, 7]))
    t0 = time.perf_counter()
    got = _sightings(kind, hw, scene, room, observer, sensing, seed, start, pattern_deg)
    sightings, n, truth, camera, name, start, sigma = got
    log(
        f"lab hardware calibrate: {len(sightings)} poster sightings in {n} frames "
        f"({time.perf_counter() - t0:.0f} s)"
    )
    result = solve_mounts(sightings, camera, start, sigma)
    stamp = datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
    mounts = replace(result.mounts, robot=name, created=stamp)
    path = None if out is None else save_mounts(out, mounts)
    run_out = CalibrationRun(result, path, n, name, truth)
    for line in report_lines(run_out):
        log(line)
    return run_out


def _sightings(kind, hw, scene, room, observer, sensing, seed: int, start, pattern_deg):
    """Stand the robot (the simulator's, or a robot config's with the nominal kinematics) and collect the
    pattern's sightings: ``(sightings, n_frames, truth, camera, robot name, believed start, its sigma)``."""
    if kind is RobotKind.SIM:
        from lab.sim import RenderSettings, SimWorld

        at = None if start is None else Pose2D(start[0], start[1], math.radians(start[2]))
        with (
            SimWorld(scene, RenderSettings(supersample=2)) as w,
            make_robot(world=w, seed=seed, sensing=sensing, start=at) as run,
        ):
            believed = run.robot.odometry()
            Sigma0 = sim_start_sigma(run.robot)
            sigma = (
                (0.01, math.radians(0.5)) if Sigma0 is None else (Sigma0[0, 0] ** 0.5, Sigma0[2, 2] ** 0.5)
            )
            got = collect_sightings(run.robot, observer, believed, pattern_deg=pattern_deg)
            return (*got, _sim_truth(run.robot), run.robot.camera, "sim", believed, sigma)
    st = robot_start(hw, scene.robot_start, start, room.landmarks.room_size)
    sigma = (st.Sigma0[0, 0] ** 0.5, st.Sigma0[2, 2] ** 0.5)
    with make_robot(hw, seed=seed, scene=scene, sensing=sensing, config_mounts=False) as run:
        got = collect_sightings(PlacedRobot(run.robot, st.pose), observer, st.pose, pattern_deg=pattern_deg)
        return (*got, _rehearsal_truth(hw), run.robot.camera, run.name, st.pose, sigma)


def _rehearsal_truth(hw) -> dict:
    """A rehearsal's rendered mounts ([sim] head_mount_deg, camera_mount_deg) as the solver's angles
    (its pan-tilt zeros are the emulator's: none)."""
    if hw is None or hw.camera.source != "sim":
        return {}
    h, c = np.radians(hw.sim.head_mount_deg), np.radians(hw.sim.camera_mount_deg)
    return dict(zip(ESTIMATED, (h[0], h[1], -c[1], c[0], c[2]), strict=True))


def report_lines(run: CalibrationRun) -> list[str]:
    """The console report: each angle with its deviation (and the truth, where known)."""
    r = run.result
    lines = [
        f"  {len(ESTIMATED)} angles from {r.n_used} sightings ({r.n_rejected} dropped by the gate), "
        f"chi2/dof {r.chi2_dof:.2f}"
    ]
    for i, name in enumerate(ESTIMATED):
        t = run.truth.get(name)
        truth = (
            "" if t is None else f"   (truth {math.degrees(t):+.3f}, off {math.degrees(r.theta[i] - t):+.3f})"
        )
        lines.append(
            f"  {name:12s} {math.degrees(r.theta[i]):+.3f} +- {math.degrees(r.std[i]):.3f} deg{truth}"
        )
    lines.append(
        "  not estimated: the head's yaw and the pan zero (one rotation with the base's heading: the "
        "localizer's heading takes it), the camera's pitch (in tilt_zero)"
    )
    lines.append(f"  wrote {run.path}" if run.path is not None else "  (no file written: give --out)")
    return lines


def main_calibrate(args) -> int:
    """``lab hardware calibrate`` (the command line's handler)."""
    calibrate(
        args.config,
        start=args.start,
        out=args.out,
        sensing=args.sensing,
        seed=args.seed,
        log=lambda s: print(s, file=sys.stderr),
    )
    return 0
