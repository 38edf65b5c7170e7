"""EKF consistency on the static-box scenes (issue 19, item 2): NEES inside its 95 % band, per profile.

    nice .venv/bin/python benchmarks/bench_nees.py [--seeds 0-7] [--frames 30] [--out nees.json]

A box model stands still in the ``arena`` world (on a carrier that does not move), in front of a
``SimRobot`` at one of a few start poses (moved a little by the seed, see :func:`jittered`). Per
start pose the robot does one of three slow things while it looks: it stands, it creeps towards
the box and back (2 cm/s), or it pans its head by +-4 deg. A
:class:`lab.estimation.PoseEKF` (rotation-vector chart, as in ``tests/test_ekf_sim.py``) is predicted
with the frames' reported pan-tilt and odometry and updated from real stereo SIFT features matched
against the box's database (``lab.training.get_database``). After ``--warmup`` frames (converging
from the RANSAC start) every frame whose update applied is scored: its NEES against the simulator's
truth, ``inv(truth.G_WC()) @ G_WO``, and whether it lies inside the chi-square(6) 95 % band
[1.24, 14.45]. The scored estimate is the filter's ``object_estimate``: the pose the features say with
the database's own error added (``--point-std-mm``, the database's figure by default; 0 scores the
papers' filter, which takes the database as exact).

The same seeds, start poses and motions run under every profile (``ideal`` and ``realistic`` side by
side, in one run), so that the difference is the sensing alone. By default 8 fresh report seeds
(:func:`lab.evaluation.fresh_report_seeds`, above every seed in the ledger of spent seeds; the split is
printed); a spent one (the former default 100000-100007 is) is refused unless ``--allow-spent-seeds``,
and the output then says "ON SPENT SEEDS". The table gives, per profile, the fraction of scored
frames inside the band (a Wilson 95 % interval over frames: frames of one episode are correlated, so
the interval is optimistic; a second interval resamples whole episodes), the median and p90 NEES, the
fraction below the band's upper end alone (the over-confidence side), the number of scored frames and
of episodes, and the range of the per-episode fractions. ``--out`` writes the same as JSON, with every
episode's figures.

Nothing is tuned here: the filter and the matcher run with their defaults. (The database's figure,
``lab.vision.database.POINT_STD_M``, was chosen with this benchmark on tuning seeds 0-7.)
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy is imported (as under the `lab` command)

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from dataclasses import asdict, dataclass  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy.stats import chi2  # noqa: E402

from lab.errors import ConfigError  # noqa: E402
from lab.estimation import (  # noqa: E402
    CalibrationUncertainty,
    EKFConfig,
    ModelUncertainty,
    OrientationChart,
    PoseEKF,
    nees,
)
from lab.evaluation import (  # noqa: E402
    ALLOW_SPENT_FLAG,
    check_report_seeds,
    fresh_report_seeds,
    parse_seeds,
    seed_ranges_text,
    split_of,
)
from lab.geometry import G_to_pose6, Pose2D, relative_pose2d, se3_inv  # noqa: E402
from lab.sim import SimRobot, SimWorld, load_box_models  # noqa: E402
from lab.training import get_database  # noqa: E402
from lab.vision import Matcher, stereo_features  # noqa: E402
from lab.vision.database import POINT_STD_M  # noqa: E402

NEES_DOF = 6
BAND = (float(chi2.ppf(0.025, NEES_DOF)), float(chi2.ppf(0.975, NEES_DOF)))
DT = 0.1  # s between frames


@dataclass(frozen=True)
class Start:
    """A start pose of the robot, the box in front of it at the origin, and what the robot does.

    ``x``, ``y`` [m], ``theta`` [rad]: the robot's start pose (the box at the world origin);
    ``box_yaw`` [rad]: the box's yaw (pi turns its unique +X face towards -x, where the robot is);
    ``motion``: ``stand``, ``creep`` (towards the box and back at 2 cm/s) or ``pan`` (+-4 deg).
    """

    name: str
    x: float
    y: float
    theta: float
    box_yaw: float
    motion: str


STARTS = (
    Start("front-1.0m-stand", -1.0, 0.0, 0.0, math.pi + 0.3, "stand"),
    Start("left-1.3m-creep", -1.2, 0.45, -0.2, math.pi - 0.4, "creep"),
    Start("right-1.5m-pan", -1.4, -0.5, 0.25, math.pi + 0.5, "pan"),
)


def _aim(robot: SimRobot, G_WO: np.ndarray) -> tuple[float, float]:
    """Pan and tilt that point the camera at the box centre (from the true pose: the set-up only)."""
    p = robot.world.truth.robot_pose()
    c = G_WO[:3, 3]
    pan = math.atan2(c[1] - p.y, c[0] - p.x) - p.theta
    tilt = math.atan2(c[2] - robot.camera.mount_R[2], math.hypot(c[0] - p.x, c[1] - p.y))
    return math.atan2(math.sin(pan), math.cos(pan)), tilt


def _move(robot: SimRobot, start: Start, k: int, pan0: float, tilt0: float) -> None:
    """The scripted slow motion of frame ``k`` (commands only; the caller steps the robot)."""
    if start.motion == "creep":  # 2 cm/s towards the box for the first half, then back
        robot.drive(0.02 if (k // 12) % 2 == 0 else -0.02, 0.0)
    elif start.motion == "pan":  # the head sweeps +-4 deg around its set-up aim, 4 s a period
        robot.command_pan_tilt(pan0 + math.radians(4.0) * math.sin(2 * math.pi * k * DT / 4.0), tilt0)


def _parts(G_CO_true: np.ndarray, estimate) -> tuple[float, float, float, float]:
    """Diagnostics of one frame: the translation and rotation parts of the NEES (each chi-square(3)
    if consistent, from the marginal blocks of ``Sigma_rv``), the translation error [mm] and the
    rotation error [deg]."""
    e_t = estimate.mu[:3] - G_CO_true[:3, 3]
    R = estimate.G_CO[:3, :3] @ G_CO_true[:3, :3].T
    ang = math.acos(min(1.0, max(-1.0, 0.5 * (np.trace(R) - 1.0))))
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    phi = 0.5 * w * (ang / math.sin(ang) if ang > 1e-8 else 1.0)  # Log(R R_true^T), as lab.estimation.nees
    S = estimate.Sigma_rv
    return (
        float(e_t @ np.linalg.solve(S[:3, :3], e_t)),
        float(phi @ np.linalg.solve(S[3:, 3:], phi)),
        1e3 * float(np.linalg.norm(e_t)),
        math.degrees(ang),
    )


def jittered(start: Start, seed: int, i: int) -> Start:
    """The start pose moved by the seed (+-5 cm, +-3 deg, the box +-6 deg): under ``ideal`` the images do
    not depend on the seed, so without it two seeds with the same model would be the same episode."""
    rng = np.random.default_rng([seed, i])
    dx, dy = rng.uniform(-0.05, 0.05, 2)
    dth, dyaw = rng.uniform(-1.0, 1.0, 2) * np.radians([3.0, 6.0])
    return Start(
        start.name,
        start.x + float(dx),
        start.y + float(dy),
        start.theta + float(dth),
        start.box_yaw + float(dyaw),
        start.motion,
    )


def run_episode(
    model,
    db,
    start: Start,
    seed: int,
    sensing: str,
    frames: int,
    warmup: int,
    point_std_m: float | None = None,
) -> dict:
    """One static-box episode: per scored frame the NEES of the filter's object estimate (with the
    database's own error, ``point_std_m``, the database's figure if None); and counts of what the
    filter did."""
    lo, hi = BAND
    chart = OrientationChart.ROTATION_VECTOR
    with SimWorld("arena") as w:
        carrier = w.add_carrier(model, Pose2D(0.0, 0.0, 0.0), box_yaw=start.box_yaw)
        robot = SimRobot(w, start=Pose2D(start.x, start.y, start.theta), seed=seed, sensing=sensing)
        robot.enable()
        pan0, tilt0 = _aim(robot, carrier.G_WO)
        robot.command_pan_tilt(pan0, tilt0)
        robot.wait_pan_tilt()
        calibration = CalibrationUncertainty.of_camera(robot.camera)  # the camera's stated accuracy
        model_err = ModelUncertainty(db.point_std_m if point_std_m is None else point_std_m)
        config = EKFConfig(chart=chart, calibration=calibration, model=model_err)
        ekf = PoseEKF(config, rng=np.random.default_rng(seed))
        matcher = Matcher(db)
        prev, values, parts, outcomes = None, [], [], {}
        for k in range(frames):
            frame = robot.capture_stereo()
            G_CO_true = se3_inv(w.truth.G_WC()) @ carrier.G_WO
            if prev is not None:
                ekf.predict(prev.G_RC, frame.G_RC, relative_pose2d(prev.odom, frame.odom), frame.t - prev.t)
            prev = frame
            f = stereo_features(frame.left, frame.right, frame.camera, t=frame.t)
            res = ekf.update(*matcher.match(f).pairs(f, db))
            outcomes[res.outcome.value] = outcomes.get(res.outcome.value, 0) + 1
            if res.applied and k >= warmup:
                values.append(nees(G_to_pose6(G_CO_true), ekf.object_estimate, chart))
                parts.append(_parts(G_CO_true, ekf.object_estimate))
            _move(robot, start, k, pan0, tilt0)
            robot.step(DT)
    v = np.asarray(values)
    return {
        "model": model.name,
        "start": start.name,
        "pose": [round(v, 4) for v in (start.x, start.y, start.theta, start.box_yaw)],
        "seed": seed,
        "sensing": sensing,
        "frames": frames,
        "scored": len(values),
        "in_band": int(np.sum((v >= lo) & (v <= hi))),
        "above_band": int(np.sum(v > hi)),
        "nees": [round(float(x), 4) for x in values],
        "parts": [[round(float(x), 5) for x in q] for q in parts],
        "outcomes": outcomes,
    }


def wilson(k: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion ``k / n``."""
    if n == 0:
        return (math.nan, math.nan)
    p = k / n
    c = (p + z * z / (2 * n)) / (1 + z * z / n)
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return (c - h, c + h)


