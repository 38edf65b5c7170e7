"""``lab demo``: the main job a new user runs first.

Until the identification loop lands, the demo tours the simulator: it renders each box model of the
identification database from its unique and from a shared side, drives the robot into the lab room
while panning the head, and writes a report (Markdown + JSON + pictures) that says what it saw,
including the stereo depth error against the renderer's depth buffer.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from lab.geometry import Pose2D
from lab.io import write_json_atomic, write_text_atomic
from lab.robot import StereoCamera
from lab.sim import RenderSettings, SimRobot, SimWorld, load_box_models
from lab.viz import disparity_map, disparity_picture, save_rgb

__all__ = ["run_demo"]


def run_demo(out: Path, seed: int = 0, supersample: int = 1) -> Path:
    """Run the simulator tour and return the path of its Markdown report."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    cam = StereoCamera.from_fov(320, 240, 60.0, 0.12, mount_R=(0.0, 0.0, 0.7))
    settings = RenderSettings(supersample=supersample)
    lines = ["# lab demo: a tour of the simulator", ""]
    summary: dict = {"seed": seed, "supersample": supersample, "models": [], "room": {}}

    lines += [
        "## The box database (identification paper, Fig. 4)",
        "",
        "Each model seen from 1.2 m: its unique face, then a shared face.",
        "",
    ]
    for model in load_box_models():
        row = {"model": model.name}
        for side, yaw in (("unique", math.pi), ("shared", 0.0)):
            with SimWorld("box_database", settings) as world:
                world.add_carrier(model, Pose2D(0.0, 0.0, 0.0), box_yaw=yaw)
                robot = SimRobot(world, cam, start=Pose2D(-1.2, 0.0, 0.0), seed=seed)
                robot.enable()
                robot.command_pan_tilt(0.0, math.radians(-8))
                robot.wait_pan_tilt()
                frame = robot.capture_stereo()
                name = f"{model.name}_{side}.png"
                save_rgb(out / name, frame.left)
                # stereo depth against the renderer's depth buffer, on the box's pixels
                G_WC = world.truth.G_WC()
                seg = world.truth.segmentation(G_WC, cam)
                depth = world.truth.depth(G_WC, cam)
                box = seg == world.body_id("target")
                d = disparity_map(frame.left, frame.right)
                ok = box & np.isfinite(d)
                z_stereo = cam.fx * cam.baseline / d[ok]
                err = np.abs(z_stereo - depth[ok])
                row[side] = {
                    "image": name,
                    "box_pixels": int(box.sum()),
                    "dense_depth_error_median_m": float(np.median(err)) if err.size else None,
                }
                lines.append(f"![{model.name} {side}]({name})")
        summary["models"].append(row)
        lines.append("")

    lines += [
        "## The lab room (search paper)",
        "",
        "The robot drives 1.5 m into the room while the head pans left and right.",
        "",
    ]
    with SimWorld("lab_room", settings) as world:
        robot = SimRobot(world, cam, seed=seed)
        robot.enable()
        frames = []
        for k, pan_deg in enumerate((0, 40, -40)):
            robot.command_pan_tilt(math.radians(pan_deg), math.radians(-5))
            for _ in range(10):
                robot.drive(0.5, 0.0)
                robot.step(0.1)
            robot.drive(0.0, 0.0)
            robot.wait_pan_tilt()
            f = robot.capture_stereo()
            frames.append(f)
            save_rgb(out / f"room_{k}.png", f.left)
            save_rgb(out / f"room_{k}_disparity.png", disparity_picture(f.left, f.right))
            lines.append(f"![room view {k}](room_{k}.png) ![disparity {k}](room_{k}_disparity.png)")
        true = world.truth.robot_pose()
        odo = robot.odometry()
        summary["room"] = {
            "bodies": world.names,
            "true_pose": [true.x, true.y, true.theta],
            "odometry_pose": [odo.x, odo.y, odo.theta],
            "odometry_error_m": math.hypot(true.x - odo.x, true.y - odo.y),
            "collisions": world.truth.collisions,
            "sim_time_s": world.t,
        }
        lines += [
            "",
            f"True pose after the drive: x={true.x:.3f} m, y={true.y:.3f} m; odometry says "
            f"x={odo.x:.3f} m, y={odo.y:.3f} m (error {summary['room']['odometry_error_m'] * 100:.1f} cm); "
            f"collisions: {world.truth.collisions}.",
            "",
        ]
    summary["wall_time_s"] = time.perf_counter() - t0
    lines += ["## Numbers", "", "```json", json.dumps(summary, indent=2), "```", ""]
    write_json_atomic(out / "report.json", summary)
    report = out / "report.md"
    write_text_atomic(report, "\n".join(lines))
    return report
