"""How many stands a survey tour needs: the refined posters' shape error for tours of 1, 2, 3 stands per
poster, in a synthetic lab room.

Run from the repository root::

    python benchmarks/survey_tour_design.py [--sensing FILE|realistic] [--error-scale 1] [--draws 12]
        [--covers 1,2,3] [--passes 2] [--fit 2,3]

Each draw surveys the lab room's posters as the simulator does (:func:`lab.sim.room_errors.survey_error`:
the profile's survey sigma times its mismatch and ``--error-scale``, episode seeds 0 .. draws-1; the
robot is told the stated sigma), stands a robot at the search's start known to 10 cm / 5 deg, and drives
the tour (:func:`lab.localization.survey_tour.survey_tour` through the stands of
:func:`~lab.localization.survey_tour.survey_stands` with ``cover``) in the synthetic room of
``tests/tour_fakes.py``: the robot moves at once with drawn odometry errors, and sees the true posters
with drawn fit errors. ``--fit ALONG,YAW`` multiplies the fakes' fit errors along the line of sight and
of the poster's yaw: the room's own fits state about 2 and 3 times the fakes' at 2.5-3 m
(docs/tuning/survey-tour.md, stop 66). The localizer is the default one.

Printed per cover: the stands, the accepted sightings, and the shape error (the posters' RMS position
error left after the turn-and-shift that best explains them all) of the survey and of the refined
posters, median and 90th percentile over the draws. The frame of the constellation (that turn-and-shift)
is what all the posters' surveys leave together whatever the tour does: benchmarks/survey_limit.py.
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))  # the synthetic room

from tour_fakes import ROOM, Sightings, TourBase, in_room, shape_error  # noqa: E402

from lab.geometry import Pose2D, wrap_angle  # noqa: E402
from lab.localization import LocalizationMode, LocalizedRobot, LocalizerConfig  # noqa: E402
from lab.localization.survey_tour import survey_stands, survey_tour  # noqa: E402
from lab.sim.room_errors import survey_error  # noqa: E402
from lab.sim.sensing import sensing_profile  # noqa: E402

START = Pose2D(0.0, -3.0, math.radians(90.0))  # the lab room's robot start


def one_tour(room, mismatch: float, seed: int, cover: int, passes: int, fit) -> tuple[float, float, int, int]:
    """(survey's shape error, refined shape error [m], stands, accepted sightings) of one draw."""
    errors, mapped = {}, []
    for lm in ROOM:
        dx, dy, _dz, dyaw = survey_error(room, mismatch, seed, lm.name)
        errors[lm.name] = (dx, dy, dyaw)
        c = (lm.centre_W[0] + dx, lm.centre_W[1] + dy, lm.centre_W[2])
        mapped.append(replace(lm, centre_W=c, yaw=lm.yaw + dyaw))
    mapped = replace(ROOM, landmarks=tuple(mapped)).surveyed(*room.survey_sigma)
    rng = np.random.default_rng([seed, 66])
    base = TourBase(START, rng)
    cfg = LocalizerConfig()
    Sigma0 = np.diag([0.1**2, 0.1**2, math.radians(5.0) ** 2])
    robot = LocalizedRobot(base, "odometry", config=cfg, Sigma0=Sigma0, start_measured_by_hand=True)
    robot.mode = LocalizationMode.LANDMARKS
    robot.observer = Sightings(base, mapped, rng, along=fit[0], yaw=fit[1])
    robot.log = lambda m: None
    robot.relocalize()
    stands = survey_stands(mapped, in_room, start_xy=robot.localizer.x[:2], config=cfg, cover=cover)
    tour = survey_tour(robot, base.navigate, stands, passes=passes)
    off = {}
    for name, (l, _) in robot.localizer.landmark_estimates().items():
        d = l - ROOM.get(name).planar
        off[name] = (d[0], d[1], wrap_angle(d[2]))
    return shape_error(errors), shape_error(off), len(stands), tour.n_sightings


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sensing", default="realistic", help="a profile name or a sensing TOML file")
    ap.add_argument("--error-scale", type=float, default=1.0)
    ap.add_argument("--draws", type=int, default=12, help="survey draws (episode seeds 0 .. draws-1)")
    ap.add_argument("--covers", default="1,2,3", help="stands that see each poster well, e.g. 1,2,3")
    ap.add_argument("--passes", type=int, default=2, help="times round the posters in view at a stand")
    ap.add_argument(
        "--fit", default="2,3", help="the fit errors along the line of sight and of yaw, x fakes'"
    )
    args = ap.parse_args(argv)
    profile = sensing_profile(args.sensing).scaled(args.error_scale)
    room = profile.room
    if room is None or room.survey_m <= 0 or room.survey_deg <= 0:
        raise SystemExit(f"the profile {args.sensing!r} has no survey error: nothing to refine")
    covers = [int(c) for c in args.covers.split(",")]
    fit = tuple(float(v) for v in args.fit.split(","))
    if len(fit) != 2 or min(fit) <= 0:
        raise SystemExit(f"--fit must be two factors > 0 (along, yaw), got {args.fit!r}")
    sm, sr = room.survey_sigma
    print(
        f"survey drawn at {100 * sm * profile.mismatch:.2f} cm / {math.degrees(sr) * profile.mismatch:.2f} "
        f"deg per poster (stated {100 * sm:.2f} cm / {math.degrees(sr):.2f} deg); {args.draws} draws, "
        f"{args.passes} passes, fit errors x {fit[0]:g} along, x {fit[1]:g} yaw"
    )
    print("| cover | stands | sightings | survey's shape, median / p90 | refined shape, median / p90 |")
    print("|---|---|---|---|---|")
    for cover in covers:
        rows = np.array(
            [one_tour(room, profile.mismatch, s, cover, args.passes, fit) for s in range(args.draws)]
        )
        sv, rf = 100 * rows[:, 0], 100 * rows[:, 1]
        print(
            f"| {cover} | {np.median(rows[:, 2]):.0f} | {np.median(rows[:, 3]):.0f} | "
            f"{np.median(sv):.2f} / {np.percentile(sv, 90):.2f} cm | "
            f"{np.median(rf):.2f} / {np.percentile(rf, 90):.2f} cm |",
            flush=True,
        )


if __name__ == "__main__":
    main()
