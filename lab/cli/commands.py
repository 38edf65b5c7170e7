"""What each ``lab`` command does: it checks its arguments and calls a run (:mod:`lab.runs`), the
training (:mod:`lab.training`), the hardware's bring-up or the grader; imports happen inside each, so
that ``lab --help`` starts fast and numpy is imported after the BLAS setting."""

from __future__ import annotations

import sys

from lab.errors import LabError

__all__ = ["HANDLERS"]


def _sensing(args):
    """The ``--sensing`` profile, read and checked before anything starts (a file's errors name it)."""
    from lab.sim.sensing import sensing_profile

    return sensing_profile(args.sensing)


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
    from lab.robot import SIM_CAMERA, CameraSpec
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
        view3d=args.view3d,
        keep_direction=args.keep_direction,
        robot_config=args.robot,
        progress=print if args.robot is not None else None,
        sensing=_sensing(args),
        localization=args.localization,
        start=args.start,
    )
    if args.view3d is not None:
        print(f"lab identify: wrote the 3D view to {args.view3d} (open it in a browser)", file=sys.stderr)
    keys = ["true_model", "identified_model", "success", "actions", "sim_time_s", "wall_time_s"]
    keys += [
        "final_posterior",
        "pose_error",
        "pose_estimate",
        "sensing",
        "localization",
        "odometry_error_m",
        "localization_error_m",
    ] + (["watchdog_stops"] if args.robot is not None else [])
    from lab.runs.room import localization_in_words

    summary = {k: res[k] for k in keys}
    summary["localization_outcome"] = localization_in_words(res)  # landmarks, the odometry learned, in words
    print(_json.dumps(summary, indent=2))
    if res["reason"] == "interrupted":
        said = f": the result so far is in {args.json}" if args.json is not None else ""
        print(f"lab identify: interrupted, motors stopped{said}", file=sys.stderr)
        return 130
    return 0


def _moving(args):
    """``lab search``'s moving object (--moving, --object-speed, --pause, --static-map, --surface), or
    None."""
    if args.moving is None:
        if args.static_map:
            raise LabError("--static-map is the baseline for a moving object: give --moving too")
        if args.surface is not None:
            raise LabError("--surface is where a moving object's carrier drives: give --moving too")
        return None
    if args.surface is not None and args.place is not None:
        raise LabError("--surface draws a seeded placement on that surface; --place puts the object itself")
    from lab.runs.moving import MovingOptions

    surface = args.surface or "floor"
    return MovingOptions(
        args.moving, args.object_speed, args.pause, predict=not args.static_map, surface=surface
    )


def _cmd_search(args) -> int:
    import json as _json

    from lab.runs.placement import searchable_objects

    names = searchable_objects()
    if args.list_objects:
        print("\n".join(names))
        return 0
    if args.object not in names:
        raise LabError(f"unknown object {args.object!r}; searchable objects: {', '.join(names)}")
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
        view3d=args.view3d,
        sensing=_sensing(args),
        localization=args.localization,
        robot_config=args.robot,
        truth=args.truth,
        start=args.start,
        moving=_moving(args),
        mounts=args.mounts,
        level=args.level,
        survey_tour=args.survey_tour,
        survey=args.survey,
    )
    data = res.to_json()
    if args.view3d is not None:
        print(f"lab search: wrote the 3D view to {args.view3d} (open it in a browser)", file=sys.stderr)
    if args.json is not None:
        write_json_atomic(args.json, data)
    if args.out is not None:
        write_json_atomic(args.out / "search.json", data)
        if args.robot is None:
            from lab.viz.search import write_figures

            cm = navigators[0].costmap if navigators else None
            files = write_figures(
                res, args.out, None if cm is None else cm.state, None if cm is None else cm.spec
            )
            print(f"wrote {len(files)} figures and search.json into {args.out}", file=sys.stderr)
        else:
            print(f"wrote search.json into {args.out} (the figures are the simulator's)", file=sys.stderr)
    from lab.runs.room import localization_in_words
    from lab.runs.search import outcome_in_words

    keys = ("object", "found", "success", "reason", "position_error_m", "orientation_error_deg")
    summary = {k: data.get(k) for k in (*keys, "path_length_m", "sim_time_s")}
    summary["pose_std"] = data.get("pose_std")  # what the robot says of its pose, without a truth
    summary["outcome"] = outcome_in_words(data)  # found / success / why, in words
    summary["localization_outcome"] = localization_in_words(data)
    print(_json.dumps(summary, indent=2))
    if res.interrupted:
        where = args.json or (None if args.out is None else args.out / "search.json")
        said = f": the result so far is in {where}" if where is not None else ""
        print(f"lab search: interrupted, motors stopped{said}", file=sys.stderr)
        return 130
    return 0


