"""The whole perception step of the identification loop, on an episode's rendered frames, stage by stage.

Run (from the repository root)::

    nice .venv/bin/python benchmarks/bench_perception.py [--model 2] [--seed 0] [--sensing realistic]
        [--max-time 40] [--repeats 2] [--bank-steps 600] [--json FILE]

1. **An episode is recorded** (``lab identify``'s run: the evasive mover, the lut planner, the sensing
   profile, ``realistic`` by default), keeping every stereo frame the agent captured: the frames are
   rendered once, there, and rendering is left out of everything timed below (its median is printed).
2. **The frames are replayed** through fresh agents built with the episode's seed, ``--repeats`` passes,
   two replays a pass, alternately:

   * **step**: the agent's own perception step (``IdentificationAgent._perceive``: the bank's
     prediction, the region of interest while tracking, the stereo features with the right image's
     SIFT in a second thread, every model's database search, EKF update and Eq. (9) score, the turn
     keyframes), timed whole, wall and CPU;
   * **stages**: the same step cut into stages, each timed on its own (SIFT of the left and of the
     right image one after the other, epipolar matching and triangulation, the database searches and
     ratio tests, the EKF bank, the model probabilities, the turn keyframes);
   * **full frame**: the step of an agent with the region of interest off (``AgentConfig(roi=False)``),
     every frame extracted whole.

   The first two must reproduce the episode's model probabilities at every frame (printed: the largest
   difference); they are the same computation as the closed loop's. The whole-frame agent's
   probabilities are printed against the episode's (they differ by what the region drops and adds).
3. **The EKF bank against filterpy**: 4 filters (the papers' Euler chart, no gate, each from its own
   start) against 4 filterpy ``ExtendedKalmanFilter`` on the same synthetic frames
   (:func:`lab.estimation.synthetic.rocking_robot_frames`, 50 matched features), timed round robin;
   their states are printed side by side (the tests hold them equal to 1e-9).

Medians and 90th percentiles in ms; the step rate is 1000 / the median step. "While tracking" counts
the frames with at least one filter's estimate before the frame and the track not lost (the region is
used on those, unless it would cover most of the image: the share is printed); the full-frame step is
the whole-frame agent's, over every frame.
The machine is shared: the load average is printed at the start and the end; ratios measured side by
side (round robin) are the robust figures. ``--json FILE`` writes them all (``perception_step_ms_median``,
``full_frame_step_ms_median``, ``bank_ms_median``, ``filterpy_bank_ms_median``, ``sensing``, ...).

OpenBLAS runs on one thread, as under the ``lab`` command, unless ``OPENBLAS_NUM_THREADS`` is set.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy is imported, as lab.cli does

import argparse  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from lab.estimation import UpdateOutcome  # noqa: E402
from lab.geometry import relative_pose2d  # noqa: E402
from lab.identification.agent import IdentificationAgent  # noqa: E402
from lab.identification.belief import calc_current_entropy  # noqa: E402
from lab.identification.loop_config import AgentConfig  # noqa: E402
from lab.identification.scoring import state_for_scoring  # noqa: E402
from lab.identification.step import _shared  # noqa: E402
from lab.io import write_json_atomic  # noqa: E402
from lab.vision import Features3D  # noqa: E402
from lab.vision.stereo import (  # noqa: E402
    _check_pair,
    _detect_uv,
    _epipolar_matches,
    _grey,
    _in_disparities,
    _roi_rects,
    sift,
    triangulate,
    triangulation_covariance,
)

STAGES = (
    "predict",
    "sift_left",
    "sift_right",
    "stereo_match_triangulate",
    "database_search",
    "ekf_bank_updates",
    "model_probabilities",
    "turn_keyframes",
)


def record_episode(model: int, seed: int, sensing: str, max_time_s: float):
    """Run one episode and keep its frames: ``(frames, posteriors, render_s, result)``."""
    from lab.runs.identify import run_identify

    frames, render_s, agents = [], [], []

    def attach(agent, carrier):
        agents.append(agent)
        robot = agent.robot
        capture = robot.capture_stereo

        def recording_capture(*a, **k):
            t0 = time.perf_counter()
            frame = capture(*a, **k)
            render_s.append(time.perf_counter() - t0)
            frames.append(frame)
            return frame

        robot.capture_stereo = recording_capture

    result = run_identify(
        model, seed=seed, mover="evasive", planner="lut", figures=False, attach=attach,
        max_time_s=max_time_s, sensing=sensing,
    )  # fmt: skip
    return frames, [s.posterior for s in agents[0].steps], render_s, result


class _Robot:
    """What the agent's constructor reads of a robot (the replay never drives)."""

    def __init__(self, camera):
        from lab.robot import BaseLimits, PanTiltLimits

        self.camera, self.pan_tilt_limits, self.base_limits = camera, PanTiltLimits(), BaseLimits()


