"""Search trials on tuning seeds with the localizer's inputs, the pose checks and the navigator's
clearings recorded, then re-analysed offline (docs/tuning/revalidation.md, issue 52).

    nice .venv/bin/python benchmarks/replay_localizer.py record --seeds 1-2 --out out/reval-search
    nice .venv/bin/python benchmarks/replay_localizer.py replay --out out/reval-search
    nice .venv/bin/python benchmarks/replay_localizer.py pose-checks --out out/reval-search
    nice .venv/bin/python benchmarks/replay_localizer.py search-figures --out out/reval-search
    nice .venv/bin/python benchmarks/replay_localizer.py record --seeds 5 --error-scale 2 \
        --only paper_obst_realistic_landmarks_cereal_box_floor --out out/x2-trial
    nice .venv/bin/python benchmarks/replay_localizer.py sightings --out out/x2-trial

``record`` runs the ``lab eval search`` trials of the paper strategy (every object, surface and obstacle
setting of ``--seeds``, realistic sensing, landmarks, 600 s) one after the other in this process, a
seed's every surface before the next seed, writes each trial's JSON to ``OUT/jobs/KEY.json`` as ``lab
eval search --out OUT`` does (so ``lab eval search ... --resume --out OUT`` then writes the report
without running them again), and beside it in ``OUT/replay/``: ``KEY.pkl``, the
:class:`lab.localization.Localizer`'s construction and every call that changed it (``predict``,
``update``, ``start_clone``, ``end_clone``) in order, with the simulator's true robot pose at each
update; ``KEY.checks.pkl``, every pose check before "found" (its counts, the checked pose, the true
camera pose, the frame) and every clearing of marks under the robot (``Navigator.clear_under_robot``);
``KEY.dbs.pkl``, the feature databases those checks used. The truth is for scoring only; the robot
never read it. A trial already in ``OUT/jobs`` is skipped. Tuning seeds only.

``replay`` feeds each recorded call sequence to a fresh localizer built with one setting changed at a
time (the recount rule, the heading's observation floor, the position terms of the floor) and scores
its estimate after every landmark update against the true pose: the position and heading errors, the
pose's NEES (3 degrees of freedom; inside the chi-square 95 % band 95 % of the time when honest), the
heading's squared z-score and the gate lock-out's inflations. The replay is open-loop: the robot drove
as the recorded run's own localizer told it, so it says what a setting does to the estimate from the
same observations, not where the robot would then have gone.

``pose-checks`` scores each logged pose check against the truth (right: within the success criterion's
5 cm and 10 degrees) and checks its frame again at the pose turned about the vertical (wrong poses),
for several thresholds; it also lists the navigator's clearings. ``search-figures`` prints the find
times against budgets and the revisits from another side (of a cell searched itself, or only of a
neighbour). ``sightings`` prints each trial's landmark sightings against the truth by poster, the
surveyed map's floor for the posters it sighted and the localizer's error, at its last pose.
``record --sensing PROFILE|FILE`` records under another profile than realistic, ``--error-scale K`` scales
its errors, ``--survey-tour`` drives a tour before each search, ``--only TEXT`` keeps the jobs whose key
contains TEXT; ``sightings`` then also prints the ranges' median error and the localizer's range scale.
"""

from __future__ import annotations

import argparse
import math
import os
import pickle
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from lab.evaluation import parse_seeds

CHI2_3_BAND = (0.2158, 9.3484)  # chi-square(3): 2.5 % and 97.5 % quantiles

VARIANTS = {
    "as is (recount 5 cm / 2 deg, heading floor 0.75 deg)": {},
    "recount off (every rejection counts)": {"recount_m": 0.0, "recount_rad": 0.0},
    "recount 10 cm / 5 deg": {"recount_m": 0.10, "recount_rad": math.radians(5.0)},
    "heading floor 0.3 deg": {"obs_sigma_rad": math.radians(0.3)},
    "heading floor 0.5 deg": {"obs_sigma_rad": math.radians(0.5)},
    "heading floor 1.0 deg": {"obs_sigma_rad": math.radians(1.0)},
    "position floor x 0.5": {
        "obs_sigma_m": 0.001,
        "obs_sigma_rel": 0.001,
        "obs_sigma_per_m": 0.0005,
        "obs_sigma_rel_across": 0.0005,
    },
    "position floor x 2": {
        "obs_sigma_m": 0.004,
        "obs_sigma_rel": 0.004,
        "obs_sigma_per_m": 0.002,
        "obs_sigma_rel_across": 0.002,
    },
}


