"""The search issue's acceptance, measured: success, collisions, path length and SPL per strategy.

Run from the repository root (each trial is a full closed-loop run in the simulator, with the stereo-
costmap navigator that ``lab search`` uses; expect one to three minutes of CPU per trial)::

    python benchmarks/eval_search.py run --out eval.jsonl [--strategies paper,lawnmower,frontier]
        [--seeds 100000,100001] [--sensing realistic|ideal]
        [--obstacles both|no|yes] [--surfaces floor,table,shelf] [--max-time 300]
        [--shard K/N]
    python benchmarks/eval_search.py report eval.jsonl

**Trials.** Three textured objects (cereal_box, book, toy_block) x three heights (floor, table_a or
table_b at 0.75 m, the shelf at 1.2 m) x the seeds: each (object, surface, seed) is one seeded random
placement (``random_placement`` with ``default_rng([seed, object, surface])``: position and yaw), the
same for every strategy and with and without obstacles. ``--obstacles yes`` adds the two boxes of
``lab.runs.search.path_obstacles`` on the straight line from the start to the object (the paper's
"obstacles placed in the planned path"; the boxes are not in the robot's map, it must see them).
Two seeds give the issue's 18 placements; by default the report split's (seeds 100000 and 100001, see
:mod:`lab.evaluation`), under the ``realistic`` sensing profile (``--sensing``). A trial that runs out
of ``--max-time`` (simulated seconds) is a failure: a slow baseline fails by its budget.

``run`` appends one JSON line per trial (the ``lab search`` JSON without its map snapshots, plus
``shortest_path_m``) and skips trials already in the file, so a killed run can be resumed; ``--shard
K/N`` runs every N-th trial from the K-th (for several processes writing separate files).

**Report** (``report FILE...``), per strategy and obstacle setting and overall:

* success: found, position error <= 5 cm and orientation error <= 10 degrees (``SearchResult.success``);
* collisions (the simulator's bump count, summed);
* SPL, success weighted by path length: mean of ``S_i l_i / max(p_i, l_i)`` with ``l_i`` the shortest
  collision-free path from the start to local-search range of the object (A* on the scene's true
  occupancy grown by the robot's radius: evaluation only, the robot never sees it) and ``p_i`` the
  driven path (odometry);
* the median over the trials both strategies got right of the ratio of the paper strategy's path
  length to the lawnmower's on the same trial (the issue wants <= 0.7), and the same ratio with the
  lawnmower's path on its failures counted as driven (a lower bound of what it would have needed).
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from lab.evaluation import report_seeds, split_of, wilson_interval

OBJECTS = ("cereal_box", "book", "toy_block")
SURFACES = ("floor", "table", "shelf")


def trial_list(strategies, seeds, obstacles, surfaces=SURFACES) -> list[dict]:
    """Every trial: the shelf's last (the slowest: its failures run to the budget), strategies
    interleaved on the same placement."""
    obst = {"no": (False,), "yes": (True,), "both": (False, True)}[obstacles]
    out = []
    for s_i, surface in enumerate(SURFACES):
        if surface not in surfaces:
            continue
        for seed in seeds:
            for o_i, name in enumerate(OBJECTS):
                for ob in obst:
                    for strat in strategies:
                        out.append(
                            {
                                "object": name,
                                "surface": surface,
                                "seed": seed,
                                "obstacles": ob,
                                "strategy": strat,
                                "placement_key": [seed, o_i, s_i],
                            }
                        )
    return out


def key(d: dict) -> tuple:
    return (d["object"], d["surface"], int(d["seed"]), bool(d["obstacles"]), d["strategy"])


def label(d: dict) -> str:
    """One trial's name for the printouts."""
    obst = "obstacles" if d["obstacles"] else "no obstacles"
    return f"{d['strategy']:9s} {d['object']:10s} {d['surface']:5s} seed {d['seed']} {obst:12s}"


def shortest_path_m(scene, place, local_max_m: float, local_min_m: float) -> float:
    """Length [m] of the shortest collision-free path from the robot's start to local-search range of
    the object, on the scene's true occupancy (every body but posters, and the walls) grown by the
    robot's radius. Evaluation only."""
    from lab.navigation import Costmap, GridSpec, astar_to_region
    from lab.robot import BaseLimits
    from lab.runs.placement import footprint

    sx, sy = scene.room.size
    spec = GridSpec.from_bounds(-sx / 2, -sy / 2, sx / 2, sy / 2, 0.05)
    X, Y = spec.cell_centers()
    pts = np.stack([X.ravel(), Y.ravel()], axis=1)
    occ = np.zeros(len(pts), bool)
    for b in scene.bodies:
        if b.role in ("decor", "object"):
            continue
        poly = footprint(b)
        edges = np.roll(poly, -1, axis=0) - poly
        rel = pts[:, None, :] - poly[None, :, :]
        cross = edges[None, :, 0] * rel[:, :, 1] - edges[None, :, 1] * rel[:, :, 0]
        occ |= np.all(cross >= 0, axis=1) | np.all(cross <= 0, axis=1)
    occ = occ.reshape(spec.shape)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = True
    grid = Costmap.from_occupancy(spec, occ).inflated(BaseLimits().radius)
    rx, ry, _ = scene.robot_start
    path = astar_to_region(grid, (rx, ry), (place[0], place[1]), local_max_m, local_min_m)
    return float(path.length) if path.found else math.nan


