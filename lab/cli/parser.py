"""The ``lab`` command's arguments: one subparser per command, with its help."""

from __future__ import annotations

import argparse
from pathlib import Path

from lab.cli.eval_parser import add_eval_parser, executor_arguments

__all__ = ["build_parser"]

HELP_LEVEL = (
    "level the camera on the floor (14 views looking down; lab/navigation/level.py) before the search; "
    "default: in the simulator when the profile states a mount error (realistic), without --mounts"
)
HELP_VIEW3D = (
    "write a recorded 3D view of the run: one self-contained HTML page with a time slider, opens offline "
    "in any browser (needs the optional package viser: pip install 'lab[view3d]')"
)


def _sensing(value: str) -> str:
    """``--sensing``'s value: a profile name or a ``.toml`` file (read and checked by the command)."""
    if value in ("realistic", "ideal", "sensors", "room") or value.endswith(".toml"):
        return value
    raise argparse.ArgumentTypeError(
        f"unknown sensing profile {value!r}; allowed: realistic, ideal, sensors, room (realistic's "
        "former name), or a .toml file with a [sensing] table"
    )


def _sensing_argument(p: argparse.ArgumentParser) -> None:
    """``--sensing``: the simulator's sensing profile (``lab/sim/sensing.py``)."""
    p.add_argument(
        "--sensing",
        default="realistic",
        type=_sensing,
        metavar="{realistic,ideal,sensors,FILE.toml}",
        help="the simulator's sensor errors (default: realistic: camera noise, calibration error, odometry "
        "drift, pan-tilt backlash, in a real room: a surveyed map, the operator's start, mount errors, "
        "camera latency, slip on a bump, errors 1.5 x what the robot is told; sensors: realistic's sensors "
        "in an exact room; ideal: exact sensors, for teaching the mathematics; room: realistic's former "
        "name; FILE.toml: a "
        '[sensing] table, profile = "realistic" plus [sensing.camera], [sensing.odometry], '
        "[sensing.pan_tilt], [sensing.room] fields to change); with --robot on a rehearsal config, its "
        "rendered camera follows the camera section (odometry and pan-tilt are the emulators')",
    )


def _localization_argument(p: argparse.ArgumentParser, default: str = "landmarks", why: str = "") -> None:
    """``--localization``: where the robot's pose comes from (``lab/localization/``)."""
    p.add_argument(
        "--localization",
        choices=("landmarks", "odometry"),
        default=default,
        help="where the robot's pose comes from: odometry corrected by the walls' posters seen in stereo "
        f"(landmarks), or wheel odometry alone (odometry, as in the papers); default {default}{why}",
    )


def _start_argument(p: argparse.ArgumentParser) -> None:
    """``--start``: where a robot stands in the room when it starts (``lab/runs/room.py``)."""
    p.add_argument(
        "--start",
        type=lambda s: _floats(s, 3, "--start"),
        metavar="X,Y,YAW_DEG",
        help="with --robot: where the robot stands in the room's frame when it starts, as measured (its "
        "odometry starts there; default: the config's [room] start, else the scene's start); the localizer "
        "starts there with the config's [room] start_sigma, and the first poster it sees can correct it",
    )


def _episode_arguments(p: argparse.ArgumentParser, movers: tuple[str, ...], max_time: float) -> None:
    """The arguments of one identification episode, shared by ``lab demo`` and ``lab identify``."""
    p.add_argument(
        "--true-model", type=int, default=1, help="index of the box on the carrier, 0..3 (default 1)"
    )
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument(
        "--mover",
        default="evasive",
        choices=movers,
        help="how the box moves (default: evasive, the paper's operator)",
    )
    p.add_argument(
        "--planner",
        default="lut",
        choices=("lut", "mc", "random", "circle"),
        help="how the next view is chosen (default: lut)",
    )
    p.add_argument("--max-actions", type=int, default=8, help="planning actions budget (default 8)")
    p.add_argument(
        "--max-time", type=float, default=max_time, help=f"time budget in seconds (default {max_time:g})"
    )
    p.add_argument("--record", type=Path, help="write an animation of the run (.gif, or .mp4 with ffmpeg)")
    p.add_argument("--view3d", type=Path, metavar="FILE.html", help=HELP_VIEW3D)
    _sensing_argument(p)
    p.add_argument(
        "--robot",
        type=Path,
        help="run on a real robot: its hardware TOML config (hardware/robot.toml); hardware/rehearsal.toml "
        "rehearses on device emulators with simulator-rendered frames (--true-model, --mover set its scene)",
    )


