"""Next-best view by lookup tables against Monte Carlo: agreement, speed, and the lookup tables at scale.

    python benchmarks/bench_planning.py [--quick] [--samples N] [--decisions N]

Part 1, rendered scenarios. A box model (M0..M3) stands on its carrier, turned so that the robot's
first view shows a shared face (or a corner of two); the robot observes 3 frames (EKF bank, model
probabilities), then decides where to go next with both planners over the same 36 candidate goals,
drives to the lookup tables' choice (the camera is put there), observes again, and so on until one
model's probability reaches 0.95 or the decision budget is spent. For every decision the Monte Carlo
gains (Eq. (4) with Eq. (10)) are the reference: does the action the tables chose attain >= 90 % of the
best Monte Carlo gain? The Monte Carlo is run twice with different seeds to show that it is stable.
Ground truth is used only to set scenes up (the first view is aimed at the true box centre); every
later view is aimed at the estimated centre.

Part 2, scale. Synthetic databases of L = 4, 10 and 20 box models (lab.identification.synthetic):
the median time of one lookup-table decision over 36 candidates, and of a Monte Carlo one for scale.

Prints per-decision lines, then the summary figures. Needs the feature databases and lookup tables
(built and cached on first use: `lab train`, `lab tables`).
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

import numpy as np

from lab.estimation import EKFBank, EKFConfig, OrientationChart
from lab.geometry import G_to_pose6, Pose2D, Rz, relative_pose2d, se3, se3_inv
from lab.identification import (
    LookupTableEvaluator,
    ModelHypotheses,
    ModelScorer,
    MonteCarloConfig,
    MonteCarloEvaluator,
    ScoringConfig,
    aim_pan_tilt,
    calc_possible_control_actions,
    entropy,
    information_gain,
    next_best_action,
    observe_frame,
    plan_next_best_view,
    pose_estimate_rv,
    ring_smoothed,
    symmetry_log_weights,
    uniform,
    z_turns,
)
from lab.identification.synthetic import synthetic_box_databases, synthetic_tables
from lab.robot import StereoCamera
from lab.sim import SimWorld, load_box_models
from lab.training import get_database, get_tables
from lab.vision import Matcher, stereo_features

CAM = StereoCamera.from_fov(320, 240, 60.0, 0.12, mount_R=(0.0, 0.0, 0.7))  # the simulated robot's
SYMMETRIES = z_turns(4)  # the boxes' side faces look alike: a filter's pose may be off by a quarter turn


def run_scenario(
    model_index, box_yaw, start, dbs, matchers, scorers, lut, mcs, max_decisions, symmetric, frames=3
):
    """Decisions of one scenario: a list of dicts (one per decision).

    ``start`` is the robot's first pose; its first view is aimed at the true box centre (set-up)."""
    models = load_box_models()
    out = []
    with SimWorld("box_database") as world:
        carrier = world.add_carrier(models[model_index], Pose2D(0.0, 0.0, 0.0), box_yaw=box_yaw)
        rng = np.random.default_rng(model_index)
        bank = EKFBank(len(dbs), EKFConfig(chart=OrientationChart.ROTATION_VECTOR), rng=rng)
        P = uniform(len(dbs))
        pose, target = start, carrier.G_WO[:3, 3]
        prev_pose, prev_G_RC = pose, None
        history = []  # (features, G_WC) of every frame: the evidence about the look-alike poses
        for d in range(max_decisions + 1):
            pan, tilt = aim_pan_tilt(CAM, pose, target)
            G_RC = CAM.G_RC(pan, tilt)
            G_WC = pose.G() @ G_RC
            G_odom = relative_pose2d(prev_pose, pose)
            for f in range(frames):
                left, right = world.render_stereo(G_WC, CAM)
                feats = stereo_features(left, right, CAM)
                first = f == 0
                predicted = bank.predict(
                    prev_G_RC if (first and prev_G_RC is not None) else G_RC,
                    G_RC,
                    G_odom if first else np.eye(4),
                    0.1,
                )
                P = observe_frame(P, feats, bank, predicted, matchers, scorers).belief.P
                history.append((feats, G_WC))
            prev_pose, prev_G_RC = pose, G_RC
            if P.max() >= 0.95 or d == max_decisions:
                break
            if symmetric:  # every model's pose turned by 0, 90, 180, 270 deg, weighted by the frames so far
                lw = symmetry_log_weights(history[-12:], scorers, bank.estimates, G_WC, SYMMETRIES)
                hyp = ModelHypotheses.from_estimates(P, bank.estimates, G_WC, SYMMETRIES, lw)
            else:
                hyp = ModelHypotheses.from_estimates(P, bank.estimates, G_WC)
            actions = calc_possible_control_actions(hyp.object_centre_W(), CAM)
            H = entropy(P)
            t0 = time.perf_counter()
            lut_plan = plan_next_best_view(hyp, CAM, lut)
            t_lut = time.perf_counter() - t0
            gains_mc, t_mc = [], []
            for mc in mcs:
                t0 = time.perf_counter()
                gains_mc.append(information_gain(H, mc.expected_entropy(actions, hyp)))
                t_mc.append(time.perf_counter() - t0)
            g = gains_mc[0]
            b_lut, b_mc = lut_plan.best, next_best_action(g, tie_break=ring_smoothed(g, actions))
            out.append(
                {
                    "model": model_index,
                    "yaw_deg": math.degrees(box_yaw),
                    "decision": d,
                    "P": P.copy(),
                    "H": H,
                    "lut_best": b_lut,
                    "mc_best": b_mc,
                    "mc_best_gain": float(g[b_mc]),
                    "mc_gain_of_lut": float(g[b_lut]),
                    "mc_seed_gap": float(np.max(np.abs(gains_mc[0] - gains_mc[1]))) if len(mcs) > 1 else 0.0,
                    "mc_seed2_ratio": float(gains_mc[1][b_mc] / max(gains_mc[1].max(), 1e-12))
                    if len(mcs) > 1
                    else 1.0,
                    "t_lut": t_lut,
                    "t_mc": t_mc[0],
                    "az_lut": math.degrees(actions[b_lut].azimuth),
                    "az_mc": math.degrees(actions[b_mc].azimuth),
                }
            )
            pose, target = lut_plan.action.pose, hyp.object_centre_W()
    return out