def run_one(t: dict, max_time: float, max_wall: float | None, sensing: str = "realistic") -> dict:
    from lab.runs.placement import random_placement
    from lab.runs.search import navigator_factory, path_obstacles, run_search
    from lab.scene import load_scene
    from lab.search.agent import AgentConfig

    scene = load_scene("lab_room")
    place = random_placement(scene, t["object"], np.random.default_rng(t["placement_key"]), t["surface"])
    w0 = time.perf_counter()
    try:
        r = run_search(
            t["object"],
            t["seed"],
            place=place,
            strategy=t["strategy"],
            max_time=max_time,
            navigate=navigator_factory,
            obstacles=t["obstacles"],
            max_wall_time=max_wall,
            sensing=sensing,
        )
        d = r.to_json()  # with its events: what it visited and why it failed
        d["n_snapshots"] = len(d.pop("map_snapshots", []))
        with_obst = r.trace.scene
    except Exception as e:  # a crash is a failed trial, recorded with its reason
        d = {
            "error": f"{type(e).__name__}: {e}",
            "found": False,
            "success": False,
            "collisions": 0,
            "path_length_m": 0.0,
        }
        with_obst = scene.with_pose(t["object"], place)
        if t["obstacles"]:
            with_obst, _ = path_obstacles(with_obst, t["object"], place, np.random.default_rng(t["seed"]))
    lc = AgentConfig().local_search
    d["obstacle_poses"] = d.get("obstacles", [])
    d.update({k: t[k] for k in ("object", "surface", "seed", "obstacles", "strategy")})
    d["place"] = [round(float(v), 4) for v in place]
    d["shortest_path_m"] = round(shortest_path_m(with_obst, place, lc.max_distance_m, lc.min_distance_m), 4)
    d["eval_wall_s"] = round(time.perf_counter() - w0, 1)
    return d


def cmd_run(args) -> int:
    from lab.io import write_text_atomic

    strategies = [s.strip() for s in args.strategies.split(",") if s.strip()]
    seeds = [int(s) for s in args.seeds.split(",")]
    surfaces = [s.strip() for s in args.surfaces.split(",") if s.strip()]
    bad = sorted(set(surfaces) - set(SURFACES))
    if bad:
        raise SystemExit(f"unknown surface(s) {', '.join(bad)}; surfaces: {', '.join(SURFACES)}")
    trials = trial_list(strategies, seeds, args.obstacles, surfaces)
    print(f"split: {split_of(seeds)} (seeds {', '.join(map(str, seeds))}); sensing {args.sensing}", flush=1)
    k, n = (int(v) for v in args.shard.split("/"))
    if not 0 <= k < n:
        raise SystemExit(f"--shard K/N needs 0 <= K < N (K counts from 0), got {args.shard}")
    trials = trials[k::n]
    out = Path(args.out)
    done = set()
    lines = []
    if out.exists():
        lines = out.read_text().splitlines()
        done = {key(json.loads(line)) for line in lines if line.strip()}
    todo = [t for t in trials if key(t) not in done]
    print(f"{len(trials)} trials in this shard, {len(todo)} to run", flush=True)
    for t in todo:
        d = run_one(t, args.max_time, args.max_wall_time, args.sensing)
        lines.append(json.dumps(d))
        write_text_atomic(out, "\n".join(lines) + "\n")
        print(
            f"{label(d)}: success {d.get('success')} found {d.get('found')} pe {d.get('position_error_m')} "
            f"oe {d.get('orientation_error_deg')} path {d.get('path_length_m', 0):.1f} m "
            f"(shortest {d['shortest_path_m']}) sim {d.get('sim_time_s')} s wall {d['eval_wall_s']} s "
            f"coll {d.get('collisions')} {d.get('reason', d.get('error', ''))}",
            flush=True,
        )
    return 0


def n_obstacles_placed(d: dict) -> int:
    """Boxes ``path_obstacles`` actually put on the line (none fit when the object is near the start):
    recomputed from the seed as ``run_search`` draws them."""
    if not d["obstacles"]:
        return 0
    if "obstacle_poses" in d:
        return len(d["obstacle_poses"])
    from lab.runs.search import path_obstacles
    from lab.scene import load_scene

    place = tuple(d["place"])
    scene = load_scene("lab_room").with_pose(d["object"], place)
    return len(path_obstacles(scene, d["object"], place, np.random.default_rng(int(d["seed"])))[1])


