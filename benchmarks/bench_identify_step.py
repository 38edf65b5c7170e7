"""One perception step of the identification loop, before and after issue 7's speed-up, side by side.

Run (from the repository root)::

    nice .venv/bin/python benchmarks/bench_identify_step.py [--frames 24] [--repeats 3]

A frame sequence like an episode's start is rendered once (the box turning in front of the robot, 1.2 m
away, its shared faces first, then its unique face), and then perceived by two set-ups, alternately,
each with its own filter bank from the same seed:

* **before**: the left then the right image's SIFT in one thread; every model's frame searched twice,
  by the EKF's FLANN matcher and by the model scorer's exact search; OpenBLAS with its default threads;
* **before, 1 BLAS thread**: the same with OpenBLAS on one thread (what the thread setting alone does);
* **after**: the right image's SIFT in a second thread (``StereoParams.parallel``); one exact search per
  model and frame, shared by the matcher and the scorer (:func:`~lab.identification.observe_frame`);
  OpenBLAS on one thread (what ``lab`` sets at start-up, see ``lab.cli``).

It prints the median wall and CPU time (this process, all threads) per frame of the features
(``stereo_features``) and of the filters and probabilities (``observe_frame``), and the ratios. CPU time
is robust to other load on the machine; wall time is not (the load average is printed). Rendering is
the same for both and is timed once (two renders per frame at the camera's 320 x 240, without
supersampling, as in ``lab identify``).
"""

from __future__ import annotations

import argparse
import copy
import ctypes
import glob
import math
import os
import statistics
import time
from pathlib import Path

import numpy as np

from lab.estimation import EKFBank, EKFConfig, OrientationChart
from lab.geometry import Pose2D
from lab.identification import ModelScorer, ScoringConfig, observe_frame, uniform, z_turns
from lab.robot import StereoCamera
from lab.sim import SimRobot, SimWorld, load_box_models
from lab.training import get_database
from lab.vision import Matcher, stereo_features
from lab.vision.stereo import StereoParams


def _openblas_threads():
    """``set(n)`` for numpy's OpenBLAS, or None (the benchmark then says it could not switch)."""
    libs = glob.glob(str(Path(np.__file__).parent.parent / "numpy.libs" / "libscipy_openblas*.so"))
    for path in libs:
        lib = ctypes.CDLL(path)
        for name in ("scipy_openblas_set_num_threads64_", "openblas_set_num_threads"):
            f = getattr(lib, name, None)
            if f is not None:
                f.argtypes = [ctypes.c_int]
                return f
    return None


def _frames(n: int):
    models = load_box_models()
    out = []
    with SimWorld("arena") as w:
        carrier = w.add_carrier(models[1], Pose2D(0.0, 0.0, 0.0), box_yaw=0.0)
        robot = SimRobot(w, start=Pose2D(-1.2, 0.0, 0.0), seed=0)
        robot.enable()
        t_render = []
        for i in range(n):
            carrier.set_pose(Pose2D(0.0, 0.0, 0.0), box_yaw=math.radians(180.0 * i / max(1, n - 1)))
            t0 = time.perf_counter()
            frame = robot.capture_stereo()
            t_render.append(time.perf_counter() - t0)
            out.append(frame)
            robot.step(0.2)
        G_RC = robot.camera.G_RC(robot.pan_tilt().pan, robot.pan_tilt().tilt)
    return out, G_RC, statistics.median(t_render)


def _run(frames, G_RC, dbs, scorers, matchers, params, set_threads, blas_threads):
    if set_threads is not None:
        set_threads(blas_threads)
    bank = EKFBank(len(dbs), EKFConfig(chart=OrientationChart.ROTATION_VECTOR), rng=np.random.default_rng(0))
    P = uniform(len(dbs))
    rows = []
    for fr in frames:
        predicted = bank.predict(G_RC, G_RC, np.eye(4), 0.2)
        w0, c0 = time.perf_counter(), time.process_time()
        f = stereo_features(fr.left, fr.right, fr.camera, params, t=fr.t)
        w1, c1 = time.perf_counter(), time.process_time()
        P = observe_frame(P, f, bank, predicted, matchers, scorers, symmetries=z_turns(4)).belief.P
        w2, c2 = time.perf_counter(), time.process_time()
        rows.append((w1 - w0, c1 - c0, w2 - w1, c2 - c1))
    return np.array(rows), P


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=24)
    ap.add_argument("--repeats", type=int, default=3, help="alternating passes of each set-up")
    args = ap.parse_args(argv)
    frames, G_RC, render_s = _frames(args.frames)
    names = [m.name for m in load_box_models()]
    dbs = [get_database(n) for n in names]
    set_threads = _openblas_threads()
    default_threads = int(os.environ.get("OPENBLAS_NUM_THREADS", os.cpu_count() or 1))
    scorers = [
        ModelScorer(db, ScoringConfig().for_camera(StereoCamera.from_fov()))  # the simulated robot's
        for db in dbs
    ]
    setups = {
        # FLANN matchers on database copies: observe_frame shares a search only with the scorer of the
        # same database object, so these search themselves, as the loop did before
        "before": (
            scorers,
            [Matcher(copy.copy(db)) for db in dbs],
            StereoParams(parallel=False),
            default_threads,
        ),
        "before, 1 BLAS thread": (
            scorers,
            [Matcher(copy.copy(db)) for db in dbs],
            StereoParams(parallel=False),
            1,
        ),
        "after": (
            scorers,
            [Matcher(db, method="brute", k=s.k_neighbours) for db, s in zip(dbs, scorers, strict=True)],
            StereoParams(parallel=True),
            1,
        ),
    }
    results = {k: [] for k in setups}
    final = {}
    for _ in range(args.repeats):
        for name, (sc, mt, params, threads) in setups.items():
            rows, P = _run(frames, G_RC, dbs, sc, mt, params, set_threads, threads)
            results[name].append(rows)
            final[name] = P
    if set_threads is not None:
        set_threads(default_threads)
    print(f"{len(frames)} frames x {args.repeats} passes per set-up, load average {os.getloadavg()[0]:.1f}")
    if set_threads is None:
        print("(could not switch OpenBLAS threads in this process: both set-ups use the default)")
    print(f"rendering (both set-ups): {1e3 * render_s:.1f} ms per stereo frame (median)")
    med = {k: np.median(np.concatenate(v), axis=0) * 1e3 for k, v in results.items()}
    for k in med:  # perception = features + filters and probabilities
        med[k] = np.r_[med[k], med[k][0] + med[k][2], med[k][1] + med[k][3]]
    labels = (
        "features, wall",
        "features, CPU",
        "filters + probabilities, wall",
        "filters + probabilities, CPU",
        "perception, wall",
        "perception, CPU",
    )
    cols = list(setups)
    print(f"{'ms per frame (median)':30s}" + "".join(f"{c:>23s}" for c in cols) + f"{'after/before':>14s}")
    for j, label in enumerate(labels):
        vals = "".join(f"{med[c][j]:23.1f}" for c in cols)
        print(f"{label:30s}{vals}{med['after'][j] / med['before'][j]:14.2f}")
    print("final probabilities: " + ", ".join(f"{c} {np.round(final[c], 3)}" for c in cols))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