def fresh_agent(frames, dbs, seed: int, roi: bool = True) -> IdentificationAgent:
    """An agent as the episode's (same databases, seed and scoring); its planner is never asked. With
    ``roi`` False it extracts every frame whole."""
    config = AgentConfig(roi=roi)
    return IdentificationAgent(_Robot(frames[0].camera), dbs, None, config, planner="random", seed=seed)


def _now() -> tuple[float, float]:
    return time.perf_counter(), time.process_time()


def staged_perceive(agent: IdentificationAgent, frame, det) -> np.ndarray:
    """``agent._perceive(frame)`` cut into :data:`STAGES`, each timed: (stages, 2) seconds, wall and CPU."""
    params = agent.stereo
    marks = [_now()]
    prev = agent._prev
    if prev is not None:
        agent.bank.predict(prev.G_RC, frame.G_RC, relative_pose2d(prev.odom, frame.odom), frame.t - prev.t)
    agent._prev = frame
    predicted = agent.bank.estimates
    agent.last_roi = roi = agent.region_of_interest(predicted, frame.camera)  # the region, or None
    marks.append(_now())
    # stereo_features, the right image after the left, each in its rectangle (None: whole)
    _check_pair(frame.left, frame.right, frame.camera)
    gl, gr = _grey(frame.left), _grey(frame.right)
    rects = (None, None) if roi is None else _roi_rects(roi, frame.camera, params)
    pts_l, des_l = _detect_uv(gl, rects[0], det, params.roi_pad_px)
    marks.append(_now())
    pts_r, des_r = _detect_uv(gr, rects[1], det, params.roi_pad_px)
    marks.append(_now())
    f = Features3D.empty(frame.t)
    if des_l is not None and des_r is not None:
        il, ir = _epipolar_matches(pts_l, des_l, pts_r, des_r, params)
        uv_l, uv_r = pts_l[il], pts_r[ir]
        disp = uv_l[:, 0] - uv_r[:, 0]
        keep = _in_disparities(roi, disp)
        if keep is not None:
            il, uv_l, uv_r, disp = il[keep], uv_l[keep], uv_r[keep], disp[keep]
        if len(il):
            cov = triangulation_covariance(uv_l, disp, frame.camera, params)
            pts = triangulate(uv_l, uv_r, frame.camera)
            f = Features3D(pts, des_l[il].astype(np.float32), uv_l, disp, cov, frame.t)
    marks.append(_now())
    # observe_frame, stage by stage
    searched = zip(agent.matchers, agent.scorers, strict=True)
    pairs = [m.match(f, _shared(m, s, f)).pairs(f, s.db) for m, s in searched]
    marks.append(_now())
    updates = agent.bank.update_all(pairs)
    marks.append(_now())
    states = [state_for_scoring(p, u) for p, u in zip(predicted, updates, strict=True)]
    belief = calc_current_entropy(agent.P, f, agent.scorers, states, agent.scoring, agent.turns)
    marks.append(_now())
    agent.P = belief.P
    if any(u.outcome is not UpdateOutcome.SKIPPED for u in updates):
        agent._last_seen_t = frame.t
    agent._follow_reinitialised_filters(predicted, updates)
    agent._keyframe(frame, f)
    agent._note_decisive_turn(belief)
    marks.append(_now())
    return np.diff(np.array(marks), axis=0)