def spl(rows) -> float:
    vals = []
    for d in rows:
        l, p = d.get("shortest_path_m"), d.get("path_length_m", 0.0)
        if not d.get("success") or l is None or not math.isfinite(l):
            vals.append(0.0)
        else:
            vals.append(l / max(p, l, 1e-9))
    return float(np.mean(vals)) if vals else math.nan


def summary_line(label: str, rows) -> str:
    n = len(rows)
    s = sum(bool(d.get("success")) for d in rows)
    f = sum(bool(d.get("found")) for d in rows)
    c = sum(int(d.get("collisions") or 0) for d in rows)
    bumped = sum(int(d.get("collisions") or 0) > 0 for d in rows)
    errs = sum("error" in d for d in rows)
    lo, hi = wilson_interval(s, n) if n else (math.nan, math.nan)
    return (
        f"{label:34s} n {n:3d}  success {s:3d} ({100 * s / max(n, 1):5.1f} %, Wilson 95 % "
        f"[{100 * lo:.1f}, {100 * hi:.1f}])  found {f:3d}  "
        f"collisions {c} (in {bumped} trials)  SPL {spl(rows):.3f}" + (f"  crashed {errs}" if errs else "")
    )


def cmd_report(args) -> int:
    rows = []
    for p in args.files:
        rows += [json.loads(line) for line in Path(p).read_text().splitlines() if line.strip()]
    by = {}
    for d in rows:
        by.setdefault(key(d), d)  # first record of a trial wins
    rows = list(by.values())
    for d in rows:
        d["n_obstacles"] = n_obstacles_placed(d)
    strategies = sorted(
        {d["strategy"] for d in rows}, key=lambda s: ("paper", "frontier", "lawnmower").index(s)
    )
    print(f"{len(rows)} trials")
    for s in strategies:
        rs = [d for d in rows if d["strategy"] == s]
        print(summary_line(f"{s}", rs))
        for ob in (False, True):
            sub = [d for d in rs if bool(d["obstacles"]) == ob]
            if sub:
                print(summary_line(f"  {'with' if ob else 'without'} obstacles", sub))
            if ob and sub:
                placed = [d for d in sub if d["n_obstacles"] > 0]
                print(summary_line("    (with >= 1 box actually placed)", placed))
        for surf in SURFACES:
            sub = [d for d in rs if d["surface"] == surf]
            if sub:
                print(summary_line(f"  on the {surf}", sub))
        for name in OBJECTS:
            sub = [d for d in rs if d["object"] == name]
            if sub:
                print(summary_line(f"  {name}", sub))
    # paper vs lawnmower on the same trials
    pairs = []
    for d in rows:
        if d["strategy"] != "paper":
            continue
        k = key(d)[:4] + ("lawnmower",)
        if k in by:
            pairs.append((d, by[k]))
    if pairs:
        both = [
            a["path_length_m"] / b["path_length_m"] for a, b in pairs if a.get("success") and b.get("success")
        ]
        censored = [
            a["path_length_m"] / b["path_length_m"]
            for a, b in pairs
            if a.get("success") and b["path_length_m"] > 0
        ]
        if both:
            med = statistics.median(both)
            print(
                f"path length paper / lawnmower, same trials: median {med:.3f} "
                f"over the {len(both)} both got right"
            )
        else:
            print("path length paper / lawnmower: no trial both got right")
        if censored:
            print(
                f"  over the {len(censored)} the paper strategy got right, the lawnmower's path on its "
                f"failures counted as driven (an upper bound): median {statistics.median(censored):.3f}"
            )
    fails = [d for d in rows if not d.get("success")]
    if fails:
        print("failures:")
        for d in sorted(fails, key=key):
            print(
                f"  {label(d)} place {d.get('place')}: found {d.get('found')} pe {d.get('position_error_m')} "
                f"oe {d.get('orientation_error_deg')}: {d.get('reason', d.get('error'))}"
            )
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("--out", required=True)
    r.add_argument("--strategies", default="paper,lawnmower,frontier")
    r.add_argument(
        "--seeds",
        default=",".join(str(s) for s in report_seeds(2)),
        help="comma-separated (default: the report split's first two, 100000,100001; tune on seeds < 1000)",
    )
    r.add_argument("--sensing", default="realistic", choices=("realistic", "ideal"))
    r.add_argument("--obstacles", choices=("no", "yes", "both"), default="both")
    r.add_argument("--surfaces", default=",".join(SURFACES), help="a subset of floor,table,shelf")
    r.add_argument("--max-time", type=float, default=300.0, help="simulated-time budget per trial [s]")
    r.add_argument("--max-wall-time", type=float, default=None, help="wall-clock cap per trial [s]")
    r.add_argument("--shard", default="0/1", help="K/N: every N-th trial from the K-th (K from 0 to N-1)")
    rep = sub.add_parser("report")
    rep.add_argument("files", nargs="+")
    args = ap.parse_args(argv)
    return cmd_run(args) if args.cmd == "run" else cmd_report(args)


if __name__ == "__main__":
    sys.exit(main())