def part_rendered(args):
    names = [m.name for m in load_box_models()]
    dbs = [get_database(n) for n in names]
    tables = get_tables(names, dbs=dbs)
    matchers = [Matcher(db) for db in dbs]
    scorers = [ModelScorer(db, ScoringConfig().for_camera(CAM)) for db in dbs]
    lut = LookupTableEvaluator(tables, CAM)
    mcs = [
        MonteCarloEvaluator(dbs, CAM, config=MonteCarloConfig(n_samples=args.samples, seed=s)) for s in (0, 1)
    ]
    # each model faces the robot with each shared face (and a corner of two), from its own distance and
    # side: 16 scenarios whose first views all differ
    yaws = (0.0, 90.0, -90.0, 45.0) if not args.quick else (0.0, 90.0)
    models = range(len(names)) if not args.quick else (0, 3)
    distances = (0.9, 1.0, 1.1, 1.2)
    sides_deg = (-15.0, 0.0, 15.0, 30.0)
    rows = []
    print(
        f"{'model':>5} {'yaw':>5} {'dec':>3} {'H':>5} {'az lut':>6} {'az mc':>6} {'mc(lut)/mc(best)':>16} "
        f"{'lut ms':>7} {'mc s':>6} {'mc seed gap':>11}"
    )
    for k in models:
        for n, yaw in enumerate(yaws):
            side = math.radians(sides_deg[(k + n) % 4])
            r0 = distances[k]
            start = Pose2D(-r0 * math.cos(side), -r0 * math.sin(side), side)  # facing the box
            box_yaw = math.radians(yaw) + side  # the same face still turned towards the robot
            scenario = (
                k,
                box_yaw,
                start,
                dbs,
                matchers,
                scorers,
                lut,
                mcs,
                args.decisions,
                not args.no_symmetry,
            )
            for r in run_scenario(*scenario):
                ratio = r["mc_gain_of_lut"] / r["mc_best_gain"] if r["mc_best_gain"] > 1e-9 else 1.0
                r["ratio"] = ratio
                rows.append(r)
                print(
                    f"{'M' + str(k):>5} {yaw:5.0f} {r['decision']:3d} {r['H']:5.2f} {r['az_lut']:6.0f} "
                    f"{r['az_mc']:6.0f} {ratio:16.2f} {1e3 * r['t_lut']:7.1f} {r['t_mc']:6.2f} "
                    f"{r['mc_seed_gap']:11.3f}",
                    flush=True,
                )
    n = len(rows)
    good = sum(r["ratio"] >= 0.9 for r in rows)
    same = sum(r["lut_best"] == r["mc_best"] for r in rows)
    t_lut = statistics.median(r["t_lut"] for r in rows)
    t_mc = statistics.median(r["t_mc"] for r in rows)
    print(f"\ndecisions: {n} in {len(models) * len(yaws)} scenarios")
    print(f"LUT choice attains >= 90% of the best Monte Carlo gain: {good}/{n} = {100 * good / n:.0f}%")
    ratios = [r["ratio"] for r in rows]
    print(f"min ratio {min(ratios):.2f}, median {statistics.median(ratios):.2f}")
    print(f"LUT and Monte Carlo choose the very same action: {same}/{n} = {100 * same / n:.0f}%")
    print(
        f"decision time (36 candidates, L = {len(names)}): LUT median {1e3 * t_lut:.1f} ms, "
        f"Monte Carlo (N = {args.samples}) median {t_mc:.2f} s, ratio {t_mc / t_lut:.0f}x"
    )
    gap = max(r["mc_seed_gap"] for r in rows)
    stable = sum(r["mc_seed2_ratio"] >= 0.9 for r in rows)
    print(
        f"Monte Carlo stability (two seeds): largest gain difference {gap:.3f} nats; the first seed's "
        f"choice attains >= 90% of the second seed's best in {stable}/{n}"
    )