def _truth_of(robot):
    """The simulator's truth under a chain of robot wrappers (``.base``), or None."""
    while robot is not None:
        t = getattr(robot, "truth", None)
        if t is not None:
            return t
        robot = getattr(robot, "base", None)
    return None


class Recorder:
    """Wraps the localizer's methods so that each instance's construction and calls are logged."""

    def __init__(self):
        self.logs: list[dict] = []
        self.truth = None

    def install(self):
        from lab.localization import filter as F
        from lab.localization import robot as R

        rec = self
        init, lr_init = F.Localizer.__init__, R.LocalizedRobot.__init__

        def localizer_init(loc, x0, Sigma0=None, config=None, first_sighting=False):
            init(loc, x0, Sigma0, config, first_sighting)
            log = dict(x0=np.array(x0, float), Sigma0=None if Sigma0 is None else np.array(Sigma0, float))
            log.update(config=loc.config, first_sighting=first_sighting, calls=[], owner=loc)
            rec.logs.append(log)

        def robot_init(robot, base, *a, **kw):
            lr_init(robot, base, *a, **kw)
            rec.truth = _truth_of(base)

        F.Localizer.__init__ = localizer_init
        R.LocalizedRobot.__init__ = robot_init
        for name in ("predict", "update", "start_clone", "end_clone"):
            setattr(F.Localizer, name, self._logged(getattr(F.Localizer, name), name))
        self.checks: list[dict] = []
        self.dbs: dict = {}
        self._install_pose_check()

    def _install_pose_check(self):
        """Log every pose check (the search's, before "found") with the true camera pose then."""
        from lab.search import tracking as T

        rec, check_pose = self, T.check_pose

        def logged_check(f, corr, db, G_CO, camera, config=None, roi=None):
            pc = check_pose(f, corr, db, G_CO, camera, config, roi)
            G_WC = None if rec.truth is None else np.array(rec.truth.G_WC(), float)
            rec.dbs[id(db)] = db
            frame = pickle.dumps((f, corr, camera, config, roi))  # for the check replayed at other poses
            rec.checks.append(
                dict(
                    n_visible=pc.n_visible,
                    n_explained=pc.n_explained,
                    confirmed=pc.confirmed,
                    G_CO=np.array(G_CO, float),
                    G_WC_true=G_WC,
                    frame=frame,
                    db=id(db),
                )
            )
            return pc

        T.check_pose = logged_check

        from lab.navigation import navigator as N

        clear = N.Navigator.clear_under_robot

        def logged_clear(nav):
            n = clear(nav)
            if n:
                rec.checks.append(dict(cleared_under_robot=n))
            return n

        N.Navigator.clear_under_robot = logged_clear

    def _logged(self, fn, name):
        rec = self

        def wrapper(loc, *args, **kw):
            log = next((g for g in reversed(rec.logs) if g["owner"] is loc), None)
            if log is not None:
                truth = None
                if name == "update" and rec.truth is not None:
                    p = rec.truth.pose()
                    truth = np.array([p.x, p.y, p.theta], float)
                log["calls"].append((name, pickle.dumps((args, kw)), truth))
            return fn(loc, *args, **kw)

        return wrapper


