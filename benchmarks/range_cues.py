"""Where a poster's fitted range comes from: the apparent size (the focal lengths) or the disparity
(the focal length and the baseline) (docs/tuning/localizer-range-scale.md, issue 52).

    nice .venv/bin/python benchmarks/range_cues.py --sensing FILE --seed 7

The robot stands at (0, 0) in the lab room and turns its head through nine views. Every poster the
localizer's observer fits is compared with the truth along the line of sight, three times:

* through the nominal camera the robot reports;
* through the episode's true camera (the renderer's drawn focal lengths and baseline);
* through the nominal camera with its focal lengths divided by one minus the drawn mean focal error,
  which is what the localizer's range scale does to its frames (``lab.localization.robot._rescaled``).

It prints the two cues' predictions and the median range error of each. The truth is read for scoring
only. Tuning seeds only.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import replace

import numpy as np

from lab.geometry import Pose2D
from lab.localization import LocalizedRobot, measurement_model
from lab.localization.robot import _rescaled
from lab.runs.robots import make_robot
from lab.sim import SimWorld
from lab.training.landmarks import landmark_map_from_scene, trained_landmark_map

PANS_DEG = (-150, -110, -70, -30, 0, 30, 70, 110, 150)


def range_errors(sensing: str, seed: int) -> None:
    """Print the cues' predictions and the fitted ranges' errors [%] through the three cameras."""
    landmarks = trained_landmark_map("lab_room", progress=False)
    true = {lm.name: lm for lm in landmark_map_from_scene("lab_room")}
    with (
        SimWorld("lab_room") as w,
        make_robot(world=w, seed=seed, sensing=sensing, start=Pose2D(0, 0, 1.4)) as run,
    ):
        base = run.robot
        base.enable()
        drawn, nominal = base.truth.sensing.camera.render_camera, base.camera
        size = -((drawn.fx / nominal.fx - 1) + (drawn.fy / nominal.fy - 1)) / 2  # the apparent size's cue
        disparity = nominal.fx * nominal.baseline / (drawn.fx * drawn.baseline) - 1
        cameras = {
            "nominal": nominal,
            "true (drawn)": replace(nominal, fx=drawn.fx, fy=drawn.fy, baseline=drawn.baseline),
            "focal lengths rescaled by the size cue": _rescaled(nominal, size, 1.0),
        }
        observer = LocalizedRobot(base, "landmarks", landmarks, log=lambda m: None).observer
        errors = {k: [] for k in cameras}
        for pan in np.radians(PANS_DEG):
            base.command_pan_tilt(float(pan), 0.0)
            base.wait_pan_tilt()
            frame = base.capture_stereo(after=base.now() + 0.3)
            p = base.truth.pose()
            x = np.array([p.x, p.y, p.theta])
            for label, camera in cameras.items():
                f = replace(frame, camera=camera)
                for obs in observer.observe(f, observer.candidates(x, f)):
                    t = true[obs.landmark.name]
                    zt = measurement_model(x, [t.centre_W[0], t.centre_W[1], t.yaw])
                    r = math.hypot(zt[0], zt[1])
                    errors[label].append(100 * float((np.asarray(obs.z[:2]) - zt[:2]) @ zt[:2]) / (r * r))
    print(
        f"{sensing}, seed {seed}: the apparent size predicts {100 * size:+.2f} %, "
        f"the disparity {100 * disparity:+.2f} %"
    )
    for label, v in errors.items():
        print(f"  {label:40s} median {np.median(v):+.2f} %, mean {np.mean(v):+.2f} % ({len(v)} fits)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sensing", default="realistic", help="a profile or a sensing file")
    ap.add_argument("--seed", type=int, default=7, help="a tuning seed (< 1000)")
    a = ap.parse_args()
    if a.seed >= 1000:
        raise SystemExit("range_cues: tuning seeds only (< 1000)")
    range_errors(a.sensing, a.seed)


if __name__ == "__main__":
    main()
