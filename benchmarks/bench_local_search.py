"""The local search alone, the robot stood where the search agent stands it: why does it miss an object
that is in view?

For each object, surface and seed the object is placed as ``lab eval search`` places it
(``random_placement`` with ``default_rng([seed, object_index, surface_index])``), and the robot is stood as
the agent's approach stands it: at a seeded distance within ``LocalSearchConfig``'s band
(``min_distance_m`` .. ``max_distance_m``; the agent's wider band, ``SearchAgentConfig.wide_band_m`` further
out, when no spot of the band is free) from the centre of the probability-map cell holding the object,
on a seeded free side of it, facing the cell's centre. Then :func:`lab.search.local_search` runs alone
(no closed loop) under the ``realistic`` sensing profile, with 2x supersampled rendering as in
``lab search``.

The truth is used only to set up and to score. Per view it records what the search saw (features,
matches, RANSAC inliers, its outcome) beside what the truth says was there: the object's distance and
its bearing off the optical axis, its visible pixels (segmentation), the face turned most towards the
camera and its angle from the line of sight, the measured features that lie on the object and the
matches that are right (the database point, put at the true pose, within 3 cm of the measured point).

Run (tuning seeds, below 1000, for diagnosis and choices; the report split once, at the end)::

    nice -n 19 .venv/bin/python benchmarks/bench_local_search.py --seeds 0-5 --json out/ls_tune.json
    nice -n 19 .venv/bin/python benchmarks/bench_local_search.py --paper --seeds 0-5   # the paper's search

Prints one line per trial, the views of the misses, and the success count per object with Wilson 95 %
intervals (success: found within 5 cm and 10 degrees of the truth, as ``lab search`` scores it).

Measured (3 objects x 3 surfaces; ``--paper`` is ``second_look=None``):

======================  ==========================  ==========================
seeds                   paper (9 views)             with the second look
======================  ==========================  ==========================
tuning 0-5 (54)         43/54, 79.6 % [67.1, 88.2]  47/54, 87.0 % [75.6, 93.6]
report 100200-09 (90)   73/90, 81.1 % [71.8, 87.9]  80/90, 88.9 % [80.7, 93.9]
======================  ==========================  ==========================
"""

from __future__ import annotations

import argparse
import json
import math
import time
from dataclasses import asdict, replace

import numpy as np

from lab.evaluation import parse_seeds, split_of, wilson_interval
from lab.geometry import Pose2D, se3_inv, transform_points
from lab.runs.placement import (
    SURFACES,
    circle_polygon,
    footprint,
    polygon_inside,
    polygons_overlap,
    random_placement,
    searchable_objects,
    supports,
)
from lab.runs.search import SUCCESS_ORIENTATION_DEG, SUCCESS_POSITION_M, map_spec, pose_errors
from lab.scene import load_scene
from lab.search.config import SearchAgentConfig
from lab.search.local_search import LocalSearchConfig, local_search, make_matcher
from lab.sim import RenderSettings, SimRobot, SimWorld
from lab.training.search import search_database
from lab.vision.roi import object_roi
from lab.vision.stereo import stereo_features

TEXTURED = ("cereal_box", "book", "toy_block")

#: The six faces of a box in its own frame: name, outward normal.
FACES = (("+x", (1, 0, 0)), ("-x", (-1, 0, 0)), ("+y", (0, 1, 0)), ("-y", (0, -1, 0)), ("+z", (0, 0, 1)))


def stand(scene, place, rng, cfg: LocalSearchConfig, wide_band_m: float, robot_radius_m: float = 0.2):
    """Where the agent's approach would stand the robot: ``(pose, target_xy, distance)``.

    The target is the centre of the map cell holding the object; the robot stands ``distance`` from it
    (uniform in the band) on a random side whose spot keeps ``robot_radius_m`` + 0.1 m from every body's
    footprint and inside the room (the navigator's grown costmap), facing the target with a heading
    error of 2 degrees (standard deviation)."""
    spec = map_spec(scene)
    ij = spec.world_to_cell(place[0], place[1])
    tx, ty = spec.cell_to_world(*ij)
    room = supports(scene)[0].polygon
    bodies = [b for b in scene.bodies if b.role != "decor"]
    for lo, hi in (
        (cfg.min_distance_m, cfg.max_distance_m),
        (cfg.max_distance_m, cfg.max_distance_m + wide_band_m),
    ):
        for _ in range(400):
            a, d = rng.uniform(-math.pi, math.pi), rng.uniform(lo, hi)
            x, y = tx + d * math.cos(a), ty + d * math.sin(a)
            disk = circle_polygon(x, y, robot_radius_m + 0.1)
            if not polygon_inside(disk, room) or any(polygons_overlap(disk, footprint(b)) for b in bodies):
                continue
            theta = math.atan2(ty - y, tx - x) + math.radians(rng.normal(0.0, 2.0))
            return Pose2D(x, y, theta), (tx, ty), d
    raise RuntimeError(f"no free spot near {place}")