def record(
    out: Path,
    seeds,
    error_scale: float = 1.0,
    survey_tour: bool = False,
    only: str = "",
    sensing: str = "realistic",
) -> None:
    """Run the trials in this process with the localizer recorded (see the module docstring): the
    ``sensing`` profile (a name or a sensing file) with its errors times ``error_scale``, a survey tour
    first with ``survey_tour``, and only the jobs whose key contains ``only``."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    from lab.eval.search import SearchSweep
    from lab.io import write_json_atomic

    rec = Recorder()
    rec.install()
    (out / "replay").mkdir(parents=True, exist_ok=True)
    sweep = SearchSweep(
        seeds=tuple(seeds),
        strategies=("paper",),
        error_scale=(error_scale,),
        survey_tour=survey_tour,
        sensing=(sensing,),
    )
    jobs = [j for j in sweep.jobs() if only in j.key]
    for job in sorted(jobs, key=lambda j: j.kwargs["seed"]):  # a seed's every surface first
        done = out / "jobs" / f"{job.key}.json"
        if done.exists():
            continue
        rec.logs.clear()
        rec.checks.clear()
        rec.dbs.clear()
        t0 = time.perf_counter()
        res = job.fn(**job.kwargs)
        write_json_atomic(done, res)
        logs = [{k: v for k, v in g.items() if k != "owner"} for g in rec.logs]
        (out / "replay" / f"{job.key}.pkl").write_bytes(pickle.dumps(logs))
        (out / "replay" / f"{job.key}.checks.pkl").write_bytes(pickle.dumps(rec.checks))
        if rec.dbs:
            (out / "replay" / f"{job.key}.dbs.pkl").write_bytes(pickle.dumps(rec.dbs))
        print(
            f"{job.key}: {res.get('reason')} in {res.get('sim_time_s')} s sim, "
            f"{time.perf_counter() - t0:.0f} s wall, {sum(len(g['calls']) for g in logs)} calls",
            flush=True,
        )


def replay_one(log: dict, changes: dict) -> dict:
    """One recorded localizer replayed with ``changes`` to its config: errors after each update."""
    from lab.geometry import wrap_angle
    from lab.localization import Localizer

    loc = Localizer(log["x0"], log["Sigma0"], replace(log["config"], **changes), log["first_sighting"])
    pos, head, nees, z2 = [], [], [], []
    for name, blob, truth in log["calls"]:
        args, kw = pickle.loads(blob)
        try:
            getattr(loc, name)(*args, **kw)
        except ValueError:  # a clone the recorded run could start and this one cannot: skip it
            continue
        if truth is not None:
            e = loc.x - truth
            e[2] = wrap_angle(e[2])
            pos.append(math.hypot(e[0], e[1]))
            head.append(abs(math.degrees(e[2])))
            nees.append(float(e @ np.linalg.solve(loc.Sigma, e)))
            z2.append(float(e[2] ** 2 / loc.Sigma[2, 2]))
    return dict(pos=pos, head=head, nees=nees, z2=z2, inflations=loc.n_inflations, accepted=loc.n_updates)


def replay(out: Path) -> None:
    """Every recorded trial, every variant: print the table (medians and tails over all updates)."""
    logs = []
    for p in sorted(q for q in (out / "replay").glob("*.pkl") if q.name.count(".") == 1):
        logs += [g for g in pickle.loads(p.read_bytes()) if any(c[2] is not None for c in g["calls"])]
    n_up = sum(sum(c[2] is not None for c in g["calls"]) for g in logs)
    print(f"{len(logs)} recorded localizers, {n_up} landmark observations (tuning seeds)\n")
    print(
        "| variant | inflations | accepted | pos. error median / p95 / max [cm] | heading error median / p95 "
        "/ max [deg] | NEES in 95 % band | NEES > 9.35 | heading z^2 | trials changed (5 mm, 0.2 deg) |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    base = None
    for label, changes in VARIANTS.items():
        runs = [replay_one(g, changes) for g in logs]
        base = base or runs
        pos = np.concatenate([r["pos"] for r in runs]) * 100
        head = np.concatenate([r["head"] for r in runs])
        nees = np.concatenate([r["nees"] for r in runs])
        changed = sum(
            len(a["pos"]) != len(b["pos"])
            or np.max(np.abs(np.subtract(a["pos"], b["pos"])), initial=0) > 0.005
            or np.max(np.abs(np.subtract(a["head"], b["head"])), initial=0) > 0.2
            for a, b in zip(runs, base, strict=True)
        )
        q = lambda x: f"{np.median(x):.2f} / {np.percentile(x, 95):.2f} / {np.max(x):.2f}"  # noqa: E731
        inside = np.mean((nees >= CHI2_3_BAND[0]) & (nees <= CHI2_3_BAND[1])) * 100
        print(
            f"| {label} | {sum(r['inflations'] for r in runs)} | {sum(r['accepted'] for r in runs)} | "
            f"{q(pos)} | {q(head)} | {inside:.1f} % | {np.mean(nees > CHI2_3_BAND[1]) * 100:.1f} % | "
            f"{np.mean(np.concatenate([r['z2'] for r in runs])):.2f} | "
            f"{changed} of {len(runs)} |"
        )


def sightings(out: Path) -> None:
    """Each recorded trial's landmark sightings against the truth, by poster: the bearing's turn and the
    range's share off (both what a shared calibration error would leave), the poster's yaw off, and how
    many; then the surveyed map's floor at the robot's last pose for the posters it sighted (their
    surveys fitted together, :func:`lab.localization.survey_limit.survey_frame_error`) and the
    localizer's own error there."""
    from lab.geometry import wrap_angle
    from lab.localization import Localizer, measurement_model
    from lab.localization.survey_limit import survey_frame_error
    from lab.training.landmarks import landmark_map_from_scene

    true = {lm.name: lm for lm in landmark_map_from_scene("lab_room")}
    for p in sorted(q for q in (out / "replay").glob("*.pkl") if q.name.count(".") == 1):
        logs = [g for g in pickle.loads(p.read_bytes()) if any(c[2] is not None for c in g["calls"])]
        for g in logs:
            by, mapped, last = {}, {}, None
            for name, blob, truth in g["calls"]:
                if name != "update" or truth is None:
                    continue
                (z, _Q, lm, *_), _kw = pickle.loads(blob)
                t = true[lm.name]
                zt = measurement_model(truth, [t.centre_W[0], t.centre_W[1], t.yaw])
                r = math.hypot(zt[0], zt[1])
                u = zt[:2] / r
                dz = np.asarray(z[:2], float) - zt[:2]
                across = float(dz @ np.array([-u[1], u[0]]))
                by.setdefault(lm.name, []).append(
                    (
                        math.degrees(across / r),
                        100 * float(dz @ u) / r,
                        math.degrees(wrap_angle(z[2] - zt[2])),
                    )
                )
                mapped[lm.name], last = lm, truth
            if last is None:
                continue
            print(f"{p.stem}: sightings against the truth, medians (bearing deg / range % / yaw deg, n)")
            for n, v in sorted(by.items()):
                b, rr, y = np.median(np.array(v), axis=0)
                print(f"  {n:18s} {b:+6.2f} {rr:+6.2f} {y:+6.2f}  n {len(v)}")
            names = sorted(mapped)
            xy = [true[n].centre_W[:2] for n in names]
            E = [
                (
                    mapped[n].centre_W[0] - true[n].centre_W[0],
                    mapped[n].centre_W[1] - true[n].centre_W[1],
                    wrap_angle(mapped[n].yaw - true[n].yaw),
                )
                for n in names
            ]
            sm, sr = mapped[names[0]].survey_sigma_m, mapped[names[0]].survey_sigma_rad
            if sm > 0 and sr > 0:
                fe = survey_frame_error(xy, E, last[:2], sm, sr)
                floor = 100 * math.hypot(fe[0], fe[1])
                print(f"  the survey's floor at the last pose, these posters: {floor:.1f} cm")
            loc = Localizer(g["x0"], g["Sigma0"], g["config"], g["first_sighting"])
            for name, blob, _truth in g["calls"]:
                args, kw = pickle.loads(blob)
                try:
                    getattr(loc, name)(*args, **kw)
                except ValueError:
                    continue
            print(f"  the localizer at the last pose: {100 * math.hypot(*(loc.x[:2] - last[:2])):.1f} cm")
            ranges = np.concatenate([np.array(v)[:, 1] for v in by.values()])
            scale = loc.range_scale_estimate
            est = "not estimated" if scale is None else f"{100 * scale[0]:+.2f} +- {100 * scale[1]:.2f} %"
            print(
                f"  ranges off, median of every sighting: {np.median(ranges):+.2f} %; "
                f"the localizer's scale {est}"
            )