def episode_bootstrap(episodes: list[dict], n_boot: int = 2000, seed: int = 0) -> tuple[float, float]:
    """A 95 % interval of the in-band fraction that resamples whole episodes (with replacement): the
    frames of one episode share its scene, calibration draw and database errors, so the Wilson interval
    over frames is optimistic; this one treats the episode as the unit."""
    scored = np.array([e["scored"] for e in episodes if e["scored"]], float)
    inside = np.array([e["in_band"] for e in episodes if e["scored"]], float)
    if len(scored) == 0:
        return (math.nan, math.nan)
    pick = np.random.default_rng(seed).integers(0, len(scored), (n_boot, len(scored)))
    frac = inside[pick].sum(axis=1) / scored[pick].sum(axis=1)
    return (float(np.percentile(frac, 2.5)), float(np.percentile(frac, 97.5)))


def summarise(episodes: list[dict]) -> dict:
    """The figures of one profile over its episodes."""
    v = np.concatenate([np.asarray(e["nees"], float) for e in episodes]) if episodes else np.zeros(0)
    n = len(v)
    k = int(sum(e["in_band"] for e in episodes))
    per_episode = [e["in_band"] / e["scored"] for e in episodes if e["scored"]]
    q = np.concatenate([np.asarray(e["parts"], float).reshape(-1, 4) for e in episodes]) if episodes else None
    med = np.median(q, axis=0) if n else np.full(4, math.nan)
    return {
        "episodes": len(episodes),
        "frames": int(sum(e["frames"] for e in episodes)),
        "scored_frames": n,
        "in_band": k / n if n else math.nan,
        "in_band_wilson95": wilson(k, n),
        "in_band_episode_bootstrap95": episode_bootstrap(episodes),
        "above_band": float(np.mean(v > BAND[1])) if n else math.nan,
        "below_band": float(np.mean(v < BAND[0])) if n else math.nan,
        "median_nees": float(np.median(v)) if n else math.nan,
        "p90_nees": float(np.percentile(v, 90)) if n else math.nan,
        "mean_nees": float(np.mean(v)) if n else math.nan,
        "median_nees_translation": float(med[0]),
        "median_nees_rotation": float(med[1]),
        "median_error_mm": float(med[2]),
        "median_error_deg": float(med[3]),
        "episode_in_band_min": min(per_episode, default=math.nan),
        "episode_in_band_max": max(per_episode, default=math.nan),
    }


