"""Shared-face drift in closed-loop episodes (issue 7), with and without pooling the shared evidence.

The model probabilities before the unique face first comes into view, with and without
``ScoringConfig.pool_shared``.

Run (from the repository root)::

    nice .venv/bin/python benchmarks/eval_shared_drift.py --planner random --episodes 0:0,1:1 --max-time 60
    nice .venv/bin/python benchmarks/eval_shared_drift.py --planner lut --episodes 0-3:0-2

Each episode (``lab identify``'s scene: evasive mover, the robot facing a shared face first) runs in
its own process, once with pooling and once without, side by side. Ground truth is used here only to
evaluate: at every step the angle between the unique (+X) face's normal and the direction from the
box to the camera; the unique face "comes into view" at the first step where it is below 90 degrees.
Printed per episode and pooling: the largest ``|P - 1/4|`` before that step (the acceptance: "the
probabilities stay near uniform until the unique face comes into view"), the probabilities then, and
the episode's outcome (identified, planning actions, sim time). The random planner's long stretches of
shared faces are the stress case; with it the evasive mover often keeps the unique face hidden for the
whole episode, and then the episode is the same for every true model.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import os
import statistics
import subprocess
import sys

from lab.evaluation import parse_seeds as _range  # "0-3,5" -> [0, 1, 2, 3, 5]


def _episodes(text: str) -> list[tuple[int, int]]:
    """``M:S`` pairs separated by commas, each side a number or a range: ``0-3:0-2`` or ``0:0,1:1``."""
    out = []
    for part in text.split(","):
        if not part:
            continue
        if ":" not in part:
            raise SystemExit(f"episodes must be MODELS:SEEDS pairs (e.g. 0-3:0-2 or 0:0,1:1), got {part!r}")
        ms, ss = part.split(":")
        out += [(m, s) for m in _range(ms) for s in _range(ss)]
    return out


def one_episode(model: int, seed: int, planner: str, pool: bool, max_time_s: float) -> dict:
    """Run one episode in this process and measure the drift (ground truth for evaluation only)."""
    import numpy as np

    import lab.identification.agent as agent_module
    from lab.identification.scoring import ScoringConfig
    from lab.runs.identify import run_identify

    agent_module.ScoringConfig = functools.partial(ScoringConfig, pool_shared=pool)
    steps = []

    def attach(agent, carrier):
        world, step = agent.robot.world, agent.step

        def observed_step():
            G_WC, G_WO = world.truth.G_WC(), carrier.G_WO.copy()
            rec = step()
            to_camera = G_WC[:3, 3] - G_WO[:3, 3]
            cos = G_WO[:3, 0] @ to_camera / np.linalg.norm(to_camera)  # +X (unique) face's normal
            steps.append((rec.t, math.degrees(math.acos(np.clip(cos, -1.0, 1.0))), rec.posterior.tolist()))
            return rec

        agent.step = observed_step

    res = run_identify(
        model, seed, mover="evasive", planner=planner, figures=False, max_time_s=max_time_s, attach=attach
    )
    angle = np.array([a for _, a, _ in steps])
    P = np.array([p for _, _, p in steps])
    in_view = np.flatnonzero(angle < 90.0)
    first = int(in_view[0]) if len(in_view) else len(steps)
    return {
        "model": model,
        "seed": seed,
        "planner": planner,
        "pool_shared": pool,
        "steps": len(steps),
        "unique_face_first_in_view_s": steps[first][0] if first < len(steps) else None,
        "max_dev_before_unique": float(np.abs(P[:first] - 0.25).max()) if first else 0.0,
        "P_before_unique": [round(float(x), 3) for x in P[first - 1]] if first else None,
        "identified": res["identified_model"],
        "success": res["success"],
        "actions": res["actions"],
        "sim_time_s": res["sim_time_s"],
        "real_time_factor_wall": res.get("real_time_factor_wall"),
        "real_time_factor_loop_cpu": res.get("real_time_factor_loop_cpu"),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--planner", default="random")
    ap.add_argument("--episodes", type=_episodes, default=_episodes("0:0,1:1,2:2,3:3"), help="MODELS:SEEDS")
    ap.add_argument("--max-time", type=float, default=60.0)
    ap.add_argument("--one", nargs=2, type=int, metavar=("MODEL", "SEED"), help=argparse.SUPPRESS)
    ap.add_argument("--pool", type=int, default=1, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.one:
        print(json.dumps(one_episode(*args.one, args.planner, bool(args.pool), args.max_time)))
        return 0
    env = dict(os.environ, OPENBLAS_NUM_THREADS=os.environ.get("OPENBLAS_NUM_THREADS", "1"))
    rows = []
    print(
        f"{'M':>2s} {'seed':>4s} {'pool':>5s} {'max|P-1/4|':>10s} {'unique in view':>14s}  P then / outcome"
    )
    for m, s in args.episodes:
        for pool in (False, True):
            cmd = [sys.executable, __file__, "--one", str(m), str(s), "--planner", args.planner]
            cmd += ["--pool", str(int(pool)), "--max-time", str(args.max_time)]
            r = subprocess.run(cmd, capture_output=True, text=True, env=env)
            if r.returncode != 0:
                print(f"M{m} seed {s} pool {pool}: FAILED: {r.stderr[-300:]}", flush=True)
                continue
            row = json.loads(r.stdout.strip().splitlines()[-1])
            rows.append(row)
            seen = row["unique_face_first_in_view_s"]
            print(
                f"{m:>2d} {s:>4d} {pool!s:>5s} {row['max_dev_before_unique']:10.3f} "
                f"{'never' if seen is None else f'{seen:.1f} s':>14s}  {row['P_before_unique']} / "
                f"identified {row['identified']} after {row['actions']} actions, {row['sim_time_s']:.1f} s",
                flush=True,
            )
    for pool in (False, True):
        dev = [r["max_dev_before_unique"] for r in rows if r["pool_shared"] is pool]
        if dev:
            print(
                f"pool_shared={pool}: largest |P - 1/4| before the unique face shows: median "
                f"{statistics.median(dev):.3f}, max {max(dev):.3f} over {len(dev)} episodes"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