def part_scale(args):
    print("\nscale: synthetic databases, one decision over 36 candidates")
    print("(20x4: 20 models with 4 pose hypotheses each)")
    print(f"{'L':>5} {'LUT median ms':>14} {'LUT p90 ms':>11} {'MC s (N=32)':>12}")
    for L, turns in ((4, 1), (10, 1), (20, 1), (20, 4)):
        rng = np.random.default_rng(L)
        dbs = synthetic_box_databases(L, rng)
        tables = synthetic_tables(dbs)
        lut = LookupTableEvaluator(tables, CAM)
        times = []
        for _ in range(args.repeats):
            P = rng.dirichlet(np.ones(L))
            P = np.maximum(P, 1e-3)
            P /= P.sum()
            G = se3(Rz(rng.uniform(-np.pi, np.pi)), (0.0, 0.0, 0.49))
            S = np.diag([2e-4] * 3 + [1e-3] * 3)
            if turns == 1:
                hyp = ModelHypotheses.one_pose_each(P, np.stack([G] * L), np.stack([S] * L))
            else:  # every model with its quarter turns: 4 L pose hypotheses
                G_WC = CAM.G_RC(0.0, 0.0)
                est = pose_estimate_rv(G_to_pose6(se3_inv(G_WC) @ G), S)
                hyp = ModelHypotheses.from_estimates(P, [est] * L, G_WC, z_turns(turns))
            t0 = time.perf_counter()
            plan = plan_next_best_view(hyp, CAM, lut)
            times.append(time.perf_counter() - t0)
            assert len(plan.actions) == 36
        times.sort()
        t_mc = float("nan")
        if L <= 10 and turns == 1 and not args.quick:
            mc = MonteCarloEvaluator(dbs, CAM, config=MonteCarloConfig(n_samples=32))
            t0 = time.perf_counter()
            plan_next_best_view(hyp, CAM, mc)
            t_mc = time.perf_counter() - t0
        label = str(L) if turns == 1 else f"{L}x{turns}"
        med, p90 = statistics.median(times), times[int(0.9 * (len(times) - 1))]
        print(f"{label:>5} {1e3 * med:14.1f} {1e3 * p90:11.1f} {t_mc:12.2f}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="2 models x 2 starting faces, no MC at scale")
    ap.add_argument("--samples", type=int, default=64, help="Monte Carlo samples N (default 64)")
    ap.add_argument("--decisions", type=int, default=3, help="decision budget per scenario (default 3)")
    ap.add_argument("--repeats", type=int, default=20, help="timed LUT decisions per L (default 20)")
    ap.add_argument("--skip-rendered", action="store_true", help="only the scale part")
    ap.add_argument(
        "--no-symmetry", action="store_true", help="one pose per model (no quarter-turn look-alike poses)"
    )
    args = ap.parse_args()
    if not args.skip_rendered:
        part_rendered(args)
    part_scale(args)


if __name__ == "__main__":
    main()