THRESHOLDS = [(3, 0.03), (2, 0.02), (4, 0.03), (5, 0.04), (6, 0.04), (3, 0.05), (8, 0.06)]


def pose_checks(out: Path) -> None:
    """Every logged pose check scored against the truth: was the checked pose right (the success
    criterion's 5 cm and 10 deg, in the true camera frame), and which thresholds pass or stop it."""
    import json

    from lab.geometry import euler_zyx_to_R, se3
    from lab.runs.search_result import SUCCESS_ORIENTATION_DEG, SUCCESS_POSITION_M, pose_errors

    rows, cleared = [], []
    for p in sorted((out / "replay").glob("*.checks.pkl")):
        key = p.name[: -len(".checks.pkl")]
        res = json.loads((out / "jobs" / f"{key}.json").read_text())
        tp = res["true_pose"]
        G_WO = se3(euler_zyx_to_R(*np.radians(tp["euler_zyx_deg"])), np.array(tp["position_m"], float))
        for c in pickle.loads(p.read_bytes()):
            if "cleared_under_robot" in c:
                cleared.append((key, c["cleared_under_robot"]))
                continue
            dp, dr = pose_errors(c["G_CO"], np.linalg.inv(c["G_WC_true"]) @ G_WO)
            right = dp <= SUCCESS_POSITION_M and dr <= SUCCESS_ORIENTATION_DEG
            rows.append(dict(key=key, right=right, dp=dp, dr=dr, n=c["n_explained"], v=c["n_visible"]))
    print(f"{len(rows)} pose checks in {len({r['key'] for r in rows})} trials\n")
    for r in sorted(rows, key=lambda r: r["n"] / max(r["v"], 1)):
        print(
            f"{r['key']}: {'right' if r['right'] else 'WRONG'} ({r['dp'] * 100:.1f} cm, {r['dr']:.1f} deg), "
            f"explains {r['n']} of {r['v']} ({100 * r['n'] / max(r['v'], 1):.1f} %)"
        )
    print("\n| min_explained, min_fraction | right poses passed | wrong poses stopped |\n|---|---|---|")
    for m, f in THRESHOLDS:
        ok = [r["n"] >= m and r["n"] >= f * r["v"] for r in rows]
        nr = sum(r["right"] for r in rows)
        print(
            f"| {m}, {f:.0%} | {sum(o for o, r in zip(ok, rows, strict=True) if r['right'])} of {nr} | "
            f"{sum(not o for o, r in zip(ok, rows, strict=True) if not r['right'])} of {len(rows) - nr} |"
        )
    turned_checks(out)
    print(
        f"\nmarks cleared under the robot (navigator): {len(cleared)} times in "
        f"{len({k for k, _ in cleared})} trials: {cleared}"
    )


