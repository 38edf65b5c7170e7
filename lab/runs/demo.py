"""``lab demo``: the main job a new user runs first, the identification paper end to end.

One identification episode in the simulator: the robot faces a box (model ``M1`` by default) that a
second robot keeps turning so that its unique face points away (the evasive mover, the paper's human
operator); the robot perceives every frame, tracks the box with the pan-tilt head, and drives to the
next-best view chosen from the lookup tables until one model's probability stays >= 0.95. The demo
writes the paper's Fig. 5-7, the ``lab identify`` JSON and a short ``report.md`` into ``out``, and
optionally an animation (``record``). With ``robot`` (a hardware TOML config) it runs the same loop on
the real (or emulated) robot instead and writes the JSON and report.

The first run builds the feature databases and the lookup tables into the cache (several minutes,
once); :func:`run_demo` says so through ``say`` before it starts.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

from lab.io import write_json_atomic, write_text_atomic

__all__ = ["run_demo", "tables_missing"]

FIGURES = (
    ("fig5_pose_and_probabilities.png", "Fig. 5: pose estimates against ground truth, model probabilities"),
    ("fig6_information_gain_ring.png", "Fig. 6: the ring of candidate goals coloured by information gain"),
    ("fig7_probabilities.png", "Fig. 7: model probabilities against time"),
)


def tables_missing(folder: Path | None = None) -> list[str]:
    """The box models whose lookup tables (or feature databases) are not in the cache yet."""
    from lab.training.databases import database_path
    from lab.training.tables import box_model_names, tables_path

    return [
        n
        for n in box_model_names()
        if not tables_path(n, folder).is_file() or not database_path(n, folder).is_file()
    ]


def _report(res: dict, names: list[str], figures: list[tuple[str, str]], robot: Path | None) -> str:
    k, found = res.get("true_model"), res.get("identified_model")
    post = ", ".join(f"P({n}) = {p:.3f}" for n, p in zip(names, res["final_posterior"], strict=False))
    where = f"on the robot of `{robot}`" if robot else "in the simulator (arena, evasive mover)"
    lines = [
        "# lab demo: model identification with next-best-view planning",
        "",
        f"One episode of the identification paper {where}, planner `{res['planner']}`, seed {res['seed']}.",
        "",
    ]
    if k is not None:
        verdict = "identified correctly" if res["success"] else "NOT identified"
        lines.append(
            f"The box on the carrier was **{names[k]}**; it was {verdict}"
            + (f" (the robot settled on {names[found]})" if found is not None and found != k else "")
            + "."
        )
    else:
        lines.append(
            "Identified model: " + ("none (budget spent)" if found is None else f"**{names[found]}**") + "."
        )
    lines += [
        "",
        f"* planning actions: {res['actions']}",
        f"* simulated time: {res['sim_time_s']:.1f} s, wall time: {res['wall_time_s']:.1f} s "
        f"(real-time factor {res['sim_time_s'] / max(res['wall_time_s'], 1e-9):.2f})",
    ]
    if res.get("real_time_factor_wall") is not None:
        lines.append(
            f"* the loop alone (start-up and figures excluded): {res['real_time_factor_wall']:.2f} x real "
            f"time on the wall clock, {res['real_time_factor_loop_cpu']:.2f} x per CPU second"
        )
    lines += [
        f"* final probabilities: {post}",
    ]
    pe = res.get("pose_error") or {}
    if pe.get("translation_m") is not None:
        lines.append(
            f"* the true model's final pose error: {100 * pe['translation_m']:.1f} cm, "
            f"{pe['rotation_deg']:.1f} deg"
        )
    lines += ["", "The numbers are in `identify.json` (the `lab identify` contract).", ""]
    for name, caption in figures:
        lines += [f"## {caption}", "", f"![{caption}]({name})", ""]
    if res.get("recording"):
        lines += [f"Animation: `{res['recording']}`", ""]
    if res.get("view3d"):
        lines += [f"3D view (open in a browser, drag the time slider): `{res['view3d']}`", ""]
    return "\n".join(lines)


def _what_runs(robot, planner: str, box: str, mover: str, max_actions: int, max_time_s: float) -> str:
    """The line that says what the demo is about to run."""
    if robot is not None:
        return f"lab demo: identifying the box with the robot of {robot} ({planner} planner) ..."
    return (
        f"lab demo: identifying the box on the carrier ({box}, {mover} mover, "
        f"{planner} planner, up to {max_actions} actions, {max_time_s:g} s simulated) ..."
    )


def run_demo(
    out: Path,
    seed: int = 0,
    true_model: int = 1,
    planner: str = "lut",
    mover: str = "evasive",
    max_actions: int = 8,
    max_time_s: float = 150.0,
    record: Path | None = None,
    view3d: Path | None = None,
    robot: Path | None = None,
    say: Callable[[str], None] = print,
    sensing="realistic",
) -> Path:
    """Run the identification demo and return the path of its Markdown report.

    Parameters
    ----------
    out : Path
        Output folder: ``report.md``, ``identify.json`` and the figures.
    seed, true_model, planner, mover, max_actions, max_time_s
        As ``lab identify`` (defaults as in the signature: the box M1, lookup tables, the evasive mover,
        8 actions, 150 s of simulated time).
    record : Path, optional
        Write an animation of the live view (.gif, or .mp4 with ffmpeg).
    view3d : Path, optional
        Write the recorded 3D view (:mod:`lab.viz.view3d`: one HTML page; needs ``lab[view3d]``).
    robot : Path, optional
        A hardware TOML config: run on that robot (no ground truth: no pose error, no Fig. 5 truth); a
        rehearsal config (``hardware/rehearsal.toml``) runs on the emulators with rendered frames and
        uses ``true_model`` and ``mover`` for the rendered scene.
    say : callable
        Where progress lines go (the terminal).
    sensing : str or mapping
        The simulator's sensing profile (:func:`lab.sim.sensing.sensing_profile`; default realistic).
    """
    from lab.training.tables import box_model_names

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    names = list(box_model_names())
    if robot is None:
        from lab.sim import box_model

        box_model(true_model)  # a clear error before anything starts
    missing = tables_missing()
    if planner == "lut" and missing:
        say(
            f"lab demo: first run: building the feature databases and lookup tables of {', '.join(missing)} "
            "(several minutes, once; `lab tables` builds them ahead)"
        )
    t0 = time.perf_counter()
    from lab.runs.identify import run_identify

    say(_what_runs(robot, planner, names[true_model], mover, max_actions, max_time_s))
    res = run_identify(
        true_model,
        seed,
        mover,
        planner,
        max_actions,
        out=out,
        json_path=out / "identify.json" if robot is None else None,
        max_time_s=max_time_s,
        record=record,
        view3d=view3d,
        robot_config=robot,
        progress=say if robot is not None else None,
        sensing=sensing,
    )
    figures = [(f, c) for f, c in FIGURES if (out / f).is_file()]
    res["demo_wall_time_s"] = time.perf_counter() - t0
    write_json_atomic(out / "identify.json", res)
    report = out / "report.md"
    write_text_atomic(report, _report(res, names, figures, robot))
    return report
