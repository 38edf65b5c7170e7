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


def _trial():
    scene = load_scene("lab_room")
    return run_search(
        "toy_block", 0, place=scene.body("toy_block").pose, max_time=120.0, navigate=truth_navigator
    )


@pytest.fixture(scope="module")
def trial():
    return _trial()


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