def print_table(summary: dict[str, dict]) -> None:
    print(
        f"\n{'profile':<10} {'in band':>8} {'Wilson 95%':>15} {'above':>6} {'below':>6} {'median':>7} "
        f"{'p90':>7} {'mean':>7} {'scored':>7} {'frames':>7} {'eps':>4} {'per-episode':>12}"
    )
    for name, s in summary.items():
        a, b = s["in_band_wilson95"]
        print(
            f"{name:<10} {s['in_band']:>8.1%} {f'[{a:.1%}, {b:.1%}]':>15} {s['above_band']:>6.1%} "
            f"{s['below_band']:>6.1%} {s['median_nees']:>7.2f} {s['p90_nees']:>7.2f} {s['mean_nees']:>7.2f} "
            f"{s['scored_frames']:>7d} {s['frames']:>7d} {s['episodes']:>4d} "
            f"{s['episode_in_band_min']:>5.0%}-{s['episode_in_band_max']:.0%}"
        )
    print(
        f"(band: chi-square({NEES_DOF}) 95 % = [{BAND[0]:.2f}, {BAND[1]:.2f}], "
        f"median {chi2.ppf(0.5, 6):.2f}; "
        f"the 3-dof parts' median {chi2.ppf(0.5, 3):.2f})"
    )
    for name, s in summary.items():
        a, b = s["in_band_episode_bootstrap95"]
        print(
            f"{name:<10} in band, 95 % over resampled episodes (an episode's frames correlate): "
            f"[{a:.1%}, {b:.1%}]"
        )
    for name, s in summary.items():
        print(
            f"{name:<10} translation part: median NEES {s['median_nees_translation']:.2f}, error median "
            f"{s['median_error_mm']:.1f} mm; rotation part: median NEES {s['median_nees_rotation']:.2f}, "
            f"error median {s['median_error_deg']:.2f} deg"
        )