class _Probe:
    """The robot, passed through, keeping every captured frame with the true camera pose (scoring only)."""

    def __init__(self, robot, world):
        self._robot, self._world = robot, world
        self.frames: list = []

    def __getattr__(self, name):
        return getattr(self._robot, name)

    def capture_stereo(self):
        frame = self._robot.capture_stereo()
        self.frames.append((frame, self._world.truth.G_WC()))
        return frame


def view_truth(frame, G_WC, G_WO, name, world, db, matcher) -> dict:
    """What the truth says one view held: the object's geometry in it and the features and matches on it."""
    cam = frame.camera
    G_CO = se3_inv(G_WC) @ G_WO
    p = G_CO[:3, 3]
    dist = float(np.linalg.norm(p))
    off_axis = math.degrees(math.acos(max(-1.0, min(1.0, p[2] / dist))))
    seg = world.truth.segmentation(G_WC, cam)
    visible_px = int(np.count_nonzero(seg == world.body_id(name)))
    # the face turned most towards the camera: angle between its normal and the line to the camera
    c_O = transform_points(se3_inv(G_CO), np.zeros((1, 3)))[0]  # the camera in the object frame
    best = ("", 90.0)
    for face, n in FACES:
        n = np.asarray(n, float)
        centre = 0.5 * np.asarray(db.extent) * n
        ray = c_O - centre
        ang = math.degrees(math.acos(float(np.clip(n @ ray / np.linalg.norm(ray), -1, 1))))
        if ang < best[1]:
            best = (face, ang)
    roi = object_roi(G_CO, db.extent, cam, 0)
    f = stereo_features(frame.left, frame.right, cam, t=frame.t)
    on_obj = 0
    if len(f) and roi is not None:
        x, y, w, h = roi
        uv, z = f.uv, f.points_C[:, 2]
        inside = (uv[:, 0] >= x) & (uv[:, 0] < x + w) & (uv[:, 1] >= y) & (uv[:, 1] < y + h)
        on_obj = int(np.count_nonzero(inside & (np.abs(z - p[2]) < 0.5 * float(np.max(db.extent)) + 0.05)))
    corr = matcher.match(f)
    right = 0
    if len(corr):
        b_C = transform_points(G_CO, db.points_O[corr.idx_db])
        ok = np.linalg.norm(f.points_C[corr.idx_meas] - b_C, axis=1) < 0.03
        right = int(len(np.unique(corr.idx_meas[ok])))
    return {
        "distance_m": round(dist, 3),
        "off_axis_deg": round(off_axis, 1),
        "visible_px": visible_px,
        "roi_px": None if roi is None else [int(v) for v in roi[2:]],
        "face": best[0],
        "face_angle_deg": round(best[1], 1),
        "features": len(f),
        "features_on_object": on_obj,
        "right_matches": right,
    }