def _cmd_survey(args) -> int:
    import json as _json

    from lab.io import write_json_atomic
    from lab.runs.survey import run_survey

    data = run_survey(
        args.out,
        args.seed,
        sensing=_sensing(args),
        robot_config=args.robot,
        start=args.start,
        level=args.level,
        progress=True,
    )
    if args.json is not None:
        write_json_atomic(args.json, data)
    tour = data["tour"]
    after = [p["sigma_after"][0] for p in data["posters"].values()]
    print(
        f"lab survey: {sum(tour['arrived'])} of {len(tour['stands'])} stands, "
        f"{tour['n_sightings']} sightings; "
        f"the posters now stated to {min(after):.1f}-{max(after):.1f} cm; wrote {data['survey']}",
        file=sys.stderr,
    )
    print(_json.dumps({k: data[k] for k in ("survey", "posters")}, indent=2))
    return 0


def _cmd_hardware(args) -> int:
    from lab.hardware import cli as hw
    from lab.runs.room import check_room

    if args.hw_command == "emulate":
        return hw.emulate(args.dir)
    if args.hw_command == "calibrate":
        from lab.runs.calibrate import main_calibrate

        return main_calibrate(args)
    return hw.check(args.config, emulate=args.emulate, room_check=check_room)


def _cmd_tables(args) -> int:
    import time

    from lab.training.databases import get_databases
    from lab.training.tables import TableParams, box_model_names, get_model_tables, tables_path

    names = box_model_names()
    unknown = [n for n in args.models if n not in names]
    if unknown:
        raise LabError(f"unknown model(s) {', '.join(unknown)}; box models: {', '.join(names)}")
    if args.repeats < 1:
        raise LabError(f"--repeats must be at least 1, got {args.repeats}")
    db_folder = args.cache / "databases" if args.cache else None
    folder = args.cache / "tables" if args.cache else None
    dbs = get_databases(names, db_folder)
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
        view3d=args.view3d,
        robot=args.robot,
        sensing=_sensing(args),
    )
    print(f"demo: figures, identify.json and the report are in {report.parent}/ (open {report})")
    return 0


def _cmd_grade(args) -> int:
    from lab.grading.cli import run_grade

    if args.workers is None and args.scheduler is None:
        return run_grade(args)
    # a class through the executor of `lab eval`: one job per student and assignment
    args.batch = True

    def batch(chosen, folder, args):
        from lab.eval.executor import make_executor
        from lab.eval.grade import grade_class

        ex = make_executor(args.workers, args.scheduler, 0, args.job_timeout)
        try:
            return grade_class(args, chosen, folder, ex)
        finally:
            ex.close()

    return run_grade(args, batch=batch)


def _cmd_check(args) -> int:
    from lab.grading.assignments import get_assignment
    from lab.grading.selfcheck import self_check

    return self_check(get_assignment(args.assignment, args.assignments), args.folder)


def _cmd_eval(args) -> int:
    from lab.eval.cli import run_eval

    return run_eval(args)


def _cmd_assignments(args) -> int:
    from lab.grading.cli import run_assignments

    if args.action == "release" and args.out_dir is None:
        raise LabError(
            "`lab assignments release` needs OUT_DIR, the folder to write the student release into"
        )
    return run_assignments(args)


#: The function of each command.
HANDLERS = {
    "assignments": _cmd_assignments,
    "check": _cmd_check,
    "demo": _cmd_demo,
    "eval": _cmd_eval,
    "grade": _cmd_grade,
    "hardware": _cmd_hardware,
    "identify": _cmd_identify,
    "notebooks": _cmd_notebooks,
    "render": _cmd_render,
    "search": _cmd_search,
    "survey": _cmd_survey,
    "tables": _cmd_tables,
    "train": _cmd_train,
    "worlds": _cmd_worlds,
}