def _floats(text: str, n: int, what: str) -> list[float]:
    try:
        vals = [float(v) for v in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{what} must be {n} comma-separated numbers, got {text!r}"
        ) from None
    if len(vals) != n:
        raise argparse.ArgumentTypeError(f"{what} must be {n} comma-separated numbers, got {text!r}")
    return vals


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--size must look like 320x240, got {text!r}") from None
    if not (16 <= w <= 4096 and 16 <= h <= 4096):
        raise argparse.ArgumentTypeError(f"--size must be within 16x16 .. 4096x4096, got {text!r}")
    return w, h


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line (what is wrong, and where help is), exit status 2."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see `{self.prog} --help`)\n")


def build_parser() -> argparse.ArgumentParser:
    ap = _Parser(
        prog="lab",
        description="Active stereo perception on a mobile robot: model identification with next-best-view "
        "planning, and object search with a probability map, in PyBullet and on a real robot.",
    )
    sub = ap.add_subparsers(dest="command", metavar="COMMAND")

    d = sub.add_parser(
        "demo",
        help="run the identification demo in the simulator and write its figures and report",
        description="Run one identification episode headless in the simulator (the identification "
        "paper): a second robot turns the box to hide its unique face (evasive mover) while the robot "
        "tracks it with the pan-tilt head and drives to the next-best view from the lookup tables. Writes "
        "the paper's Fig. 5-7, identify.json and report.md into --out. The first run builds the lookup "
        "tables (several minutes, once).",
    )
    d.add_argument("--out", type=Path, default=Path("out/demo"), help="output folder (default: out/demo)")
    _episode_arguments(d, movers=("static", "scripted", "random", "evasive"), max_time=150.0)

    r = sub.add_parser(
        "render",
        help="render a stereo pair and its disparity from a viewpoint",
        description="Render the left and right images of the robot's stereo camera and a "
        "disparity picture (StereoSGBM) for a world and a viewpoint; writes left.png, "
        "right.png and disparity.png into --out.",
    )
    r.add_argument("--world", default="lab_room", help="world name (see `lab worlds`; default: lab_room)")
    r.add_argument(
        "--at",
        type=lambda s: _floats(s, 3, "--at"),
        metavar="X,Y,HEADING_DEG",
        help="robot pose in the world (default: the scene's start)",
    )
    r.add_argument(
        "--pan-tilt",
        type=lambda s: _floats(s, 2, "--pan-tilt"),
        default=[0.0, 0.0],
        metavar="PAN_DEG,TILT_DEG",
        help="pan-tilt angles in degrees (default: 0,0)",
    )
    r.add_argument("--model", help="put this box model (M0..M3) on a carrier at the origin")
    r.add_argument(
        "--model-yaw",
        type=float,
        default=180.0,
        help="yaw of the carried box in degrees (default 180: unique face towards -x)",
    )
    from lab.robot import SIM_CAMERA  # here, not at import: numpy after the BLAS setting

    cam = SIM_CAMERA
    r.add_argument(
        "--size",
        type=_size,
        default=(cam.width, cam.height),
        metavar="WxH",
        help=f"image size (default {cam.width}x{cam.height})",
    )
    r.add_argument(
        "--fov",
        type=float,
        default=cam.fov_y_deg,
        help=f"vertical field of view in degrees (default {cam.fov_y_deg:g})",
    )
    r.add_argument("--supersample", type=int, default=1, choices=(1, 2), help="render at 2x and downsample")
    r.add_argument("--out", type=Path, default=Path("out/render"), help="output folder (default: out/render)")

    t = sub.add_parser(
        "train",
        help="build the feature databases and colour models (cached)",
        description="Render each object from its training ring, extract 3D SIFT features and colour "
        "histograms, and store them in the cache (reused while textures and parameters are unchanged).",
    )
    t.add_argument("objects", nargs="*", help="object names (default: all; see `lab train --list`)")
    t.add_argument("--list", action="store_true", help="list the trainable objects and exit")
    t.add_argument("--cache", type=Path, help="cache folder (default: $LAB_CACHE or ~/.cache/lab)")
    t.add_argument("--force", action="store_true", help="rebuild even when the cache is current")
    t.add_argument("--step-deg", type=float, default=10.0, help="angle between ring viewpoints (default 10)")

    idf = sub.add_parser(
        "identify",
        help="identify which box model the robot faces (next-best-view planning)",
        description="Run the identification loop of the identification paper: the robot perceives every "
        "frame, updates one pose EKF per model and the model probabilities, and drives to the view with the "
        "highest expected information gain until one model's probability stays >= 0.95. Writes the JSON "
        "(--json) and the paper's figures (--out).",
    )
    _episode_arguments(idf, movers=("static", "scripted", "random", "evasive", "teleop"), max_time=240.0)
    idf.add_argument("--json", type=Path, help="write the result JSON here")
    idf.add_argument("--out", type=Path, help="write the figures (Fig. 5, 6, 7) and identify.json here")
    _localization_argument(
        idf,
        "odometry",
        ": in the arena's short episodes a single update from a far poster has left the pose up to "
        "11 cm farther from the truth than the odometry (issue #20)",
    )
    _start_argument(idf)
    idf.add_argument(
        "--keep-direction",
        type=float,
        metavar="RATIO",
        help="keep driving the same way round the object when the best goal that way has at least RATIO "
        "of the best information gain (default 0.5; 1 = always the best gain, Eq. (6))",
    )

    se = sub.add_parser(
        "search",
        help="search the lab room for a named object (probability map, colour and SIFT search)",
        description="Run the search paper's loop: a colour-histogram global search seeds a grid probability "
        "map, the robot drives (stereo costmap + A*) to the most probable cells and runs the SIFT + EKF "
        "local search there, until the object is found (with its 6D pose) or the time budget is spent.",
    )
    se.add_argument("--object", help="object to find (see --list-objects)")
    se.add_argument("--list-objects", action="store_true", help="print the searchable objects and exit")
    se.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    se.add_argument(
        "--place",
        type=lambda s: _floats(s, 4, "--place"),
        metavar="X,Y,Z,YAW_DEG",
        help="where to put the object (Z: the surface it stands on); default: seeded random",
    )
    se.add_argument("--obstacles", action="store_true", help="drop obstacles on the straight path")
    se.add_argument(
        "--moving",
        choices=("random", "evasive"),
        help="the object moves on a carrier over the floor or a table's top (simulator only): random, a "
        "random walk in free space; evasive, it leaves the camera's view when seen. The search then "
        "predicts its map between updates (default: the stationary object of the paper)",
    )
    se.add_argument(
        "--surface",
        choices=("floor", "table"),
        help="with --moving and no --place: the surface of the seeded placement, the floor (default) or a "
        "table's top, where the carrier then drives",
    )
    se.add_argument(
        "--object-speed", type=float, default=0.1, help="with --moving: its speed [m/s] (default 0.1)"
    )
    se.add_argument(
        "--pause", type=float, default=5.0, help="with --moving: its pause after each leg [s] (default 5)"
    )
    se.add_argument(
        "--static-map",
        action="store_true",
        help="with --moving: the baseline, a search whose map does not predict the motion",
    )
    se.add_argument(
        "--strategy",
        default="paper",
        choices=("paper", "rate", "lawnmower", "frontier"),
        help="where to search next (default: paper, the probability map's peak; rate: the peak with the most "
        "probability per second of driving there and looking; lawnmower, frontier: baselines)",
    )
    se.add_argument(
        "--max-time",
        type=float,
        default=600.0,
        help="time budget in seconds: simulated time, or wall time on a robot (default 600)",
    )
    se.add_argument("--json", type=Path, help="write the result JSON here")
    se.add_argument("--out", type=Path, help="write the figures here")
    se.add_argument(
        "--record",
        type=Path,
        help="write an animation of the run (.gif, or .mp4 with ffmpeg): one frame per event",
    )
    se.add_argument("--view3d", type=Path, metavar="FILE.html", help=HELP_VIEW3D + "; one step per event")
    se.add_argument(
        "--robot",
        type=Path,
        help="run on a robot: its hardware TOML config (hardware/robot.toml: the real robot, stood at the "
        "room's start; hardware/rehearsal.toml: the device emulators with the room rendered from their "
        "state, the object placed by --place or the seed); --max-time is then wall time",
    )
    se.add_argument(
        "--mounts",
        type=Path,
        metavar="FILE.toml",
        help="a mount calibration (lab hardware calibrate): the robot's camera frame includes it (a robot "
        "config's [camera] mounts is used without it)",
    )
    se.add_argument("--level", action=argparse.BooleanOptionalAction, help=HELP_LEVEL)
    se.add_argument(
        "--survey-tour",
        action="store_true",
        help="before the search, drive a survey tour: stand at a few places, each in view of several "
        "posters, and look at every poster in view, so that a surveyed map's posters are tied together "
        "(outside the time budget; the JSON's survey_tour)",
    )
    se.add_argument(
        "--survey",
        type=Path,
        metavar="FILE.json",
        help="a room surveyed once (lab survey --out FILE.json): start from its refined posters instead of "
        "the map's survey (default: the robot config's [room] survey, if any)",
    )
    se.add_argument(
        "--truth",
        type=lambda s: _floats(s, 4, "--truth"),
        metavar="X,Y,Z,YAW_DEG",
        help="the real robot: the object's measured pose in the room (as --place) to score the run against; "
        "without it the scoring fields are null",
    )
    _sensing_argument(se)
    _localization_argument(se)
    _start_argument(se)

    sv = sub.add_parser(
        "survey",
        help="survey the room once: tie the map's posters together and keep them for later searches",
        description="Drive a survey tour (stand at a few places, each in view of several posters, and look "
        "at every poster in view) and write the posters as the tour refined them, with their joint "
        "covariance, to a file that `lab search --survey FILE` starts from. A map measured with a tape is "
        "off by 1-2 cm per poster; after the tour the posters' shape is known to millimetres.",
    )
    sv.add_argument(
        "--out",
        type=Path,
        metavar="FILE.json",
        help="where to write the survey (default: the robot config's [room] survey, which later runs on that "
        "config start from)",
    )
    sv.add_argument(
        "--seed", type=int, default=0, help="in the simulator: the episode whose room is surveyed (default 0)"
    )
    sv.add_argument("--json", type=Path, help="write what the tour did here")
    sv.add_argument(
        "--robot", type=Path, help="survey with a robot: its hardware TOML config (as lab search --robot)"
    )
    sv.add_argument("--level", action=argparse.BooleanOptionalAction, help=HELP_LEVEL)
    _sensing_argument(sv)
    _start_argument(sv)

    hw = sub.add_parser(
        "hardware",
        help="the real robot: emulators and bring-up checks",
        description="Run device emulators (to rehearse without the robot) or check a robot's bring-up.",
    )
    hws = hw.add_subparsers(dest="hw_command", metavar="HW_COMMAND", required=True)
    he = hws.add_parser(
        "emulate",
        help="run PTU-D46 and Create 2 emulators on ptys until Ctrl-C",
        description="Start the PTU-D46 and Create 2 emulators and print their ports.",
    )
    he.add_argument(
        "--dir",
        default="/tmp/lab-emulators",
        help="folder for the port symlinks (default /tmp/lab-emulators, as hardware/emulated.toml)",
    )
    hc = hws.add_parser(
        "check",
        help="bring-up diagnostics: one PASS/FAIL line per check, with the fix",
        description="Check config, calibration, ports, the PTU, the base's stream and "
        "odometry, and one stereo frame. Never moves the robot.",
    )
    hc.add_argument("--config", required=True, type=Path, help="hardware TOML file, e.g. hardware/robot.toml")
    hc.add_argument("--emulate", action="store_true", help="start the emulators on the config's ports first")
    hk = hws.add_parser(
        "calibrate",
        help="estimate the camera's mounts and the tilt's zero from posters seen by the standing robot",
        description="Turn the head over a pan/tilt pattern, fit the landmark map's posters, solve for the "
        "head's roll and pitch, the tilt's zero and the camera's roll and yaw (least squares), print them "
        "with their deviations and write the calibration file (lab/runs/calibrate.py). Never drives.",
    )
    hk.add_argument("--config", type=Path, help="the robot's hardware TOML (default: the simulator)")
    hk.add_argument("--out", type=Path, help="the calibration file (default: the config's [camera] mounts)")
    hk.add_argument("--seed", type=int, default=0, help="the simulator's episode (its drawn mounts)")
    hk.add_argument(
        "--start",
        type=lambda s: _floats(s, 3, "--start"),
        metavar="X,Y,YAW_DEG",
        help="where the robot stands (the simulator places it there; default: [room] start, else the "
        "scene's start); a spot that sees many posters within a few metres calibrates best",
    )
    _sensing_argument(hk)

    nb = sub.add_parser(
        "notebooks",
        help="open the step-by-step notebooks in JupyterLab",
        description="Start JupyterLab in the repository's notebooks/ folder (00 simulator and stereo, "
        "01 pose EKF, 02 entropy planning, 03 grid search, 04 the real robot, 05 localization). Needs "
        "the notebooks extra: pip install -e '.[notebooks]' (`make notebooks` does both).",
    )
    nb.add_argument("--list", action="store_true", help="list the notebooks and exit")
    nb.add_argument("--fast", action="store_true", help="fast mode (LAB_FAST=1: small budgets, as in CI)")
    nb.add_argument("--no-browser", action="store_true", help="do not open a browser (print the URL)")

    tb = sub.add_parser(
        "tables",
        help="build the lookup tables of the identification planner (cached)",
        description="Render each box model around its training ring, match every render against every "
        "model's feature database, and store the probability lookup tables (the identification paper's "
        "Table I) in the cache (reused while the databases and parameters are unchanged).",
    )
    tb.add_argument("models", nargs="*", help="true models to build (default: all box models)")
    tb.add_argument("--cache", type=Path, help="cache folder (default: $LAB_CACHE or ~/.cache/lab)")
    tb.add_argument("--force", action="store_true", help="rebuild even when the cache is current")
    tb.add_argument("--repeats", type=int, default=8, help="renders per model and training pose (default 8)")

    sub.add_parser(
        "worlds",
        help="list the worlds and their bodies",
        description="List the scene files in worlds/ with their named bodies.",
    )

    ck = sub.add_parser(
        "check",
        help="students: run an assignment's public tests on your folder before submitting",
        description="Run the public tests of ASSIGNMENT (the test_*.py you received) on the module in "
        "FOLDER, on any OS, without the grader's sandbox or the graded tests: your grade may differ.",
    )
    ck.add_argument("assignment", help="assignment name (see `lab assignments list`), e.g. ekf")
    ck.add_argument("folder", type=Path, help="the folder holding your module (e.g. ekf.py), or the file")
    ck.add_argument(
        "--assignments", type=Path, help="assignments folder (default: $LAB_ASSIGNMENTS or assignments/)"
    )

    g = sub.add_parser(
        "grade",
        help="grade a submission of an assignment (Gradescope results.json)",
        description="Run an assignment's graded tests on a submission, each test in its own limited process, "
        "print a summary and write Gradescope's results.json. With --batch, grade a folder with one "
        "subfolder per student and write one CSV of scores; with --workers N or --scheduler ADDRESS (a Dask "
        "cluster), grade that class one submission per job, in parallel (--batch implied).",
    )
    g.add_argument(
        "assignment",
        nargs="?",
        help="assignment name (see `lab assignments list`); with --batch also a,b or all",
    )
    g.add_argument(
        "submission",
        nargs="?",
        type=Path,
        help="folder holding the module (or the module file); with --batch, a folder of student folders",
    )
    g.add_argument("--json", type=Path, help="write Gradescope's results.json here")
    g.add_argument("--batch", action="store_true", help="SUBMISSION holds one subfolder per student")
    g.add_argument("--csv", type=Path, help="with --batch: the scores CSV (default SUBMISSION/scores.csv)")
    g.add_argument("--out", type=Path, help="with --batch: write OUT/STUDENT/ASSIGNMENT.json for each")
    g.add_argument("--jobs", type=int, default=None, help="tests run at once (default: min(4, CPUs))")
    executor_arguments(g)  # --workers/--scheduler: a class (--batch implied), one submission per job
    g.add_argument(
        "--timeout-scale", type=float, default=1.0, help="multiply every time limit (slow machine)"
    )
    g.add_argument(
        "--assignments", type=Path, help="assignments folder (default: $LAB_ASSIGNMENTS or assignments/)"
    )
    g.add_argument("--quiet", action="store_true", help="print nothing")
    g.add_argument(
        "--check-sandbox",
        action="store_true",
        help="check that the sandbox isolating students' code works here (exit 0) and stop",
    )
    g.add_argument(
        "--insecure",
        action="store_true",
        help="grade even without a working sandbox (practice only: every result says so)",
    )

    add_eval_parser(sub)

    a = sub.add_parser(
        "assignments",
        help="list the assignments, write the student release or a Gradescope autograder zip",
        description="`list`: the assignments with their points. `release OUT_DIR [NAME ...]`: copy each "
        "assignment's student files into OUT_DIR/NAME with the solution blocks stripped and no graded tests, "
        "and check that no solution code is left. `gradescope NAME --out autograder.zip`: the autograder "
        "bundle Gradescope builds its image from (setup.sh, run_autograder, the package, the versions of "
        "uv.lock, the template in place of the reference solution; see assignments/README.md).",
    )
    a.add_argument("action", choices=("list", "release", "gradescope"))
    a.add_argument(
        "out_dir", type=Path, nargs="?", help="release: the folder to write; gradescope: the assignment"
    )
    a.add_argument("--out", type=Path, help="gradescope: the zip to write (default autograder.zip)")
    a.add_argument("names", nargs="*", help="release: these assignments only (default: all)")
    a.add_argument("--force", action="store_true", help="release: replace existing assignment folders")
    a.add_argument(
        "--assignments", type=Path, help="assignments folder (default: $LAB_ASSIGNMENTS or assignments/)"
    )
    a.add_argument("--quiet", action="store_true", help=argparse.SUPPRESS)
    return ap