def trial(
    name: str, surface: str, seed: int, cfg: LocalSearchConfig, wide_band_m: float, diagnose: bool
) -> dict:
    scene = load_scene("lab_room")
    objects = searchable_objects(scene)
    place = random_placement(
        scene, name, np.random.default_rng([seed, objects.index(name), SURFACES.index(surface)]), surface
    )
    scene = scene.with_pose(name, place)
    pose, target_xy, d = stand(scene, place, np.random.default_rng([seed, 7]), cfg, wide_band_m)
    db = search_database(name)
    matcher = make_matcher(db)
    with SimWorld(scene, RenderSettings(supersample=2)) as w:
        robot = SimRobot(w, start=pose, seed=seed, sensing="realistic")
        robot.enable()
        probe = _Probe(robot, w)
        t0 = time.perf_counter()
        res = local_search(probe, db, target_xy, np.random.default_rng([seed, 1]), cfg, matcher)
        wall = time.perf_counter() - t0
        G_WO = w.truth.G_W(name)
        truth_at = {fr.t: (fr, G_WC) for fr, G_WC in probe.frames}
        views = []
        for v in res.views:
            rec = {
                k: (round(math.degrees(x), 1) if k in ("pan", "tilt") else x) for k, x in asdict(v).items()
            }
            if diagnose and v.t in truth_at:
                rec.update(view_truth(*truth_at[v.t], G_WO, name, w, db, matcher))
            views.append(rec)
    pe = oe = None
    if res.found:
        pe, oe = pose_errors(res.G_WO, G_WO)
    ok = res.found and pe <= SUCCESS_POSITION_M and oe <= SUCCESS_ORIENTATION_DEG
    bearing = math.degrees(math.atan2(place[1] - pose.y, place[0] - pose.x) - pose.theta)
    return {
        "object": name,
        "surface": surface,
        "seed": seed,
        "place": [round(v, 3) for v in place],
        "stand": [round(pose.x, 3), round(pose.y, 3), round(math.degrees(pose.theta), 1)],
        "cell_distance_m": round(d, 3),
        "object_distance_m": round(math.hypot(place[0] - pose.x, place[1] - pose.y), 3),
        "object_bearing_deg": round((bearing + 180) % 360 - 180, 1),
        "found": res.found,
        "success": bool(ok),
        "reason": res.reason,
        "position_error_m": pe,
        "orientation_error_deg": oe,
        "n_views": len(res.views),
        "search_time_s": round(res.t_end - res.t_start, 2),
        "wall_s": round(wall, 1),
        "views": views,
    }


def trial_line(r: dict) -> str:
    err = ""
    if r["found"]:
        err = f" {r['position_error_m'] * 100:.1f} cm {r['orientation_error_deg']:.1f} deg"
    ok = "OK  " if r["success"] else "MISS"
    return (
        f"{r['object']:10s} {r['surface']:5s} s{r['seed']:<6d} d={r['object_distance_m']:.2f} m "
        f"brg={r['object_bearing_deg']:+5.0f} {ok}{err} ({r['n_views']} views, "
        f"{r['search_time_s']:.0f} s sim, {r['wall_s']:.0f} s wall) {r['reason'][:110]}"
    )


def view_line(v: dict) -> str:
    return (
        f"      pan {v['pan']:+6.1f} tilt {v['tilt']:+5.1f} x{v.get('upsample', 1)}: "
        f"vis {v['visible_px']:5d} px face {v['face']} {v['face_angle_deg']:4.0f} deg, "
        f"{v['distance_m']:.2f} m; feat {v['n_features']:3d} on obj {v['features_on_object']:3d} "
        f"match {v['n_matched']:3d} right {v['right_matches']:3d} inl {v['n_inliers']:3d}: "
        f"{v['outcome'][:70]}"
    )


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--objects", default=",".join(TEXTURED))
    ap.add_argument("--surfaces", default=",".join(SURFACES))
    ap.add_argument(
        "--seeds", default="0-5", help="tuning seeds (< 1000) for diagnosis; the report split once"
    )
    ap.add_argument("--paper", action="store_true", help="the paper's local search (no second look)")
    ap.add_argument("--no-diagnose", action="store_true", help="skip the per-view truth (faster)")
    ap.add_argument("--json", help="write every trial here")
    args = ap.parse_args()
    seeds = parse_seeds(args.seeds)
    cfg = LocalSearchConfig()
    if args.paper:
        cfg = replace(cfg, second_look=None)
    wide = SearchAgentConfig().wide_band_m
    mode = "paper" if args.paper else "default"
    print(f"local search alone, {split_of(seeds)} seeds {args.seeds}, sensing realistic, {mode} config")
    rows = []
    for name in args.objects.split(","):
        for surface in args.surfaces.split(","):
            for seed in seeds:
                r = trial(name, surface, seed, cfg, wide, not args.no_diagnose)
                rows.append(r)
                print(trial_line(r), flush=True)
                if not r["success"]:
                    for v in r["views"]:
                        if "visible_px" in v:
                            print(view_line(v))
    print("\nsuccess (found within 5 cm, 10 deg), Wilson 95 %:")
    for name in [*args.objects.split(","), None]:
        sel = [r for r in rows if name is None or r["object"] == name]
        k, n = sum(r["success"] for r in sel), len(sel)
        lo, hi = wilson_interval(k, n)
        print(f"  {name or 'all':10s} {k:3d}/{n:<3d} {100 * k / n:5.1f} % [{100 * lo:.1f}, {100 * hi:.1f}]")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=1)


if __name__ == "__main__":
    main()
