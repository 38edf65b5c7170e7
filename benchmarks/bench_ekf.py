"""Median time of one EKF step (predict + update with 50 matched features): a single filter, a bank
of 4 models, and filterpy's dense ExtendedKalmanFilter on the same data for scale.

    python benchmarks/bench_ekf.py [--steps N] [--features N]

Frames are generated before timing (synthetic cube, stereo-like noise, robot and pan-tilt moving a
little every step), so only the filter is timed. Prints medians in microseconds.

OpenBLAS runs on one thread, as under the `lab` command (``lab.cli._one_blas_thread``), unless
``OPENBLAS_NUM_THREADS`` is set: its spinning worker threads made the bank of 4 6.8x a single filter
(and filterpy 9x) on a loaded 2-core machine, against 3.6x (1.5x) with one thread.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy is imported; see the docstring

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from filterpy.kalman import ExtendedKalmanFilter  # noqa: E402

from lab.estimation import (  # noqa: E402
    EKFBank,
    EKFConfig,
    GateConfig,
    OrientationChart,
    PoseEKF,
    measurement_covariance,
    measurement_jacobian,
    measurement_model,
    motion_jacobian,
    motion_model,
    process_noise_covariance,
)
from lab.estimation.synthetic import rocking_robot_frames  # noqa: E402


def median_us(steps, frames, warmup=20):
    """Median time [us] of each step function over the frames, timed round-robin (frame by frame, every
    function in turn) so that load from other processes hits them all alike."""
    times = np.zeros((len(frames), len(steps)))
    for i, fr in enumerate(frames):
        for j, step in enumerate(steps):
            t0 = time.perf_counter_ns()
            step(fr)
            times[i, j] = time.perf_counter_ns() - t0
    return np.median(times[warmup:], axis=0) / 1e3


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--features", type=int, default=50)
    args = ap.parse_args()
    X0 = np.array([0.05, 0.02, 1.1, 0.6, -0.4, 1.8])
    _, frames = rocking_robot_frames(args.steps, args.features)
    Sigma0 = np.diag([0.01] * 3 + [0.02] * 3) ** 2
    dt = 0.1

    ekf = PoseEKF(rng=np.random.default_rng(0))
    ekf.initialize(X0, Sigma0)

    def one(fr):
        ekf.predict(fr[0], fr[1], fr[2], dt)
        ekf.update(fr[3], fr[4], fr[5])

    bank = EKFBank(4, rng=np.random.default_rng(0))
    for f in bank.filters:
        f.initialize(X0, Sigma0)

    def banked(fr):
        bank.predict(fr[0], fr[1], fr[2], dt)
        for i in range(len(bank)):
            bank.update(i, fr[3], fr[4], fr[5])

    no_gate = PoseEKF(
        EKFConfig(gate=GateConfig(dist_max_m=np.inf, gate_prob=None)), rng=np.random.default_rng(0)
    )
    no_gate.initialize(X0, Sigma0)

    def ungated(fr):
        no_gate.predict(fr[0], fr[1], fr[2], dt)
        no_gate.update(fr[3], fr[4], fr[5])

    rv = PoseEKF(EKFConfig(chart=OrientationChart.ROTATION_VECTOR), rng=np.random.default_rng(0))
    rv.initialize(X0, Sigma0)

    def rotvec(fr):
        rv.predict(fr[0], fr[1], fr[2], dt)
        rv.update(fr[3], fr[4], fr[5])

    class FP(ExtendedKalmanFilter):
        def predict_x(self, u=0):
            self.x = motion_model(self.x[:, 0], *u)[:, None]

    fp = FP(6, 3)
    fp.x, fp.P = X0[:, None].copy(), Sigma0.copy()
    noise = EKFConfig().process

    def filterpy_step(fr):
        u = fr[:3]
        fp.F = motion_jacobian(fp.x[:, 0], *u)
        fp.Q = process_noise_covariance(motion_model(fp.x[:, 0], *u), fr[1], fr[2], dt, noise)
        fp.predict(u=u)
        fp.update(
            fr[3].reshape(-1, 1),
            lambda x, b: measurement_jacobian(x[:, 0], b),
            lambda x, b: measurement_model(x[:, 0], b).reshape(-1, 1),
            R=measurement_covariance(fr[5]),
            args=fr[4],
            hx_args=fr[4],
        )

    names = [
        "PoseEKF, predict + update (gated)",
        "PoseEKF, predict + update (no gate)",
        "PoseEKF rotation-vector chart (gated)",
        "EKFBank of 4, predict + 4 updates",
        "filterpy EKF (dense S, inv), same step",
    ]
    rows = list(zip(names, median_us([one, ungated, rotvec, banked, filterpy_step], frames), strict=True))
    print(
        f"median over {args.steps - 20} steps, {args.features} matched features per update, "
        f"OPENBLAS_NUM_THREADS={os.environ['OPENBLAS_NUM_THREADS']}"
    )
    for name, us in rows:
        print(f"  {name:<42s} {us:9.1f} us")
    print(f"  bank of 4 / single filter: {rows[3][1] / rows[0][1]:.2f}x")
    print(f"  filterpy / PoseEKF (both ungated): {rows[4][1] / rows[1][1]:.2f}x")
    print(
        f"  final state difference PoseEKF (no gate) vs filterpy: {np.abs(no_gate.mu - fp.x[:, 0]).max():.1e}"
    )
    assert (
        ekf.divergence is None and rv.divergence is None and all(f.divergence is None for f in bank.filters)
    )


if __name__ == "__main__":
    main()
