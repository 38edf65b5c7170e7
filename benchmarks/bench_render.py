"""Median stereo render time (both images) in the lab room, TinyRenderer, headless.

Run: .venv/bin/python benchmarks/bench_render.py [--repeats N]
Prints medians side by side in one run: 320x240 and 640x480, at 1x and 2x supersampling.
"""

import argparse
import statistics
import time

from lab.robot import StereoCamera
from lab.sim import RenderSettings, SimWorld, viewpoint_G_WC


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=15)
    args = ap.parse_args()
    G_WC = viewpoint_G_WC((0.0, -3.0, 0.7), (0.5, 0.0, 0.6))
    print(f"{'size':>9} {'supersample':>11} {'stereo pair median ms':>22} {'p90 ms':>8}")
    for w, h in ((320, 240), (640, 480)):
        cam = StereoCamera.from_fov(w, h, 60.0, 0.12)
        for ss in (1, 2):
            with SimWorld("lab_room", RenderSettings(supersample=ss)) as world:
                world.render_stereo(G_WC, cam)  # warm-up (texture upload)
                times = []
                for _ in range(args.repeats):
                    t = time.perf_counter()
                    world.render_stereo(G_WC, cam)
                    times.append((time.perf_counter() - t) * 1e3)
            times.sort()
            p90 = times[int(0.9 * (len(times) - 1))]
            print(f"{w}x{h:<5} {ss:>11} {statistics.median(times):>22.1f} {p90:>8.1f}")


if __name__ == "__main__":
    main()