NEES_SEEDS = 8  #: the default: this many fresh report seeds


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--seeds",
        type=parse_seeds,
        default=fresh_report_seeds(NEES_SEEDS),
        help=f"seeds, e.g. 0-7 (tuning) or report seeds (default: {NEES_SEEDS} fresh report seeds, above "
        f"every seed in the ledger of spent seeds; a spent one is refused without {ALLOW_SPENT_FLAG})",
    )
    ap.add_argument("--frames", type=int, default=30, help="frames per episode (0.1 s apart)")
    ap.add_argument("--warmup", type=int, default=5, help="frames not scored after the start")
    ap.add_argument("--profiles", default="ideal,realistic")
    ap.add_argument(
        "--point-std-mm",
        type=float,
        help="the database points' own error [mm] the filter assumes (default: the database's, "
        "lab.vision.database.POINT_STD_M; 0 is the papers' exact database)",
    )
    ap.add_argument("--out", type=Path, help="JSON summary")
    ap.add_argument(
        ALLOW_SPENT_FLAG,
        action="store_true",
        help="run even on report seeds the ledger lists as spent (refused otherwise); the output says so",
    )
    return ap


def main(argv=None) -> int:
    ap = build_parser()
    try:  # a malformed ledger or seed list, or a spent seed: one line
        args = ap.parse_args(argv)
        spent = check_report_seeds(args.seeds, allow_spent=args.allow_spent_seeds, run="bench_nees")
    except ConfigError as e:
        print(f"bench_nees: error: {e}", file=sys.stderr)
        return 2
    if args.point_std_mm is not None and not (math.isfinite(args.point_std_mm) and args.point_std_mm >= 0):
        ap.error(f"--point-std-mm must be a finite number >= 0, got {args.point_std_mm}")
    point_std_m = None if args.point_std_mm is None else 1e-3 * args.point_std_mm
    seeds = args.seeds
    profiles = [p for p in args.profiles.split(",") if p]
    split = split_of(seeds)
    on = f"; ON SPENT SEEDS: {seed_ranges_text(spent)}, no fresh evidence" if spent else ""
    print(
        f"seeds {seeds[0]}..{seeds[-1]} ({len(seeds)}; {split} split{on}), {len(STARTS)} start poses, "
        f"{args.frames} frames each ({args.warmup} warm-up), profiles {', '.join(profiles)}"
    )
    models = load_box_models()
    dbs = {m.name: get_database(m.name, progress=False) for m in models}
    episodes: dict[str, list[dict]] = {p: [] for p in profiles}
    t0 = time.perf_counter()
    for seed in seeds:
        for i, base in enumerate(STARTS):
            model, start = models[(seed + i) % len(models)], jittered(base, seed, i)
            for p in profiles:  # side by side: the same scene under every profile
                e = run_episode(model, dbs[model.name], start, seed, p, args.frames, args.warmup, point_std_m)
                episodes[p].append(e)
                print(
                    f"  {p:<9} seed {seed} {start.name:<17} {model.name:<10} in band "
                    f"{e['in_band']}/{e['scored']}  above {e['above_band']}  {e['outcomes']}",
                    flush=True,
                )
    summary = {p: summarise(episodes[p]) for p in profiles}
    print_table(summary)
    print(f"wall time {time.perf_counter() - t0:.0f} s")
    result = {
        "seeds": seeds,
        "split": split,
        "on_spent_seeds": seed_ranges_text(spent) or None,
        "frames_per_episode": args.frames,
        "warmup": args.warmup,
        "point_std_m": point_std_m if point_std_m is not None else POINT_STD_M,
        "band": BAND,
        "starts": [asdict(s) for s in STARTS],
        "summary": summary,
        "episodes": episodes,
    }
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(result, indent=1))
        print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
