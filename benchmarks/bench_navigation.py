"""The navigator's costmap update per stereo frame in the simulated lab room, and the stereo error by range.

Run from the repository root::

    python benchmarks/bench_navigation.py [--poses 6] [--repeats 3] [--no-accuracy]

Frames are rendered once (320 x 240, the robot's head tilted down 25 degrees, 7 pans from each of
``--poses`` seeded poses in the room); the render time is printed but not counted. Then each frame
goes through ``Navigator.observe`` (full-width, left-right checked StereoSGBM disparity, points to the
world frame, ground-plane fit, surface-area support, ``Costmap.integrate``) ``--repeats`` times on a
fresh navigator, and the stages are timed one by one the same way. Printed: the median and 90th
percentile [ms] of the whole update and of each stage, and of the planning that follows a frame while
driving (the inflated cost grid and an A* query across the room).

``--no-accuracy`` skips the last two tables: for every valid disparity pixel of plain StereoSGBM
(``disparity_map``) and of the navigator's full-width, left-right checked one (``checked_disparity``),
the error of the point's depth and of its position on the floor against the simulator's depth buffer,
by true depth: the measurement behind the navigator's 2 m ``max_range``.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

import numpy as np
from scipy import ndimage

from lab.geometry import Pose2D, transform_points
from lab.navigation import GridSpec, Navigator, astar, room_bounds
from lab.navigation.costmap import CellState
from lab.navigation.ground import GroundPlane, NoGroundPlane, fit_ground_plane
from lab.sim import SimRobot, SimWorld
from lab.vision.dense import checked_disparity, dense_points, disparity_map


def percentiles(ms: list[float]) -> str:
    ms = sorted(ms)
    return f"{statistics.median(ms):8.2f} {ms[int(0.9 * (len(ms) - 1))]:8.2f}"


def free_poses(world: SimWorld, n: int, rng: np.random.Generator) -> list[Pose2D]:
    """``n`` poses at least 0.6 m from every body (from the simulator's truth), random headings."""
    spec = GridSpec.from_bounds(-3.0, -4.0, 3.0, 4.0, 0.1)
    occ = world.truth.occupancy(spec, 0.0, 1.05)
    dist = ndimage.distance_transform_edt(~occ) * spec.resolution
    cells = np.argwhere(dist >= 0.6)
    picks = cells[rng.choice(len(cells), n, replace=False)]
    return [Pose2D(*spec.centers_of(c)[0], rng.uniform(-math.pi, math.pi)) for c in picks]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--poses", type=int, default=6)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-accuracy", action="store_true")
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)

    frames, depths, render_ms = [], [], []
    with SimWorld("lab_room") as w0:
        poses = free_poses(w0, args.poses, rng)
    for k, pose in enumerate(poses):
        with SimWorld("lab_room") as world:
            robot = SimRobot(world, start=pose, seed=k)
            robot.enable()
            nav = Navigator(robot, bounds=room_bounds(world.scene))
            for pan in nav.config.scan_pans:
                robot.command_pan_tilt(pan, nav.config.tilt)
                robot.wait_pan_tilt()
                t = time.perf_counter()
                frames.append(robot.capture_stereo())
                render_ms.append(1e3 * (time.perf_counter() - t))
                if not args.no_accuracy:
                    depths.append((world.truth.G_WC(), world.truth.depth(world.truth.G_WC(), robot.camera)))
            cfg = nav.config
    print(
        f"{len(frames)} frames of 320 x 240 from {args.poses} poses; stereo render (not counted) "
        f"median {statistics.median(render_ms):.1f} ms\n"
    )

    stages: dict[str, list[float]] = {
        k: []
        for k in (
            "dense points in W",
            "ground plane",
            "support + integrate",
            "observe (total)",
            "inflated grid",
            "A* across the room",
        )
    }
    with SimWorld("lab_room") as world:
        robot = SimRobot(world, start=poses[0])
        for _ in range(args.repeats):
            nav = Navigator(robot, bounds=room_bounds(world.scene))
            g = np.random.default_rng(0)
            for f in frames:
                t1 = time.perf_counter()
                P_C = dense_points(  # two StereoSGBM matchings (left and right) and the LR check
                    f.left, f.right, f.camera, cfg.pixel_step, cfg.max_range, checked=cfg.lr_check
                )
                G_WC = f.odom.G() @ f.G_RC
                P_W = transform_points(G_WC, P_C)
                t2 = time.perf_counter()
                try:
                    plane = fit_ground_plane(P_W[P_C[:, 2] <= cfg.ground_fit_range], g)
                except NoGroundPlane:  # a view of a wall: observe() keeps the previous plane
                    plane = nav.plane or GroundPlane.horizontal()
                t3 = time.perf_counter()
                keep = nav._supported(P_W, P_C[:, 2], plane, f.camera.fx)
                nav.costmap.integrate(P_W[keep], plane, sensor_origin_xy=(G_WC[0, 3], G_WC[1, 3]))
                t4 = time.perf_counter()
                nav.observe(f)
                t5 = time.perf_counter()
                grid = nav.planning_grid()
                t6 = time.perf_counter()
                astar(grid, (-2.0, -3.0), (2.0, 3.2))
                t7 = time.perf_counter()
                for key, dt in zip(
                    stages, (t2 - t1, t3 - t2, t4 - t3, t5 - t4, t6 - t5, t7 - t6), strict=True
                ):
                    stages[key].append(1e3 * dt)
    print(f"costmap update per stereo frame ({len(frames)} frames x {args.repeats}):")
    print(f"{'stage':>22} {'median ms':>9} {'p90 ms':>8}")
    for key, ms in stages.items():
        print(f"{key:>22} {percentiles(ms)}")
    print(
        f"(the A* query runs on the map of all {len(frames)} frames; "
        f"{int((nav.costmap.state != CellState.UNKNOWN).sum())} cells known)\n"
    )

    if args.no_accuracy:
        return
    cam = frames[0].camera
    fb = cam.fx * cam.baseline
    for name, matcher in (("disparity_map", disparity_map), ("checked_disparity", checked_disparity)):
        rows = []
        for f, (G_WC, D) in zip(frames, depths, strict=True):
            d = matcher(f.left, f.right)
            v, u = np.nonzero(np.isfinite(d))
            Z, Zt = fb / d[v, u], D[v, u]
            P = transform_points(G_WC, np.stack([(u - cam.cx) * Z / cam.fx, (v - cam.cy) * Z / cam.fy, Z], 1))
            Pt = transform_points(
                G_WC, np.stack([(u - cam.cx) * Zt / cam.fx, (v - cam.cy) * Zt / cam.fy, Zt], 1)
            )
            rows.append(np.stack([Zt, np.abs(Z - Zt), np.hypot(*(P[:, :2] - Pt[:, :2]).T)], 1))
        E = np.concatenate(rows)
        print(f"dense stereo error against the depth buffer, by true depth Z ({name}):")
        print(
            f"{'Z [m]':>9} {'points':>8} {'|dZ| p50 cm':>11} {'|dZ| p90 cm':>11} {'floor p90 cm':>12} "
            f"{'gross > 0.2 m':>13}"
        )
        for lo in np.arange(0.5, 4.5, 0.5):
            m = (E[:, 0] >= lo) & (E[:, 0] < lo + 0.5)
            if m.sum() < 100:
                continue
            e = E[m]
            print(
                f"{lo:4.1f}-{lo + 0.5:3.1f} {m.sum():8d} {100 * np.median(e[:, 1]):11.1f} "
                f"{100 * np.percentile(e[:, 1], 90):11.1f} {100 * np.percentile(e[:, 2], 90):12.1f} "
                f"{100 * np.mean(e[:, 1] > 0.2):12.1f}%"
            )
        print()


if __name__ == "__main__":
    main()
