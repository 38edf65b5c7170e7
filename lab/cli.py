"""The ``lab`` command: ``lab --help`` lists the subcommands, ``lab CMD --help`` explains each.

Errors a user can fix (unknown world, bad option value, missing file) print one line naming what is
wrong and what is allowed, and exit with status 2; no traceback.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from lab.errors import LabError
from lab.robot import SIM_CAMERA

__all__ = ["main", "build_parser"]


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
        "--strategy",
        default="paper",
        choices=("paper", "lawnmower", "frontier"),
        help="where to search next (default: paper, the probability map's peak)",
    )
    se.add_argument("--max-time", type=float, default=600.0, help="sim-time budget in seconds (default 600)")
    se.add_argument("--json", type=Path, help="write the result JSON here")
    se.add_argument("--out", type=Path, help="write the figures here")
    se.add_argument(
        "--record",
        type=Path,
        help="write an animation of the run (.gif, or .mp4 with ffmpeg): one frame per event",
    )
    se.add_argument("--robot", type=Path, help="real robot: not supported for the search yet")

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

    nb = sub.add_parser(
        "notebooks",
        help="open the step-by-step notebooks in JupyterLab",
        description="Start JupyterLab in the repository's notebooks/ folder (00 simulator and stereo, "
        "01 pose EKF, 02 entropy planning, 03 grid search, 04 the real robot). Needs the notebooks "
        "extra: pip install -e '.[notebooks]' (`make notebooks` does both).",
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

    g = sub.add_parser(
        "grade",
        help="grade a submission of an assignment (Gradescope results.json)",
        description="Run an assignment's graded tests on a submission, each test in its own limited process, "
        "print a summary and write Gradescope's results.json. With --batch, grade a folder with one "
        "subfolder per student and write one CSV of scores.",
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

    a = sub.add_parser(
        "assignments",
        help="list the assignments or write the student release",
        description="`list`: the assignments with their points. `release OUT_DIR [NAME ...]`: copy each "
        "assignment's student files into OUT_DIR/NAME with the solution blocks stripped and no graded tests, "
        "and check that no solution code is left.",
    )
    a.add_argument("action", choices=("list", "release"))
    a.add_argument("out_dir", type=Path, nargs="?", help="release: the folder to write")
    a.add_argument("names", nargs="*", help="release: these assignments only (default: all)")
    a.add_argument("--force", action="store_true", help="release: replace existing assignment folders")
    a.add_argument(
        "--assignments", type=Path, help="assignments folder (default: $LAB_ASSIGNMENTS or assignments/)"
    )
    a.add_argument("--quiet", action="store_true", help=argparse.SUPPRESS)
    return ap


def _cmd_worlds(args) -> int:
    from lab.scene import list_worlds, load_scene

    for name in list_worlds():
        s = load_scene(name)
        print(f"{name}: {s.description}")
        for b in s.bodies:
            print(f"  {b.name:20s} {b.shape:13s} {b.role}")
        for m in s.models:
            print(f"  {m.name:20s} box model     unique face {m.unique_face}")
    return 0


def _cmd_render(args) -> int:
    import math

    from lab.geometry import Pose2D
    from lab.robot import CameraSpec
    from lab.sim import RenderSettings, SimRobot, SimWorld, load_box_models
    from lab.viz import disparity_picture, save_rgb

    w, h = args.size
    with SimWorld(args.world, RenderSettings(supersample=args.supersample)) as world:
        spec = CameraSpec(w, h, args.fov, SIM_CAMERA.baseline)
        cam = spec.camera(mount_R=(0.0, 0.0, world.scene.robot_mast_height))
        if args.model:
            models = {m.name: m for m in load_box_models()}
            if args.model not in models:
                raise LabError(f"unknown model {args.model!r}; models: {', '.join(models)}")
            world.add_carrier(models[args.model], Pose2D(0, 0, 0), math.radians(args.model_yaw))
        start = None if args.at is None else Pose2D(args.at[0], args.at[1], math.radians(args.at[2]))
        robot = SimRobot(world, cam, start=start)
        pan, tilt = (math.radians(v) for v in args.pan_tilt)
        robot.pan_tilt_limits.check(pan, tilt)
        robot.enable()
        robot.command_pan_tilt(pan, tilt)
        robot.wait_pan_tilt(timeout=10.0)
        frame = robot.capture_stereo()
        args.out.mkdir(parents=True, exist_ok=True)
        save_rgb(args.out / "left.png", frame.left)
        save_rgb(args.out / "right.png", frame.right)
        save_rgb(args.out / "disparity.png", disparity_picture(frame.left, frame.right))
    print(f"wrote {args.out / 'left.png'}, {args.out / 'right.png'}, {args.out / 'disparity.png'}")
    return 0


def _cmd_train(args) -> int:
    import time

    from lab.training.databases import TrainingParams, database_path, get_database, trainable_objects

    names = list(trainable_objects())
    if args.list:
        print("\n".join(names))
        return 0
    unknown = [n for n in args.objects if n not in names]
    if unknown:
        raise LabError(f"unknown object(s) {', '.join(unknown)}; trainable objects: {', '.join(names)}")
    folder = args.cache / "databases" if args.cache else None
    params = TrainingParams(step_deg=args.step_deg)
    for name in args.objects or names:
        t0 = time.perf_counter()
        db = get_database(name, folder, params, rebuild=args.force)
        print(
            f"{name}: {len(db)} features from {db.seen_from.shape[1]} views "
            f"({time.perf_counter() - t0:.1f} s) -> {database_path(name, folder)}"
        )
    return 0


def _cmd_identify(args) -> int:
    import json as _json

    if args.max_actions < 0:
        raise LabError(f"--max-actions must be >= 0, got {args.max_actions}")
    from lab.runs.identify import run_identify

    res = run_identify(
        args.true_model,
        args.seed,
        args.mover,
        args.planner,
        args.max_actions,
        None if args.robot is not None else args.out,
        args.json,
        args.max_time,
        record=args.record,
        keep_direction=args.keep_direction,
        robot_config=args.robot,
        progress=print if args.robot is not None else None,
    )
    keys = ["true_model", "identified_model", "success", "actions", "sim_time_s", "wall_time_s"]
    keys += ["final_posterior", "pose_error"] + (["watchdog_stops"] if args.robot is not None else [])
    summary = {k: res[k] for k in keys}
    print(_json.dumps(summary, indent=2))
    return 0


def _cmd_search(args) -> int:
    import json as _json

    from lab.runs.placement import searchable_objects

    names = searchable_objects()
    if args.list_objects:
        print("\n".join(names))
        return 0
    if args.object not in names:
        raise LabError(f"unknown object {args.object!r}; searchable objects: {', '.join(names)}")
    if args.robot is not None:
        raise LabError("`lab search --robot` is not supported yet: the search runs in the simulator only")
    from lab.io import write_json_atomic
    from lab.runs.search import navigator_factory, run_search

    navigators = []

    def navigate(robot, spec):  # keeps the Navigator for its costmap (the figures)
        nav = navigator_factory(robot, spec)
        navigators.append(nav.navigator)
        return nav

    res = run_search(
        args.object,
        args.seed,
        place=args.place,
        strategy=args.strategy,
        max_time=args.max_time,
        navigate=navigate,
        obstacles=args.obstacles,
        progress=True,
        record=args.record,
    )
    data = res.to_json()
    if args.json is not None:
        write_json_atomic(args.json, data)
    if args.out is not None:
        from lab.viz.search import write_figures

        cm = navigators[0].costmap if navigators else None
        files = write_figures(
            res, args.out, None if cm is None else cm.state, None if cm is None else cm.spec
        )
        write_json_atomic(args.out / "search.json", data)
        print(f"wrote {len(files)} figures and search.json into {args.out}", file=sys.stderr)
    keys = ("object", "found", "position_error_m", "orientation_error_deg", "path_length_m", "sim_time_s")
    print(_json.dumps({k: data.get(k) for k in keys}, indent=2))
    return 0


def _cmd_hardware(args) -> int:
    from lab.hardware import cli as hw

    if args.hw_command == "emulate":
        return hw.emulate(args.dir)
    return hw.check(args.config, emulate=args.emulate)


def _cmd_tables(args) -> int:
    import time

    from lab.training.databases import get_database
    from lab.training.tables import TableParams, box_model_names, get_model_tables, tables_path

    names = box_model_names()
    unknown = [n for n in args.models if n not in names]
    if unknown:
        raise LabError(f"unknown model(s) {', '.join(unknown)}; box models: {', '.join(names)}")
    if args.repeats < 1:
        raise LabError(f"--repeats must be at least 1, got {args.repeats}")
    db_folder = args.cache / "databases" if args.cache else None
    folder = args.cache / "tables" if args.cache else None
    dbs = [get_database(n, db_folder) for n in names]
    params = TableParams(repeats=args.repeats)
    t0 = time.perf_counter()
    for n in args.models or names:  # one file per true model, built only when missing or stale
        t1 = time.perf_counter()
        t = get_model_tables(n, dbs, folder, params, rebuild=args.force)
        V = len(t.viewpoints)
        print(
            f"{n}: {len(t.names)} tables x {V} training poses against {', '.join(t.names)} "
            f"({time.perf_counter() - t1:.1f} s) -> {tables_path(n, folder)}"
        )
    print(f"done in {time.perf_counter() - t0:.1f} s")
    return 0


def _cmd_notebooks(args) -> int:
    import importlib.util
    import os
    import subprocess

    from lab.paths import repo_root

    folder = repo_root() / "notebooks"
    notebooks = sorted(folder.glob("*.ipynb"))
    if not notebooks:
        raise LabError(f"no notebooks in {folder}: `lab notebooks` needs a checkout of the repository")
    if args.list:
        for p in notebooks:
            print(p.name)
        return 0
    if importlib.util.find_spec("jupyterlab") is None:
        raise LabError("JupyterLab is not installed: pip install -e '.[notebooks]' (or run `make notebooks`)")
    env = dict(os.environ, **({"LAB_FAST": "1"} if args.fast else {}))
    cmd = [sys.executable, "-m", "jupyterlab", *(["--no-browser"] if args.no_browser else [])]
    return subprocess.call(cmd, cwd=folder, env=env)


def _cmd_demo(args) -> int:
    from lab.runs.demo import run_demo

    if args.max_actions < 0:
        raise LabError(f"--max-actions must be >= 0, got {args.max_actions}")
    if not args.max_time > 0:
        raise LabError(f"--max-time must be > 0 s, got {args.max_time}")
    report = run_demo(
        args.out,
        seed=args.seed,
        true_model=args.true_model,
        planner=args.planner,
        mover=args.mover,
        max_actions=args.max_actions,
        max_time_s=args.max_time,
        record=args.record,
        robot=args.robot,
    )
    print(f"demo: figures, identify.json and the report are in {report.parent}/ (open {report})")
    return 0


def _cmd_grade(args) -> int:
    from lab.grading.cli import run_grade

    return run_grade(args)


def _cmd_assignments(args) -> int:
    from lab.grading.cli import run_assignments

    if args.action == "release" and args.out_dir is None:
        raise LabError(
            "`lab assignments release` needs OUT_DIR, the folder to write the student release into"
        )
    return run_assignments(args)


def _one_blas_thread() -> None:
    """Keep OpenBLAS to one thread unless the user chose otherwise (``OPENBLAS_NUM_THREADS``).

    The loops' matrix products are small (a frame's ~200 descriptors against a database of ~700), and
    OpenBLAS's worker threads spin while they wait for work: measured on a 2-core machine, a ``lab
    identify`` episode took 33.6 s of CPU with the default threads and 18.6 s with one, for the same
    wall time and the same result. It only takes effect before numpy is first imported, which is why
    it is set here, at the command's entry, and not in the library.
    """
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def main(argv: list[str] | None = None) -> int:
    _one_blas_thread()
    ap = build_parser()
    args = ap.parse_args(argv)
    if args.command is None:
        ap.print_help()
        return 0
    handlers = {
        "assignments": _cmd_assignments,
        "demo": _cmd_demo,
        "grade": _cmd_grade,
        "hardware": _cmd_hardware,
        "identify": _cmd_identify,
        "notebooks": _cmd_notebooks,
        "render": _cmd_render,
        "search": _cmd_search,
        "tables": _cmd_tables,
        "train": _cmd_train,
        "worlds": _cmd_worlds,
    }
    try:
        return handlers[args.command](args)
    except LabError as e:
        print(f"lab {args.command}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"lab {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
