"""The live view's cost: a short identification run with and without the view, side by side.

Run: PYTHONPATH=. .venv/bin/python benchmarks/bench_live.py [--repeats N] [--sim-time S] [--rate HZ]

Each repeat runs the same seeded episode (static box, circling planner, so every run takes the same
steps) twice, alternating: without a view (the agent's observer is None) and with
``LiveView.for_identification(agent)`` at the default rate (2 Hz of sim time) feeding an
``ipywidgets.Image`` (render + PNG encoding, as in a notebook). Prints the medians of the run's wall and
CPU time, their ratio, and the view's own time (its update calls, measured inside the same run) as a
fraction of that run's wall time. The acceptance of issue 12: the view costs < 10 % of the run's wall time.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from lab.geometry import Pose2D
from lab.identification.agent import AgentConfig, IdentificationAgent
from lab.sim import SimRobot, SimWorld, load_box_models
from lab.training import get_database
from lab.viz.live import LiveView


def one_run(with_view: bool, sim_time_s: float, rate_hz: float) -> dict:
    models = load_box_models()
    with SimWorld("arena") as world:
        world.add_carrier(models[2], Pose2D(0.0, 0.0, 0.0), box_yaw=0.1)
        robot = SimRobot(world, start=Pose2D(-1.2, 0.0, 0.0), seed=3)
        agent = IdentificationAgent(
            robot,
            [get_database(m.name) for m in models],
            planner="circle",
            seed=3,
            config=AgentConfig(max_actions=2, max_time_s=sim_time_s),
        )
        view_s = 0.0
        view = None
        if with_view:
            view = LiveView.for_identification(agent, rate_hz=rate_hz)
            view.widget  # noqa: B018 - a notebook displays it: PNG encoding included
            update = view.update

            def timed_update():
                nonlocal view_s
                t = time.perf_counter()
                out = update()
                view_s += time.perf_counter() - t
                return out

            view.update = timed_update
        w0, c0 = time.perf_counter(), time.process_time()
        agent.run()
        wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    return {
        "wall": wall,
        "cpu": cpu,
        "steps": len(agent.steps),
        "draws": 0 if view is None else view.n_draws,
        "full": 0 if view is None else view.n_full_draws,
        "view_s": view_s,
    }


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--sim-time", type=float, default=8.0, help="sim seconds per run (default 8)")
    ap.add_argument("--rate", type=float, default=2.0, help="view rate [Hz of sim time] (default 2)")
    args = ap.parse_args()
    one_run(False, 1.0, args.rate)  # warm-up: databases loaded, matchers built
    runs = {False: [], True: []}
    for _ in range(args.repeats):
        for v in (False, True):
            runs[v].append(one_run(v, args.sim_time, args.rate))
    med = {v: {k: statistics.median(r[k] for r in runs[v]) for k in ("wall", "cpu")} for v in runs}
    steps = {v: sorted({r["steps"] for r in runs[v]}) for v in runs}
    frac = [r["view_s"] / r["wall"] for r in runs[True]]
    print(
        f"identification run of {args.sim_time:g} s sim time, {args.repeats} repeats, "
        f"view at {args.rate:g} Hz"
    )
    print(f"steps per run: without view {steps[False]}, with view {steps[True]}")
    print(f"{'':>14} {'wall median s':>14} {'cpu median s':>13}")
    print(f"{'without view':>14} {med[False]['wall']:>14.2f} {med[False]['cpu']:>13.2f}")
    print(f"{'with view':>14} {med[True]['wall']:>14.2f} {med[True]['cpu']:>13.2f}")
    print(
        f"ratio with/without: wall {med[True]['wall'] / med[False]['wall']:.3f}, "
        f"cpu {med[True]['cpu'] / med[False]['cpu']:.3f}"
    )
    draws = [r["draws"] for r in runs[True]]
    full = [r["full"] for r in runs[True]]
    per_draw = [1e3 * r["view_s"] / max(r["draws"], 1) for r in runs[True]]
    print(
        f"view: {statistics.median(draws):.0f} draws per run ({statistics.median(full):.0f} full redraws), "
        f"{statistics.median(per_draw):.0f} ms per draw "
        f"(median); its share of the run's wall time: median {100 * statistics.median(frac):.1f} %, "
        f"max {100 * float(np.max(frac)):.1f} %"
    )


if __name__ == "__main__":
    main()