def search_figures(out: Path) -> None:
    """The trials' find times against budgets, and the revisits: a cell approached from another side
    because it (own) or only a neighbour (neighbour: the rule of a neighbour's answered-for cell) was
    searched before, and whether the local search that followed found the object."""
    import json

    res = [json.loads(p.read_text()) for p in sorted((out / "jobs").glob("*.json"))]
    ok = sorted(r["sim_time_s"] for r in res if r["success"])
    print(f"{len(res)} trials, {len(ok)} successes; success sim times [s]: {[round(t) for t in ok]}")
    for b in (90, 150, 200, 300, 400, 600):
        print(f"  within {b} s: {sum(t <= b for t in ok)} of {len(res)}")
    for r in res:
        if not r["success"]:
            print(
                f"  miss: {r['object']} {r['surface']} s{r['seed']} obstacles={bool(r['obstacles'])}: "
                f"{r['reason']} at {r['sim_time_s']} s"
            )
    kinds = {"own": [0, 0], "neighbour": [0, 0]}
    for r in res:
        ev, searched = r["events"], set()
        for i, e in enumerate(ev):
            cell = tuple(e["cell"]) if e["cell"] else None
            if e["kind"] == "navigate" and "from another side" in e["detail"]:
                kind = "own" if cell in searched else "neighbour"
                nxt = next((f for f in ev[i + 1 :] if f["kind"] == "local"), None)
                kinds[kind][0] += 1
                kinds[kind][1] += bool(nxt and nxt["detail"].startswith("found"))
                print(
                    f"  revisit ({kind}) {r['object']} {r['surface']} s{r['seed']} "
                    f"obst={bool(r['obstacles'])} cell {cell}: {nxt['detail'][:60] if nxt else '-'}"
                )
            if e["kind"] == "local" and cell:
                searched.add(cell)
    for k, (n, f) in kinds.items():
        print(f"revisits of cells {k}-searched before: {n}, found at once after {f}")


