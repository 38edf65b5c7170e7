"""The paper's figures, drawn from a real trial (headless): they hold what the run recorded."""

import numpy as np
import pytest
from search_standin import truth_navigator

from lab.navigation import Costmap, GridSpec
from lab.robot import StereoCamera
from lab.runs.search import run_search
from lab.scene import load_scene
from lab.viz.search import (
    draw_pose,
    fig2_global_search,
    fig5_trial,
    fig6_snapshots,
    panorama,
    write_figures,
)


def _trial(localization="odometry"):
    scene = load_scene("lab_room")
    return run_search(
        "toy_block",
        0,
        place=scene.body("toy_block").pose,
        max_time=120.0,
        navigate=truth_navigator,
        localization=localization,
    )


@pytest.fixture(scope="module")
def trial():
    return _trial()


@pytest.fixture(scope="module")
def localized_trial():
    return _trial("landmarks")


def test_fig2_shows_the_scan_peaks_and_the_map(trial):
    g = trial.trace.agent.globals_[0]
    fig = fig2_global_search(g, trial.trace.spec)
    assert len(fig.axes) >= 6
    # the map panel marks every used peak
    map_ax = fig.axes[4]
    assert len(map_ax.lines) == 1 + len(g.used_peaks)  # origin marker + one circle per peak


def test_fig5_and_fig6(trial, tmp_path):
    spec = GridSpec.from_bounds(-3, -4, 3, 4, 0.1)
    occ = np.zeros(spec.shape, bool)
    occ[10:15, 10:15] = True
    fig = fig5_trial(trial, Costmap.from_occupancy(spec, occ).state, spec)
    assert "6D pose" in fig.axes[2].get_title()
    fig.savefig(tmp_path / "fig5.png")
    fig6 = fig6_snapshots(trial)
    fig6.savefig(tmp_path / "fig6.png")
    assert (tmp_path / "fig5.png").stat().st_size > 10_000 and (tmp_path / "fig6.png").stat().st_size > 10_000
    pano = panorama(trial.trace.agent.globals_[0])
    assert pano.shape == (240, 6 * 320, 3)


def test_fig6_maps_share_one_scale_and_every_mark_is_named(trial):
    """One colour scale over all snapshots (one colourbar, log), axes in metres, and a legend entry for
    every kind of mark; the true object only where the truth is known."""
    import dataclasses

    fig = fig6_snapshots(trial)
    maps = [a for a in fig.axes if a.images and a.get_xlabel() == "x [m]"]
    assert maps
    norms = {(a.images[0].norm.vmin, a.images[0].norm.vmax) for a in maps}
    assert len(norms) == 1
    vmin, vmax = norms.pop()
    snaps = trial.trace.agent.snapshots
    shown = [s for s in snaps if s.label == "global search"][:1] + [
        s for s in snaps if s.label == "local search failed"
    ][:6]
    assert vmax == pytest.approx(max(float(s.P.max()) for s in shown)) and vmin == pytest.approx(1e-4 * vmax)
    assert type(maps[0].images[0].norm).__name__ == "LogNorm"
    assert sum(1 for a in fig.axes if a.get_label() == "<colorbar>") == 1
    assert maps[0].get_ylabel() == "y [m]"
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert labels[:3] == ["robot (line: heading)", "cell just searched", "cells searched before"]
    assert "true object" in labels
    no_truth = dataclasses.replace(trial, true_pose=None)
    assert "true object" not in [t.get_text() for t in fig6_snapshots(no_truth).legends[0].get_texts()]


def _path_lines(fig):
    """The trajectory panel's labelled lines, by label."""
    return {ln.get_label(): ln for ln in fig.axes[1].lines if not ln.get_label().startswith("_")}


def test_the_track_is_what_the_run_scored(localized_trial):
    """The recorded track ends where the scoring read the robot: its odometry and estimate are the
    JSON's final errors off its truth, the truth is the simulator's, and the estimate is the pose the
    agent used (the budgeted robot's trajectory), corrected by landmarks away from the odometry."""
    r = localized_trial
    tr = r.trace.track
    assert tr.localization == "landmarks" and tr.localized and tr.landmark_updates == r.landmark_updates >= 1
    assert tr.truth is not None and len(tr) >= 10 and np.all(np.diff(tr.t) >= 0)
    assert np.hypot(*(tr.odometry[-1, :2] - tr.truth[-1, :2])) == pytest.approx(r.odometry_error_m, abs=1e-9)
    assert np.hypot(*(tr.estimate[-1, :2] - tr.truth[-1, :2])) == pytest.approx(
        r.localization_error_m, abs=1e-9
    )
    x0, y0, heading_deg = load_scene("lab_room").robot_start  # the truth starts where the scene put it
    assert tr.truth[0] == pytest.approx([x0, y0, np.radians(heading_deg)], abs=1e-3)
    used = r.trace.trajectory  # (t, x, y, theta) of the pose the agent saw, every 0.2 s
    at = np.searchsorted(tr.t, used[:, 0])
    ok = (at < len(tr)) & (np.abs(tr.t[np.minimum(at, len(tr) - 1)] - used[:, 0]) < 1e-9)
    assert ok.sum() >= len(used) // 2
    assert tr.estimate[at[ok], :2] == pytest.approx(used[ok, 1:3], abs=1e-12)
    assert np.abs(tr.estimate[:, :2] - tr.odometry[:, :2]).max() > 1e-4  # the landmarks moved it