def replay(frames, posteriors, dbs, seed: int, repeats: int):
    """The replays, in turn, ``repeats`` passes: the agent's step (with its region of interest), the
    staged step, and the step of an agent that extracts every frame whole; per-frame timings and the
    probabilities' check (the first two must reproduce the episode's; the whole-frame agent's may
    differ, by how much is returned)."""
    det = sift()
    keys = ("wall", "cpu", "tracking", "roi", "n_feat", "full_wall", "full_cpu", "full_n_feat")
    out = {k: [] for k in keys}
    stages = []
    worst = worst_full = 0.0
    for _ in range(repeats):
        a = fresh_agent(frames, dbs, seed)
        for k, fr in enumerate(frames):
            tracking_k = any(f.initialized for f in a.bank.filters) and not a._lost  # a track before it
            w0, c0 = time.perf_counter(), time.process_time()
            f, _ = a._perceive(fr)
            out["wall"].append(time.perf_counter() - w0)
            out["cpu"].append(time.process_time() - c0)
            a._check_track(fr)  # the loop's, after the step: lost or not for the next frame's region
            out["tracking"].append(tracking_k)
            out["roi"].append(a.last_roi is not None)
            out["n_feat"].append(len(f))
            worst = max(worst, float(np.abs(a.P - posteriors[k]).max()))
        b = fresh_agent(frames, dbs, seed)
        for k, fr in enumerate(frames):
            stages.append(staged_perceive(b, fr, det))
            b._check_track(fr)
            worst = max(worst, float(np.abs(b.P - posteriors[k]).max()))
        c = fresh_agent(frames, dbs, seed, roi=False)
        for k, fr in enumerate(frames):
            w0, c0 = time.perf_counter(), time.process_time()
            f, _ = c._perceive(fr)
            out["full_wall"].append(time.perf_counter() - w0)
            out["full_cpu"].append(time.process_time() - c0)
            c._check_track(fr)
            out["full_n_feat"].append(len(f))
            worst_full = max(worst_full, float(np.abs(c.P - posteriors[k]).max()))
    out = {k: np.array(v) for k, v in out.items()}
    for k in ("wall", "cpu", "full_wall", "full_cpu"):
        out[k] = out[k] * 1e3
    out["full_final_P"] = c.P.copy()
    return out, np.array(stages) * 1e3, worst, worst_full