def turned_checks(out: Path, turns_deg=(20.0, -20.0, 40.0, -40.0, 180.0)) -> None:
    """The unit-level replay: each recorded check's frame checked again at its pose turned about the
    world's vertical through the object (wrong poses, as the pose check's module docstring measured
    them on its test set-ups): which thresholds stop them."""
    from scipy.spatial.transform import Rotation

    from lab.geometry import se3
    from lab.search.pose_check import PoseCheckConfig, check_pose

    found = {t: [] for t in turns_deg}
    for p in sorted((out / "replay").glob("*.dbs.pkl")):
        key = p.name[: -len(".dbs.pkl")]
        dbs = pickle.loads(p.read_bytes())
        for c in pickle.loads((out / "replay" / f"{key}.checks.pkl").read_bytes()):
            if "frame" not in c:
                continue
            f, corr, camera, config, roi = pickle.loads(c["frame"])
            R_WO = c["G_WC_true"][:3, :3] @ c["G_CO"][:3, :3]
            v_O = R_WO.T @ np.array([0.0, 0.0, 1.0])  # the vertical in O
            for t in turns_deg:
                G = c["G_CO"] @ se3(Rotation.from_rotvec(np.radians(t) * v_O).as_matrix(), np.zeros(3))
                pc = check_pose(
                    f, corr, dbs[c["db"]], G, camera, PoseCheckConfig(min_explained=0, min_fraction=0.0), roi
                )
                found[t].append((pc.n_explained, pc.n_visible))
    print("\nthe same frames at their pose turned about the vertical (wrong poses): explained of visible")
    for t, xs in found.items():
        print(f"  turned {t:+.0f} deg: {sorted(xs, key=lambda x: x[0] / max(x[1], 1))}")
    print(
        "\n| min_explained, min_fraction | "
        + " | ".join(f"turned {t:+.0f} deg stopped" for t in turns_deg)
        + " |\n|---|"
        + "---|" * len(turns_deg)
    )
    for m, fr in THRESHOLDS:
        cells = [f"{sum(not (n >= m and n >= fr * v) for n, v in xs)} of {len(xs)}" for xs in found.values()]
        print(f"| {m}, {fr:.0%} | " + " | ".join(cells) + " |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("what", choices=("record", "replay", "pose-checks", "search-figures", "sightings"))
    ap.add_argument("--seeds", default="1-2", help="tuning seeds, e.g. 1-2 (record)")
    ap.add_argument("--error-scale", type=float, default=1.0, help="the profile's errors times this (record)")
    ap.add_argument("--survey-tour", action="store_true", help="a survey tour before each search (record)")
    ap.add_argument("--only", default="", help="only the jobs whose key contains this (record)")
    ap.add_argument("--sensing", default="realistic", help="a profile or sensing file (record)")
    ap.add_argument("--out", type=Path, required=True)
    a = ap.parse_args()
    if a.what == "record":
        seeds = parse_seeds(a.seeds)
        if any(s >= 1000 for s in seeds):
            raise SystemExit("replay_localizer: tuning seeds only (< 1000)")
        record(a.out, seeds, a.error_scale, a.survey_tour, a.only, a.sensing)
    elif a.what == "sightings":
        sightings(a.out)
    elif a.what == "replay":
        replay(a.out)
    elif a.what == "pose-checks":
        pose_checks(a.out)
    else:
        search_figures(a.out)


if __name__ == "__main__":
    main()
