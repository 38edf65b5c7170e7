"""The robot in the room: where a run's robot starts, the landmark map it localizes against, and the
localizer around it (:class:`~lab.localization.LocalizedRobot`), on every kind of robot.

* **the simulator**: the scene's posters, as a survey would give them under a profile with the real
  room's errors (:func:`surveyed_map`: each poster off by the survey's error, drawn per episode, while
  the renderer draws the true ones); the start is the scene's, the odometry starting where the
  operator believes the robot stands (:mod:`lab.sim.room_errors`);
* **a rehearsal**: the robot config's ``[room] landmarks`` file, else the posters of the scene it
  renders; the start is ``--start``, else ``[room] start``, else the rendered scene's start;
* **the real robot**: ``[room] landmarks`` (``hardware/landmarks.toml``: without one the run falls back
  to odometry alone and says so in its JSON and log); the start is ``--start``, else ``[room] start``,
  else the search room's ``[robot] start``.

On a robot the wheel odometry reads (0, 0, 0) where the base was switched on;
:class:`~lab.runs.robots.PlacedRobot` puts it at the start in W. The start is a pose someone measured
(a tape measure from the room's origin), so the localizer starts with the covariance ``[room]
start_sigma`` says and lets the first landmark it sees correct it
(:meth:`~lab.localization.Localizer.first_sighting`): a start 30 cm off its mark is corrected
at the first poster, not locked out by the gate. In the simulator the localizer is told the profile's
stated start sigma the same way (:func:`sim_start_sigma`; a profile without the room's errors starts it
certain, as before).
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from lab.errors import ConfigError, LabError
from lab.geometry import Pose2D
from lab.hardware.config import HardwareConfig, RoomConfig
from lab.localization import LandmarkMap, LocalizationMode, LocalizedRobot, LocalizerConfig
from lab.robot import Robot
from lab.runs.robots import PlacedRobot, RobotKind

__all__ = [
    "RobotStart",
    "RoomLandmarks",
    "camera_states_told",
    "check_room",
    "localization_in_words",
    "localize",
    "robot_start",
    "room_landmarks",
    "sim_localizer_told",
    "sim_start_sigma",
    "survey_the_room",
    "surveyed_map",
    "survey_to_use",
    "with_stored_survey",
]


@dataclass(frozen=True)
class RoomLandmarks:
    """The landmark map a run localizes against, or why it has none.

    Attributes
    ----------
    mode : LocalizationMode
        The mode the run uses (``odometry`` when it had to fall back).
    landmarks : LandmarkMap or None
        Trained (every landmark with its database); None in ``odometry`` mode.
    note : str or None
        Why the run fell back to odometry alone (for its JSON and log).
    survey_sigma : (float, float) or None [m, rad]
        The stated accuracy of each landmark's pose in ``landmarks`` (position per coordinate, yaw):
        the sensing profile's survey in the simulator; None where the map is taken as exact.
    stored_survey : dict or None
        The room surveyed once that the map's posters come from (:func:`with_stored_survey`), for the
        JSON: the file, its posters, and the tour's stands and sightings.
    """

    mode: LocalizationMode
    landmarks: LandmarkMap | None = field(default=None, repr=False)
    note: str | None = None
    survey_sigma: tuple[float, float] | None = None
    stored_survey: dict | None = None


@dataclass(frozen=True)
class RobotStart:
    """Where a robot's odometry starts in the room W, and how well that is known.

    Attributes
    ----------
    pose : Pose2D
    Sigma0 : ndarray, shape (3, 3) [m^2, rad^2]
        ``diag(sigma_m^2, sigma_m^2, sigma_rad^2)`` from ``[room] start_sigma``.
    source : str
        Where the pose was read (``--start``, the config's ``[room] start``, the scene's start).
    """

    pose: Pose2D
    Sigma0: np.ndarray = field(repr=False)
    source: str = ""


def _room(config: HardwareConfig | None) -> RoomConfig:
    return RoomConfig() if config is None else config.room


def room_landmarks(
    kind: RobotKind,
    config: HardwareConfig | None,
    scene,
    localization,
    progress: bool = False,
    sensing=None,
    seed: int = 0,
) -> RoomLandmarks:
    """The trained landmark map of a run (see the module's table), or the fallback to odometry alone.

    Parameters
    ----------
    kind : RobotKind
    config : HardwareConfig or None
        The robot config (None in the simulator).
    scene : Scene, str or None
        The scene the simulator or the rehearsal renders (None: the real robot's room is only its map).
    localization : {"landmarks", "odometry"} or LocalizationMode
    progress : bool
        Say when a landmark database is built.
    sensing : SensingProfile, str or mapping, optional
        The simulator's profile: with the room's errors, the map is :func:`surveyed_map`'s copy for
        episode ``seed``, and ``survey_sigma`` its stated accuracy.
    seed : int

    Raises
    ------
    ConfigError
        A bad landmark file: one line naming the file and the field
        (:func:`lab.training.landmarks.load_landmark_map`).
    """
    from lab.training.landmarks import load_landmark_map, trained_landmark_map

    mode = LocalizationMode.parse(localization)
    if mode is LocalizationMode.ODOMETRY:
        return RoomLandmarks(mode)
    path = _room(config).landmarks if kind is not RobotKind.SIM else ""
    if path:
        load_landmark_map(path)  # checked (file and field) before anything is trained
        source = path
    elif kind is RobotKind.HARDWARE or scene is None:
        where = "" if config is None or config.path is None else f" in {config.path}"
        return RoomLandmarks(
            LocalizationMode.ODOMETRY,
            note=f"no landmark map for this robot ([room] landmarks{where}): the pose is odometry alone",
        )
    else:
        source = scene
    landmarks = trained_landmark_map(source, progress=progress)
    if len(landmarks) == 0:
        return RoomLandmarks(
            LocalizationMode.ODOMETRY, note=f"{landmarks.source} has no landmarks: the pose is odometry alone"
        )
    if kind is RobotKind.SIM and sensing is not None:
        from lab.sim.sensing import sensing_profile

        profile = sensing_profile(sensing)
        if profile.room.survey_m > 0 or profile.room.survey_deg > 0:
            return RoomLandmarks(
                mode, surveyed_map(landmarks, profile, seed), None, profile.room.survey_sigma
            )
    return RoomLandmarks(mode, landmarks)


def with_stored_survey(room: RoomLandmarks, survey) -> RoomLandmarks:
    """The run's map as a room surveyed once left it (:mod:`lab.localization.stored_survey`): ``survey``
    is the file ``lab survey`` wrote, or a :class:`~lab.localization.stored_survey.StoredSurvey`; None
    leaves ``room`` as it is.

    Raises
    ------
    ConfigError
        A bad or corrupt file, a survey of another map, or a run without a landmark map.
    """
    if survey is None:
        return room
    from lab.localization.stored_survey import StoredSurvey, load_survey

    stored = survey if isinstance(survey, StoredSurvey) else load_survey(survey)
    if room.mode is not LocalizationMode.LANDMARKS or room.landmarks is None:
        why = f" ({room.note})" if room.note else ""
        raise ConfigError(f"a stored survey refines the posters of a landmark map; this run has none{why}")
    tour = (stored.record or {}).get("tour") or {}
    made = {
        "file": str(survey) if not isinstance(survey, StoredSurvey) else f"(given in code: {stored.source})",
        "posters": len(stored.names),
        "stands": len(tour.get("stands", [])),
        "n_sightings": int(tour.get("n_sightings", 0)),
    }
    return replace(room, landmarks=stored.applied_to(room.landmarks), stored_survey=made)


def survey_to_use(given, hw, room: RoomLandmarks):
    """The room surveyed once that a run starts from: ``given`` (``--survey``) when there is one, else the
    robot config's ``[room] survey`` when the run localizes on a landmark map (a run on odometry ignores
    it), else None (the map's own survey)."""
    if given is not None:
        return given
    on_landmarks = room.mode is LocalizationMode.LANDMARKS and room.landmarks is not None
    return hw.room.survey if hw is not None and hw.room.survey and on_landmarks else None


def surveyed_map(landmarks: LandmarkMap, profile, seed: int) -> LandmarkMap:
    """The map a survey of the room gives in episode ``seed``: each landmark's centre and yaw off by
    :func:`lab.sim.room_errors.survey_error` (the profile's survey sigma times its mismatch factor), its
    database unchanged (it is in the landmark's own frame), each stated to be known to the profile's survey
    sigma, so the localizer holds them in its state and refines them (:mod:`lab.localization.posters`).
    The renderer keeps drawing the true posters."""
    from lab.localization import inward_normal
    from lab.sim.room_errors import survey_error

    out = []
    for lm in landmarks:
        dx, dy, dz, dyaw = survey_error(profile.room, profile.mismatch, seed, lm.name)
        c = (lm.centre_W[0] + dx, lm.centre_W[1] + dy, lm.centre_W[2] + dz)
        out.append(
            replace(lm, centre_W=c, yaw=lm.yaw + dyaw, normal_W=inward_normal(c, lm.yaw + dyaw, lm.size))
        )
    surveyed = LandmarkMap(tuple(out), landmarks.room_size, f"{landmarks.source} (surveyed)")
    return surveyed.surveyed(*profile.room.survey_sigma)  # the localizer refines them from that accuracy


def sim_localizer_told(robot) -> dict:
    """What the localizer is told in the simulator, as :class:`~lab.localization.LocalizedRobot`'s keyword
    arguments: the stated start sigma with the first sighting allowed to correct it
    (:func:`sim_start_sigma`), the camera's stated latency (its frames are stamped at arrival), and the
    camera's constants that every sighting shares in the filter's state:

    * with the mounts stated uncertain, the camera's yaw on the base, its prior the camera's stated
      pointing (``LocalizerConfig.camera_yaw_sigma_rad``). The pan zero and the mounts turn every
      sighting by one angle that a standing robot takes into its heading, and the odometry then drives
      along that wrong heading; a state of its own keeps the heading the base's
      (docs/tuning/localizer-camera-yaw.md);
    * with the calibration stated uncertain, the stereo's range scale, its prior the camera's stated
      depth scale (``LocalizerConfig.range_scale_sigma``): the focal lengths' and baseline's errors
      stretch every range alike, which sightings from many places do not average out; held exact, it
      bends the posters' refined shape and the robot's position towards the posters it sees
      (docs/tuning/localizer-range-scale.md);

    and the odometry's stated errors, as its calibration's priors where they are wider than the
    defaults (:func:`odometry_told`). Empty for a profile without the room's errors."""
    Sigma0 = sim_start_sigma(robot)
    told = {} if Sigma0 is None else {"Sigma0": Sigma0, "start_measured_by_hand": True}
    room = getattr(getattr(robot, "sensing", None), "room", None)
    if room is None:
        return told
    if room.latency_s > 0:
        told["camera_latency_s"] = room.latency_s
    config = camera_states_told(robot.camera, room.camera_mount_deg > 0 or room.head_mount_deg > 0)
    config = odometry_told(robot.sensing.odometry, robot.base_limits.wheel_base, config)
    return told if config is None else {**told, "config": config}


def camera_states_told(camera, mounts_uncertain: bool) -> LocalizerConfig | None:
    """The localizer's settings for the camera's constants it estimates (:func:`sim_localizer_told` says
    why): the camera's yaw on the base from its stated pointing when the mounts are uncertain, and the
    stereo's range scale from its stated depth scale; None when it holds both exact."""
    config = {}
    if mounts_uncertain and camera.pointing_std_deg > 0:
        config["camera_yaw_sigma_rad"] = math.radians(camera.pointing_std_deg)
    if camera.depth_scale_std > 0:
        config["range_scale_sigma"] = camera.depth_scale_std
    return LocalizerConfig(**config) if config else None


def odometry_told(odometry, wheel_base: float, config: LocalizerConfig | None) -> LocalizerConfig | None:
    r"""``config`` (None: the defaults) with the odometry calibration's priors widened to cover what the
    profile's stated odometry errors (:class:`lab.sim.sensing.OdometryErrors`) make of the calibrated
    motion model's constants on a base of track ``wheel_base`` [m]; widened only, never narrowed. A
    stated spin slip puts the slip in the state (:func:`lab.localization.models.calibrated_motion_model`).

    * The turn scale ``k``: a turn's measured heading change is ``(1 + e_s)(1 + e_b)`` times the true
      one, with the mean radius error ``e_s`` and the track's ``e_b``; that over-count's RMS about 1 is
      :math:`\sqrt{\sigma_s^2 + \sigma_b^2}` to first order, and ``k``, its inverse, spreads the same.
    * The spin's slip ``sigma``: a spin over-counts by a further ``(1 + slip)``, the slip uniform in
      ``[0, 2 s]``, a drive's turn by the spin's share of that (``OdometryErrors.spin_slip``). Its prior
      is centred on no slip, with the slip's RMS about 0, :math:`2 s / \sqrt{3}`, for its sigma. With
      one ``k`` for both, a spin teaches ``k`` the slip and a drive's turn is then corrected by it too:
      at twice the profile's errors a robot's heading ran 13 deg off on a 1.2 m drive after a 200 deg
      spin (docs/tuning/localizer-spin-slip.md).
    * The curvature ``c``: unequal wheels curve a straight drive by ``e_d / b`` rad/m.
    * The heading noise per metre left once they are estimated: the wheels' random errors give
      :math:`\sqrt{2}\, \sigma_w / b` rad per square-root metre.

    The defaults cover the realistic profile's odometry as stated (its world draws it at the mismatch
    factor, which the localizer is not told); a profile scaled up (``lab eval --error-scale``) states a
    larger error than they do, and a localizer told less than the world draws holds a turn scale it
    cannot move and loses the robot in long spins (docs/tuning/localizer-refind.md, the lost robot).
    None when ``config`` is None and the profile states neither a slip nor errors beyond the defaults."""
    base = config or LocalizerConfig()
    stated = {
        "turn_scale_sigma": math.hypot(odometry.wheel_radius_error, odometry.track_width_error),
        "curvature_sigma_rad_per_m": odometry.wheel_ratio_error / wheel_base,
        "calibrated_heading_rad_per_sqrt_m": math.sqrt(2.0) * odometry.wheel_noise / wheel_base,
        "spin_slip_sigma": 2.0 * odometry.spin_slip / math.sqrt(3.0),
    }
    if not base.odometry_calibration:
        return config
    wider = {k: v for k, v in stated.items() if v > getattr(base, k)}
    if "spin_slip_sigma" in wider and wheel_base != base.track_m:
        wider["track_m"] = wheel_base
    return replace(base, **wider) if wider else config


def sim_start_sigma(robot) -> np.ndarray | None:
    """The start covariance the localizer is told in the simulator: ``diag(s_m^2, s_m^2, s_rad^2)`` from
    the profile's stated start sigma (:attr:`lab.sim.room_errors.RoomErrors.start_sigma`, a real robot's
    ``[room] start_sigma``); None for a profile without the room's errors (or a robot without a profile)."""
    profile = getattr(robot, "sensing", None)
    room = getattr(profile, "room", None)
    if room is None or (room.start_m == 0 and room.start_deg == 0):
        return None
    s_m, s_rad = room.start_sigma
    return np.diag([s_m**2, s_m**2, s_rad**2])


def robot_start(
    config: HardwareConfig | None,
    default,
    start=None,
    room_size: tuple[float, float] | None = None,
) -> RobotStart | None:
    """Where a robot stands in the room when its odometry reads (0, 0, 0): ``start`` (``--start``), else
    the config's ``[room] start``, else ``default`` (the scene's start; None: unknown).

    Parameters
    ----------
    config : HardwareConfig or None
    default : (x_m, y_m, heading_deg) or None
    start : (x_m, y_m, heading_deg), optional
        The ``--start`` flag's value.
    room_size : (float, float) [m], optional
        The room's floor extent, centred on the origin: a start outside it is an error.

    Raises
    ------
    ConfigError
        A start that is not three finite numbers, or one outside the room.
    """
    room = _room(config)
    if start is not None:
        value, source = start, "--start"
    elif len(room.start) == 3:
        value, source = room.start, f"[room] start of {config.path or config.robot.name}"
    elif default is not None:
        value, source = default, "the scene's start"
    else:
        return None
    vals = tuple(value)
    ok = len(vals) == 3 and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in vals)
    if not ok or not all(math.isfinite(float(v)) for v in vals):
        raise ConfigError(f"{source} must be X,Y,YAW_DEG (3 finite numbers [m, m, deg]), got {value!r}")
    x, y, yaw_deg = (float(v) for v in vals)
    if room_size is not None and not (abs(x) < room_size[0] / 2 and abs(y) < room_size[1] / 2):
        raise ConfigError(
            f"{source} ({x:g}, {y:g}) is outside the room: x within +-{room_size[0] / 2:g} m, y within "
            f"+-{room_size[1] / 2:g} m (the room's frame, origin at the floor's centre)"
        )
    s_m, s_deg = (float(v) for v in room.start_sigma)
    Sigma0 = np.diag([s_m**2, s_m**2, math.radians(s_deg) ** 2])
    return RobotStart(Pose2D(x, y, math.radians(yaw_deg)), Sigma0, source)


def check_room(config: HardwareConfig, line) -> None:
    """The bring-up's lines about the room (``lab hardware check``): the landmark map and the start.

    ``[room] landmarks`` is read strictly (a bad file is one FAIL line naming the file and the field),
    and every poster's database is trained into the cache now if it is not there yet, so that the first
    run in front of a class does not stop to train. The start is the one ``lab search`` will assume:
    ``[room] start``, else the search room's ``[robot] start`` (``--start`` overrides both at run time).
    Nothing moves.

    Parameters
    ----------
    config : HardwareConfig
    line : callable (ok: bool, what: str, detail: str, fix: str = "") -> bool
        Prints one PASS/FAIL line (:func:`lab.hardware.cli.check`'s).
    """
    from lab.scene import load_scene
    from lab.training.landmarks import load_landmark_map, trained_landmark_map

    room = config.room
    guide = "hardware/README.md, 'Localize against the room's posters'"
    size = None
    if not room.landmarks:
        line(
            True,
            "landmark map",
            "none ([room] landmarks): lab search and lab identify will localize by odometry alone",
        )
    else:
        try:
            size = load_landmark_map(room.landmarks).room_size
        except LabError as e:
            line(False, "landmark map", str(e), f"edit the landmark file ({guide})")
        else:
            t0 = time.perf_counter()
            trained = trained_landmark_map(room.landmarks, progress=False)
            names = ", ".join(lm.name for lm in trained)
            line(
                True,
                "landmark map",
                f"{room.landmarks}: {len(trained)} posters ({names}), their databases ready "
                f"({time.perf_counter() - t0:.0f} s)",
            )
            if room.survey:
                _check_survey(config, trained, line)
    scene = load_scene("lab_room")
    try:
        s = robot_start(config, scene.robot_start, None, size or scene.room.size)
    except ConfigError as e:
        line(False, "start", str(e), f"measure the start and fix [room] start in {config.path} ({guide})")
        return
    sigma_m, sigma_deg = room.start_sigma
    source = "the search room's [robot] start" if s.source == "the scene's start" else s.source
    line(
        True,
        "start",
        f"lab search assumes ({s.pose.x:g} m, {s.pose.y:g} m, {math.degrees(s.pose.theta):g} deg), from "
        f"{source}, known to {100 * sigma_m:g} cm and {sigma_deg:g} deg ([room] start_sigma): stand the "
        "robot there, or give --start",
    )


def _check_survey(config: HardwareConfig, landmarks: LandmarkMap, line) -> None:
    """The bring-up's line about ``[room] survey`` (``lab hardware check``, beside the landmark map): the
    room surveyed once that every run on the landmarks will start from. A file not made yet, corrupt, or
    made on another map is one FAIL line with what to run, so that the class does not find out when the
    first run stops; a good one says what it holds. Nothing moves."""
    from lab.localization.stored_survey import load_survey

    path = config.room.survey
    redo = f"stand the robot on its mark and run: lab survey --robot {config.path}"
    if not Path(path).is_file():
        line(False, "room survey", f"{path} ([room] survey) is not made yet: every run would stop", redo)
        return
    try:
        stored = load_survey(path)
        stored.applied_to(landmarks)
    except LabError as e:
        line(False, "room survey", str(e), redo)
        return
    tour = (stored.record or {}).get("tour") or {}
    arrived = sum(bool(a) for a in tour.get("arrived", []))
    line(
        True,
        "room survey",
        f"{path}: {len(stored.names)} posters as a tour of {arrived} of {len(tour.get('stands', []))} stands "
        f"placed them ({int(tour.get('n_sightings', 0))} sightings); runs on the landmarks start from it",
    )


def localize(
    robot: Robot, kind: RobotKind, room: RoomLandmarks, start: RobotStart | None, seed: int, log=None
) -> LocalizedRobot:
    """The run's robot placed at ``start`` in the room (a robot's; None: as it is) behind the localizer.

    In the simulator the localizer starts at the robot's odometry, with the profile's stated start sigma
    and the first sighting allowed to correct it when the profile has the room's errors
    (:func:`sim_start_sigma`), else with its default covariance (so too a robot without a start); on a
    robot at ``start`` with ``start.Sigma0``, the first landmark sighting allowed to correct it
    (:meth:`~lab.localization.Localizer.first_sighting`). A robot's localizer estimates its camera's
    yaw and range scale from the camera's stated accuracy (:func:`camera_states_told`; a real head's pan
    zero and brackets are never exact, ``[camera] mount_sigma_deg``), as the simulator's does under the
    room's errors; its frames are stamped at exposure, so it is told no latency.
    """
    rng = np.random.default_rng([seed, 20])
    if kind is RobotKind.SIM:
        told = sim_localizer_told(robot)
        return LocalizedRobot(robot, room.mode, room.landmarks, rng=rng, log=log, **told)
    config = camera_states_told(robot.camera, mounts_uncertain=True)
    if start is None:
        return LocalizedRobot(robot, room.mode, room.landmarks, config, rng=rng, log=log)
    p = start.pose
    s_m, s_rad = math.sqrt(start.Sigma0[0, 0]), math.sqrt(start.Sigma0[2, 2])
    (log or (lambda m: print(f"lab: {m}", file=sys.stderr)))(
        f"localization: the robot starts at ({p.x:.3f}, {p.y:.3f}) m, {math.degrees(p.theta):.1f} deg in the "
        f"room ({start.source}; sigma {s_m:.3f} m, {math.degrees(s_rad):.1f} deg)"
    )
    return LocalizedRobot(
        PlacedRobot(robot, start.pose),
        room.mode,
        room.landmarks,
        config,
        rng=rng,
        log=log,
        Sigma0=start.Sigma0,
        start_measured_by_hand=True,
    )


def localization_in_words(data: dict) -> str:
    """How a run (the JSON fields of ``lab search`` or ``lab identify``) knew where the robot was, in one
    line for the console: odometry alone, or how many landmark updates, what the filter learned of the
    odometry (``odometry_calibration``: ``turn_scale`` is the true turn per reported turn, so the wheels
    over-count turns by ``1 / turn_scale - 1``), what it learned of the camera (``camera_estimate``) and,
    in the simulator, how far the estimate ended from the truth.

    For example ``54 landmark updates; the wheels over-count turns by 4.2 % (turn scale 0.960 +- 0.006)
    and drift 0.012 +- 0.004 rad per metre; 0.7 cm from the true pose at the end`` (with the spin's slip
    in the state, ``..., spins 5.1 +- 1.2 % more, and drift ...``); after a survey tour
    (``survey_tour``) it starts with ``a survey tour of 4 stands first (87 sightings of 12 posters, 208
    s)``; a robot the gate had lost and sightings re-found (``landmark_refinds``) says ``54 landmark
    updates (lost and re-found once)``.
    """
    if data.get("localization_note"):  # a fallback to odometry (no landmark map, none seen) says why
        return str(data["localization_note"])
    if data.get("localization") != "landmarks":
        return "odometry alone (--localization odometry)"
    n = int(data.get("landmark_updates") or 0)
    parts = [f"{n} landmark update{'' if n == 1 else 's'}"]
    lost = int(data.get("landmark_refinds") or 0)  # the estimate reset by sightings that agreed
    if lost:
        parts[0] += f" (lost and re-found {'once' if lost == 1 else f'{lost} times'})"
    tour = data.get("survey_tour")
    if tour:  # the updates count from the search's start; the tour's sightings came before it
        posters = len(set().union(*(set(s) for s in tour["sightings"])))
        parts.insert(
            0,
            f"a survey tour of {len(tour['stands'])} stands first ({tour['n_sightings']} sightings of "
            f"{posters} posters, {tour['sim_time_s']:.0f} s)",
        )
    cal = data.get("odometry_calibration")
    if cal is not None:
        k, sk = cal["turn_scale"], cal["turn_scale_sd"]
        over = 100.0 * (1.0 / k - 1.0)
        verb = f"over-count turns by {over:.1f} %" if over >= 0 else f"under-count turns by {-over:.1f} %"
        spin = ""
        if "spin_slip" in cal:  # the spin's slip in the state: what a turn in place over-counts beyond
            spin = f", spins {100 * cal['spin_slip']:.1f} +- {100 * cal['spin_slip_sd']:.1f} % more,"
        parts.append(
            f"the wheels {verb} (turn scale {k:.3f} +- {sk:.3f}){spin} and drift "
            f"{cal['curvature_rad_per_m']:.3f} +- {cal['curvature_sd_rad_per_m']:.3f} rad per metre"
        )
    cam = data.get("camera_estimate") or {}
    if "yaw_deg" in cam:
        parts.append(
            f"the camera sits {cam['yaw_deg']:+.2f} +- {cam['yaw_sd_deg']:.2f} deg turned on the base"
        )
    if "range_scale" in cam:
        s, sd = 100.0 * cam["range_scale"], 100.0 * cam["range_scale_sd"]
        parts.append(
            f"the stereo's ranges come out {abs(s):.2f} +- {sd:.2f} % {'long' if s >= 0 else 'short'}"
        )
    err = data.get("localization_error_m")
    if err is not None:
        parts.append(f"{100.0 * err:.1f} cm from the true pose at the end")
    return "; ".join(parts)


def survey_the_room(robot: LocalizedRobot, spec, log=None, cover: int = 1) -> dict:
    """Tie the room's posters together before the work starts (:mod:`lab.localization.survey_tour`): look
    round where the robot stands (its first sighting corrects a start measured by hand), scan the floor
    for the navigator, choose the stands on its planning grid, drive the tour and come back to the start
    (so the work starts where it would have). Returns the JSON's record of it: the stands, whether each
    was reached, the sightings at each, whether the robot got back, and the robot's and the wall's time
    it took. ``spec`` is the floor the navigator may drive over (the search's map grid); ``cover`` the
    stands that see each poster well (:func:`~lab.localization.survey_tour.survey_stands`)."""
    from lab.localization.survey_tour import survey_stands, survey_tour
    from lab.navigation.drive_loop import NavOutcome
    from lab.search.navigate import NavigatorAdapter

    wall0, t0 = time.perf_counter(), robot.now()
    robot.enable()
    robot.relocalize()
    drive = NavigatorAdapter(robot, spec)
    drive.navigator.scan()
    drive.scanned = True
    grid = drive.navigator.planning_grid()

    def free(x, y):
        return grid.spec.contains_xy(x, y) and math.isfinite(grid.cost_at(x, y))

    x = robot.localizer.x
    stands = survey_stands(robot.observer.map, free, start_xy=x[:2], config=robot.config, cover=cover)
    (log or robot.log)(f"localization: a survey tour of {len(stands)} stands ties the posters together")
    tour = survey_tour(robot, drive, stands)
    back = drive.navigator.go_to((float(x[0]), float(x[1])), float(x[2])).outcome is NavOutcome.ARRIVED
    robot.stop()
    return {
        "stands": [[round(float(v), 3) for v in xy] for xy in tour.stands],
        "arrived": [bool(a) for a in tour.arrived],
        "sightings": [dict(sorted(s.items())) for s in tour.sightings],
        "n_sightings": tour.n_sightings,
        "returned": back,
        "sim_time_s": round(float(robot.now() - t0), 3),
        "wall_time_s": round(time.perf_counter() - wall0, 3),
    }