def bank_against_filterpy(n_steps: int, n_features: int = 50):
    """Median ms of predict + 4 updates: the EKF bank (Euler chart, no gate) and 4 filterpy EKFs on the
    same frames, round robin; and the largest state difference at the end."""
    from filterpy.kalman import ExtendedKalmanFilter

    from lab.estimation import (
        EKFBank,
        EKFConfig,
        GateConfig,
        measurement_covariance,
        measurement_jacobian,
        measurement_model,
        motion_jacobian,
        motion_model,
        process_noise_covariance,
    )
    from lab.estimation.synthetic import rocking_robot_frames

    _, frames = rocking_robot_frames(n_steps, n_features)
    X0 = np.array([0.05, 0.02, 1.1, 0.6, -0.4, 1.8])
    starts = [X0 + 0.01 * np.array([i, -i, i, 0.5 * i, -0.5 * i, 0.5 * i]) for i in range(4)]
    Sigma0 = np.diag([0.01] * 3 + [0.02] * 3) ** 2
    dt = 0.1
    config = EKFConfig(gate=GateConfig(dist_max_m=np.inf, gate_prob=None))
    bank = EKFBank(4, config, rng=np.random.default_rng(0))
    for f, x in zip(bank.filters, starts, strict=True):
        f.initialize(x, Sigma0)

    class FP(ExtendedKalmanFilter):
        def predict_x(self, u=0):
            self.x = motion_model(self.x[:, 0], *u)[:, None]

    fps = []
    for x in starts:
        fp = FP(6, 3)
        fp.x, fp.P = x[:, None].copy(), Sigma0.copy()
        fps.append(fp)
    noise = config.process

    def banked(fr):
        bank.predict(fr[0], fr[1], fr[2], dt)
        bank.update_all([fr[3:6]] * 4)

    def filterpy_step(fr):
        u = fr[:3]
        R = measurement_covariance(fr[5])
        for fp in fps:
            fp.F = motion_jacobian(fp.x[:, 0], *u)
            fp.Q = process_noise_covariance(motion_model(fp.x[:, 0], *u), fr[1], fr[2], dt, noise)
            fp.predict(u=u)
            fp.update(
                fr[3].reshape(-1, 1),
                lambda x, b: measurement_jacobian(x[:, 0], b),
                lambda x, b: measurement_model(x[:, 0], b).reshape(-1, 1),
                R=R,
                args=fr[4],
                hx_args=fr[4],
            )

    times = np.zeros((len(frames), 2))
    for k, fr in enumerate(frames):
        for j, step in enumerate((banked, filterpy_step)):
            t0 = time.perf_counter()
            step(fr)
            times[k, j] = time.perf_counter() - t0
    times = times[20:] * 1e3  # warm-up
    diff = max(float(np.abs(f.mu - fp.x[:, 0]).max()) for f, fp in zip(bank.filters, fps, strict=True))
    diff_P = max(float(np.abs(f.P - fp.P).max()) for f, fp in zip(bank.filters, fps, strict=True))
    ratio = np.median(times[:, 1] / times[:, 0])
    return np.median(times, axis=0), np.percentile(times, 90, axis=0), ratio, diff, diff_P


