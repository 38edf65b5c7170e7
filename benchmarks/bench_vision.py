"""Stereo 3D SIFT extraction plus matching against the 4 box databases at 320x240.

Run: .venv/bin/python benchmarks/bench_vision.py [--repeats N]
Prints the median ms per frame of each stage and the share of the frame spent in SIFT, side by side
for FLANN and exact (brute-force) matching, in one run. Rendering is not included.

OpenBLAS runs on one thread, as under the `lab` command (``lab.cli._one_blas_thread``), unless
``OPENBLAS_NUM_THREADS`` is set: on a loaded 2-core machine its spinning worker threads made the
frame 154 ms (FLANN) and 192 ms (exact) against 93 ms and 89 ms with one thread.
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy is imported; see the docstring

import argparse  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from lab.geometry import Pose2D  # noqa: E402
from lab.robot import StereoCamera  # noqa: E402
from lab.sim import SimWorld, load_box_models, viewpoint_G_WC  # noqa: E402
from lab.training.databases import get_database
from lab.vision.matching import Matcher
from lab.vision.stereo import StereoParams, _epipolar_matches, stereo_features  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=20)
    args = ap.parse_args()
    cam = StereoCamera.from_fov(320, 240, 60.0, 0.12)
    dbs = [get_database(m.name) for m in load_box_models()]
    pairs = []
    with SimWorld("box_database") as w:
        w.add_carrier(load_box_models()[1], Pose2D(0, 0, 0), box_yaw=0.4)
        for a in np.linspace(0, 2 * np.pi, 5, endpoint=False):
            pairs.append(w.render_stereo(viewpoint_G_WC((np.cos(a), np.sin(a), 0.7), (0, 0, 0.49)), cam))
    print(f"OPENBLAS_NUM_THREADS={os.environ['OPENBLAS_NUM_THREADS']}")
    params = StereoParams()
    det = cv2.SIFT_create(contrastThreshold=params.contrast_threshold)
    for method in ("flann", "brute"):
        matchers = [Matcher(db, method=method) for db in dbs]
        t_sift, t_stereo, t_match, n_feat = [], [], [], []
        for r in range(args.repeats):
            left, right = pairs[r % len(pairs)]
            t0 = time.perf_counter()
            gl, gr = cv2.cvtColor(left, cv2.COLOR_RGB2GRAY), cv2.cvtColor(right, cv2.COLOR_RGB2GRAY)
            kl, dl = det.detectAndCompute(gl, None)
            kr, dr = det.detectAndCompute(gr, None)
            t1 = time.perf_counter()
            _epipolar_matches(kl, dl, kr, dr, params)
            f = stereo_features(left, right, cam, params, detector=det)  # the whole stage, for the count
            t2 = time.perf_counter()
            for m in matchers:
                m.match(f)
            t3 = time.perf_counter()
            t_sift.append((t1 - t0) * 1e3)
            t_stereo.append((t2 - t1) * 1e3 - (t1 - t0) * 1e3)  # stereo_features repeats SIFT: subtract it
            t_match.append((t3 - t2) * 1e3)
            n_feat.append(len(f))
        sift_ms, stereo_ms, match_ms = (statistics.median(x) for x in (t_sift, t_stereo, t_match))
        total = sift_ms + stereo_ms + match_ms
        print(
            f"{method:5s}: SIFT x2 {sift_ms:6.1f} ms | epipolar match+triangulate {stereo_ms:5.1f} ms | "
            f"match 4 databases {match_ms:5.1f} ms | frame {total:6.1f} ms | "
            f"SIFT share {sift_ms / total:.0%} | "
            f"{statistics.median(n_feat):.0f} features"
        )


if __name__ == "__main__":
    main()
