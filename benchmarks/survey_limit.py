"""The floor a surveyed poster map puts under the robot's position error, in the lab room.

Run from the repository root::

    python benchmarks/survey_limit.py [--sensing realistic|FILE] [--error-scale 1] [--draws 200]

For points on the room's floor (a 0.5 m grid, 0.6 m from the walls) and the survey drawn as the
simulator draws it (:func:`lab.sim.room_errors.survey_error`: the profile's survey sigma times its
mismatch and ``--error-scale``, one draw per episode seed 0 .. draws-1), the robot's position error
with *perfect* sightings of the ``k`` best posters in view (:func:`lab.localization.survey_limit.
posters_in_view`), for k = 1, 2, 3, 4, 6 and all in view: the turn-and-shift those posters' surveys
leave (:func:`~lab.localization.survey_limit.survey_frame_error`, weighted by the stated sigmas, as the
localizer weighs them). Medians, 90th percentiles and the share past issue 52's 5 cm over points x
draws. A run's localizer adds its sightings' and odometry's errors to this, and a found object adds the
local search's own.
What the figures mean for issue 52: docs/tuning/survey-limit.md.
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from lab.localization.survey_limit import posters_in_view, survey_frame_error
from lab.sim.room_errors import survey_error
from lab.sim.sensing import sensing_profile
from lab.training.landmarks import landmark_map_from_scene


def floor_points(room_size, step_m: float = 0.5, margin_m: float = 0.6) -> np.ndarray:
    """A grid of points (n, 2) over the room's floor, ``margin_m`` from its walls."""
    hx, hy = room_size[0] / 2 - margin_m, room_size[1] / 2 - margin_m
    xs = np.arange(-hx, hx + 1e-9, step_m)
    ys = np.arange(-hy, hy + 1e-9, step_m)
    return np.array([(x, y) for x in xs for y in ys])


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sensing", default="realistic", help="a profile name or a sensing TOML file")
    ap.add_argument("--error-scale", type=float, default=1.0)
    ap.add_argument("--draws", type=int, default=200, help="survey draws (episode seeds 0 .. draws-1)")
    args = ap.parse_args(argv)
    profile = sensing_profile(args.sensing).scaled(args.error_scale)
    room = profile.room
    if room is None or room.survey_m <= 0 or room.survey_deg <= 0:
        raise SystemExit(f"the profile {args.sensing!r} has no survey error: nothing to bound")
    landmarks = landmark_map_from_scene("lab_room")  # the posters' true poses (no databases needed)
    sm, sr = room.survey_sigma
    pts = floor_points(landmarks.room_size)
    views = [posters_in_view(landmarks, p) for p in pts]
    xy = {lm.name: np.asarray(lm.centre_W[:2], float) for lm in landmarks}
    ks = [1, 2, 3, 4, 6, None]
    err = {k: [] for k in ks}
    for seed in range(args.draws):
        e = {}
        for lm in landmarks:
            dx, dy, _dz, dyaw = survey_error(room, profile.mismatch, seed, lm.name)
            e[lm.name] = (dx, dy, dyaw)
        for p, names in zip(pts, views, strict=True):
            for k in ks:
                use = names if k is None else names[:k]
                if not use or (k is not None and len(names) < k):
                    continue
                t = survey_frame_error([xy[n] for n in use], [e[n] for n in use], p, sm, sr)
                err[k].append(100.0 * math.hypot(t[0], t[1]))
    n_view = [len(v) for v in views]
    print(
        f"survey drawn at {100 * sm * profile.mismatch:.2f} cm / "
        f"{math.degrees(sr) * profile.mismatch:.2f} deg per poster (stated {100 * sm:.2f} cm / "
        f"{math.degrees(sr):.2f} deg); {len(pts)} floor points, posters in view: median "
        f"{int(np.median(n_view))}, min {min(n_view)}, max {max(n_view)}; {args.draws} draws"
    )
    print("| posters seen | position error median | p90 | past 5 cm |")
    print("|---|---|---|---|")
    for k in ks:
        v = np.asarray(err[k])
        label = "all in view" if k is None else f"best {k}"
        med, p90, past = np.median(v), np.percentile(v, 90), 100 * np.mean(v > 5.0)
        print(f"| {label} | {med:.2f} cm | {p90:.2f} cm | {past:.1f} % |")


if __name__ == "__main__":
    main()