def _p90(x) -> float:
    return float(np.percentile(x, 90)) if len(x) else float("nan")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", type=int, default=2, help="the true box, 0..3")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--sensing", default="realistic", help="the simulator's sensing profile")
    ap.add_argument("--max-time", type=float, default=40.0, help="simulated seconds of the episode at most")
    ap.add_argument("--repeats", type=int, default=2, help="replay passes")
    ap.add_argument("--bank-steps", type=int, default=600, help="synthetic frames of the bank comparison")
    ap.add_argument("--json", type=Path, default=None, help="write the figures there")
    args = ap.parse_args(argv)
    from lab.training import get_database

    load0 = os.getloadavg()[0]
    frames, posteriors, render_s, result = record_episode(args.model, args.seed, args.sensing, args.max_time)
    dbs = [get_database(name) for name in ("M0", "M1", "M2", "M3")]
    r, stages, worst, worst_full = replay(frames, posteriors, dbs, args.seed, args.repeats)
    wall, cpu, tracking, n_feat = r["wall"], r["cpu"], r["tracking"], r["n_feat"]
    bank_med, bank_p90, bank_ratio, bank_diff, bank_diff_P = bank_against_filterpy(args.bank_steps)
    load1 = os.getloadavg()[0]

    trk = wall[tracking]
    step_med = float(np.median(trk))
    print(
        f"episode: true model {args.model}, seed {args.seed}, sensing {result['sensing']}, "
        f"{len(frames)} frames ({result['sim_time_s']:.1f} s simulated), identified "
        f"{result['identified_model']}; {args.repeats} replay passes; load average {load0:.1f} -> {load1:.1f}"
    )
    print(f"rendering (excluded): {1e3 * np.median(render_s):.1f} ms per stereo frame (median)")
    print(f"replays reproduce the episode's probabilities: largest difference {worst:.1e}")
    print(
        f"whole-frame agent's probabilities against the episode's (region of interest off): largest "
        f"difference {worst_full:.2g}, final {np.array2string(r['full_final_P'], precision=3)} against "
        f"{np.array2string(posteriors[-1], precision=3)}"
    )
    print(
        f"features per frame, tracking: median {np.median(n_feat[tracking]):.0f} with the region, "
        f"{np.median(r['full_n_feat'][tracking]):.0f} whole; region used on "
        f"{np.mean(r['roi'][tracking]):.0%} of the tracking frames"
    )
    print(f"{'ms per frame':34s}{'median':>9s}{'p90':>9s}{'CPU med':>9s}")
    ctrk = cpu[tracking]
    print(f"{'perception step (tracking)':34s}{step_med:9.1f}{_p90(trk):9.1f}{np.median(ctrk):9.1f}")
    fw, fc = r["full_wall"], r["full_cpu"]
    print(f"{'full-frame step (all frames)':34s}{np.median(fw):9.1f}{_p90(fw):9.1f}{np.median(fc):9.1f}")
    st_trk = stages[tracking]
    for j, name in enumerate(STAGES):
        w, c = st_trk[:, j, 0], st_trk[:, j, 1]
        print(f"{'  ' + name:34s}{np.median(w):9.1f}{_p90(w):9.1f}{np.median(c):9.1f}")
    tot_w, tot_c = st_trk.sum(axis=1).T
    print(f"{'  sum of the stages':34s}{np.median(tot_w):9.1f}{_p90(tot_w):9.1f}{np.median(tot_c):9.1f}")
    print(f"step rate (tracking): {1e3 / step_med:.1f} Hz (the camera's: 48 Hz)")
    print(
        f"EKF bank of 4 (Euler, no gate), predict + 4 updates, {args.bank_steps} synthetic frames: "
        f"{bank_med[0]:.2f} ms; 4 filterpy EKFs: {bank_med[1]:.2f} ms; filterpy / bank "
        f"{bank_ratio:.2f}x (median of the per-frame ratios); final state difference {bank_diff:.1e}, "
        f"covariance {bank_diff_P:.1e}"
    )
    if args.json is not None:
        out = {
            "sensing": result["sensing"],
            "true_model": args.model,
            "seed": args.seed,
            "frames": len(frames),
            "repeats": args.repeats,
            "load_average": [load0, load1],
            "render_ms_median": 1e3 * float(np.median(render_s)),
            "probabilities_max_difference": worst,
            "full_frame_probabilities_max_difference": worst_full,
            "features_median": float(np.median(n_feat)),
            "features_tracking_median": float(np.median(n_feat[tracking])),
            "full_frame_features_median": float(np.median(r["full_n_feat"])),
            "full_frame_features_tracking_median": float(np.median(r["full_n_feat"][tracking])),
            "roi_fraction_of_tracking_frames": float(np.mean(r["roi"][tracking])),
            "perception_step_ms_median": step_med,
            "perception_step_ms_p90": _p90(trk),
            "perception_step_cpu_ms_median": float(np.median(cpu[tracking])),
            "full_frame_step_ms_median": float(np.median(fw)),
            "full_frame_step_ms_p90": _p90(fw),
            "full_frame_step_cpu_ms_median": float(np.median(fc)),
            "step_rate_hz": 1e3 / step_med,
            "stages_ms_median": {s: float(np.median(st_trk[:, j, 0])) for j, s in enumerate(STAGES)},
            "stages_ms_p90": {s: _p90(st_trk[:, j, 0]) for j, s in enumerate(STAGES)},
            "stages_cpu_ms_median": {s: float(np.median(st_trk[:, j, 1])) for j, s in enumerate(STAGES)},
            "bank_ms_median": float(bank_med[0]),
            "bank_ms_p90": float(bank_p90[0]),
            "filterpy_bank_ms_median": float(bank_med[1]),
            "filterpy_bank_ms_p90": float(bank_p90[1]),
            "filterpy_over_bank": float(bank_ratio),
            "bank_state_max_difference": bank_diff,
        }
        write_json_atomic(args.json, out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