def test_fig5_draws_the_localized_path_beside_the_odometry_and_the_truth(localized_trial, trial):
    """With landmarks: the true, odometry and localized paths, each the recorded track, all in the
    legend; with odometry alone no localized path; without a truth neither the true path nor the
    true object (and the figure still draws)."""
    import dataclasses

    tr = localized_trial.trace.track
    fig = fig5_trial(localized_trial)
    lines = _path_lines(fig)
    for label, xy in (
        ("true path", tr.truth),
        ("odometry", tr.odometry),
        ("localized (landmarks)", tr.estimate),
    ):
        assert np.array_equal(lines[label].get_xydata(), xy[:, :2]), label
    legend = [t.get_text() for t in fig.axes[1].get_legend().get_texts()]
    assert legend == ["true path", "odometry", "localized (landmarks)", "object (truth)"]
    title = fig.axes[1].get_title()
    assert f"odometry {100 * localized_trial.odometry_error_m:.1f} cm" in title
    assert f"localized {100 * localized_trial.localization_error_m:.1f} cm" in title

    legend = [t.get_text() for t in fig5_trial(trial).axes[1].get_legend().get_texts()]
    assert legend == ["true path", "odometry", "object (truth)"]

    no_truth_track = dataclasses.replace(tr, truth=None)
    no_truth = dataclasses.replace(
        localized_trial,
        true_pose=None,
        odometry_error_m=None,
        localization_error_m=None,
        trace=dataclasses.replace(localized_trial.trace, track=no_truth_track),
    )
    fig = fig5_trial(no_truth)
    assert list(_path_lines(fig)) == ["odometry", "localized (landmarks)"]
    assert "off the truth" not in fig.axes[1].get_title()


def test_draw_pose_draws_the_box_where_it_projects():
    cam = StereoCamera.from_fov()
    img = np.zeros((240, 320, 3), np.uint8)
    G = np.eye(4)
    G[:3, 3] = (0.0, 0.0, 1.0)
    out = draw_pose(img, G, (0.2, 0.2, 0.2), cam)
    ys, xs = np.nonzero(out.any(axis=2))
    assert abs(xs.mean() - cam.cx) < 15 and abs(ys.mean() - cam.cy) < 15  # around the centre
    assert xs.min() > cam.cx - 0.2 * cam.fx / 0.9 - 3  # and no wider than the near face
    assert not img.any()  # a copy was drawn on


def test_write_figures_writes_every_snapshot(trial, tmp_path):
    spec = GridSpec.from_bounds(-3, -4, 3, 4, 0.1)
    state = np.ones(spec.shape, np.int8)  # all free
    files = write_figures(trial, tmp_path / "out", state, spec)
    names = sorted(f.name for f in files)
    n = len(trial.trace.agent.snapshots)
    assert n >= 1
    maps = [f"map_{k:02d}.png" for k in range(n)]
    assert names == sorted(["fig2_global_search.png", "fig5_trial.png", "fig6_snapshots.png", *maps])
    for f in files:
        assert f.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and f.stat().st_size > 5_000, f.name
    assert not list((tmp_path / "out").glob(".*tmp*"))  # atomic: no temporary file left behind


_FRESH = """
import json, sys
sys.path.insert(0, {tests!r})
import test_search_figures as t
r = t._trial()
print(json.dumps({{"events": [e.as_dict() for e in r.events], "estimated_pose": r.estimated_pose}}))
"""


def test_a_trial_repeats_after_another_and_in_a_fresh_process(trial):
    """The same trial run again in this process (after the fixture's, and whatever this worker ran
    before) and in a fresh interpreter gives the same events and the same estimated pose: no state
    (random generators, caches, the renderer, the matchers) carries from one trial to the next."""
    import json
    import subprocess
    import sys
    from pathlib import Path

    again = _trial()
    code = _FRESH.format(tests=str(Path(__file__).parent))
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    fresh = json.loads(r.stdout.strip().splitlines()[-1])
    first = [e.as_dict() for e in trial.events]
    assert len(first) >= 3  # a global search, a drive and a local search at least
    assert [e.as_dict() for e in again.events] == first
    assert again.estimated_pose == trial.estimated_pose
    assert fresh["events"] == json.loads(json.dumps(first)) and fresh["estimated_pose"] == json.loads(
        json.dumps(trial.estimated_pose)
    )
