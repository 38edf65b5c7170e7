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
    trial_panels,
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


def test_fig6_follows_the_whole_trial(trial):
    """One panel per map snapshot (every global scan and every failed local search changed the map), in
    order, then the end: the cells each searched, the cells the local searches covered before it (from
    the run's events), and the found cell."""
    agent = trial.trace.agent
    panels = trial_panels(trial)
    snaps = agent.snapshots
    assert len(snaps) >= 1
    assert [(p.t, p.cell) for p in panels[: len(snaps)]] == [(s.t, s.cell) for s in snaps]
    assert all(p.P is s.P for p, s in zip(panels, snaps, strict=False))
    locals_ = [e for e in agent.events if e.kind == "local" and e.cell is not None]
    for p in panels[: len(snaps)]:
        want = {e.cell for e in locals_ if e.t <= p.t} - {p.cell}
        assert set(p.searched_before) == want
    scans = [p for p in panels if p.cell is None and p.found_cell is None]
    assert len(scans) == len(agent.globals_)
    for p, g in zip(scans, agent.globals_, strict=True):  # each scan's used colour peaks
        assert np.allclose(p.peaks_xy, [q.p_W[:2] for q in g.used_peaks])
    if trial.found:
        end = panels[-1]
        found = [e for e in locals_ if "found:" in e.detail and "not found" not in e.detail]
        assert len(panels) == len(snaps) + 1 and end.found_cell == found[-1].cell
        assert np.array_equal(end.P, agent.P_final)
    fig = fig6_snapshots(trial)
    maps = [a for a in fig.axes if a.images and a.images[0].get_array().shape == panels[0].P.T.shape]
    assert len(maps) == len(panels)  # every panel drawn, nothing else looks like a map
    assert [a.get_title().split("\n")[0] for a in maps] == [f"t = {p.t:.0f} s" for p in panels]


def _longer_trial(trial):
    """The trial with a longer record made up from its own maps: a scan, two failed local searches (the
    first with a side look at its cell), a second scan, then the found search."""
    import dataclasses

    from lab.search.records import MapSnapshot, SearchEvent

    agent = trial.trace.agent
    P0 = agent.snapshots[0].P
    rng = np.random.default_rng(0)
    maps = [P0 * rng.uniform(0.5, 2.0, P0.shape) for _ in range(4)]
    maps = [m / m.sum() for m in maps]
    pose = agent.snapshots[0].pose
    snaps = (
        MapSnapshot(1.0, maps[0], "global search", None, pose),
        MapSnapshot(2.0, maps[1], "local search failed", (3, 4), pose),
        MapSnapshot(3.0, maps[2], "local search failed", (5, 6), pose),
        MapSnapshot(4.0, maps[3], "global search", None, pose),
    )
    events = (
        SearchEvent(1.0, "global"),
        SearchEvent(2.0, "local", (3, 4), "not found"),
        SearchEvent(2.5, "local", (3, 4), "side look: not found"),
        SearchEvent(3.0, "local", (5, 6), "not found"),
        SearchEvent(4.0, "global"),
        SearchEvent(5.0, "local", (7, 8), "side look: found: 4 confirming updates"),  # found by a side look
    )
    agent = dataclasses.replace(
        agent, snapshots=snaps, events=events, globals_=(agent.globals_[0],) * 2, P_final=maps[3]
    )
    return dataclasses.replace(trial, trace=dataclasses.replace(trial.trace, agent=agent))


def test_fig6_panels_of_a_longer_record(trial):
    """Every snapshot a panel, the cells searched before each (side looks too, no repeats), the end
    panel at the found search, and a grid with no empty slot but the legend's."""
    longer = _longer_trial(trial)
    panels = trial_panels(longer)
    assert [p.t for p in panels] == [1.0, 2.0, 3.0, 4.0, 5.0]
    assert [p.searched_before for p in panels] == [(), (), ((3, 4),), ((3, 4), (5, 6)), ((3, 4), (5, 6))]
    assert [p.cell for p in panels] == [None, (3, 4), (5, 6), None, None]
    assert panels[-1].found_cell == (7, 8) and panels[-1].what == "found at cell (7, 8)"
    assert [p.peaks_xy is not None for p in panels] == [True, False, False, True, False]
    fig = fig6_snapshots(longer)
    maps = [a for a in fig.axes if a.images and a.images[0].get_array().shape == panels[0].P.T.shape]
    assert len(maps) == 5
    boxes = sorted({(round(a.get_position().x0, 3), round(a.get_position().y0, 3)) for a in maps})
    assert len({y for _, y in boxes}) == 2 and len({x for x, _ in boxes}) == 3  # 3 across, 2 rows
    slot = [a for a in fig.axes if a.get_legend() is not None and not a.images]
    assert len(slot) == 1  # the legend fills the grid's one empty slot
    norm = maps[0].images[0].norm
    assert norm.vmin == pytest.approx(min(float(p.P.min()) for p in panels))


def test_fig6_maps_share_one_log_scale_spanning_the_data(trial):
    """One colour scale over all panels (one colourbar, log), its limits the smallest and the largest
    cell of the maps drawn; no panel is one colour on it."""
    from matplotlib.colors import LogNorm

    fig = fig6_snapshots(trial)
    panels = trial_panels(trial)
    maps = [a for a in fig.axes if a.images and a.images[0].get_array().shape == panels[0].P.T.shape]
    assert len(maps) == len(panels)
    norms = {id(a.images[0].norm) for a in maps}
    assert len(norms) == 1
    norm = maps[0].images[0].norm
    assert isinstance(norm, LogNorm)
    assert norm.vmax == pytest.approx(max(float(p.P.max()) for p in panels))
    assert norm.vmin == pytest.approx(min(float(p.P.min()) for p in panels))
    for a, p in zip(maps, panels, strict=True):
        colours = a.images[0].to_rgba(a.images[0].get_array(), bytes=True).reshape(-1, 4)
        assert len(np.unique(colours, axis=0)) >= 2, a.get_title()
        assert np.array_equal(np.asarray(a.images[0].get_array()), np.maximum(p.P.T, norm.vmin))
    assert sum(1 for a in fig.axes if a.get_label() == "<colorbar>") == 1


def test_map_norm_spans_the_maps_and_ignores_zero_cells():
    from lab.viz.search import MAX_DECADES, map_norm

    a = np.full((3, 3), 0.1)
    b = np.array([[0.0, 1e-3], [0.5, 0.2]])
    n = map_norm([a, b])
    assert (n.vmin, n.vmax) == (pytest.approx(1e-3), pytest.approx(0.5))
    n = map_norm([np.array([[1.0, 1e-30]])])  # at most MAX_DECADES decades
    assert n.vmin == pytest.approx(10.0**-MAX_DECADES)
    n = map_norm([np.full((2, 2), 0.25)])  # a uniform map still has a scale
    assert 0 < n.vmin < n.vmax == 0.25


def test_fig6_marks_are_named_and_the_truth_only_where_known(trial):
    import dataclasses

    fig = fig6_snapshots(trial)
    labels = [
        t.get_text()
        for a in [*fig.axes, fig]
        for lg in [a.get_legend() if hasattr(a, "get_legend") else None, *getattr(a, "legends", [])]
        if lg is not None
        for t in lg.get_texts()
    ]
    for want in (
        "robot (arrow: heading)",
        "robot's path so far",
        "cell just searched",
        "cells searched before",
        "colour peaks",
        "object (truth)",
    ):
        assert want in labels, want
    no_truth = dataclasses.replace(trial, true_pose=None)
    fig = fig6_snapshots(no_truth)
    labels = [
        t.get_text()
        for a in [*fig.axes, fig]
        for lg in [a.get_legend() if hasattr(a, "get_legend") else None, *getattr(a, "legends", [])]
        if lg is not None
        for t in lg.get_texts()
    ]
    assert "object (truth)" not in labels and "cell just searched" in labels


def test_fig5_first_map_is_on_the_trials_log_scale(trial):
    """The map after the first global search on the trial's log scale (the snapshots' range), with a
    colourbar: the prior's level and the colour peaks' cells get different colours, and the peaks are
    circled."""
    fig = fig5_trial(trial)
    a = fig.axes[0]
    im = a.images[0]
    snaps = trial.trace.agent.snapshots
    first = next(s for s in snaps if s.label == "global search")
    assert type(im.norm).__name__ == "LogNorm"
    assert im.norm.vmin == pytest.approx(min(float(s.P.min()) for s in snaps))
    assert im.norm.vmax == pytest.approx(max(float(s.P.max()) for s in snaps))
    colours = im.to_rgba(first.P, bytes=True).reshape(-1, 4)
    assert len(np.unique(colours, axis=0)) >= 2
    g = trial.trace.agent.globals_[0]
    lo, hi = im.norm(first.P.min()), im.norm(first.P.max())
    if g.used_peaks:
        assert hi - lo > 0.1  # a peak's cell stands out from the prior's level
        circles = [ln for ln in a.lines if ln.get_label() == "colour peaks"]
        assert np.allclose(circles[0].get_xydata(), [p.p_W[:2] for p in g.used_peaks])
    assert sum(1 for ax in fig.axes if ax.get_label() == "<colorbar>") == 1


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
    # at least a third of the agent's samples fall on a recorded one (both sample every 0.2 s of a clock
    # that starts after the camera's levelling, so their phases drift apart by rounding)
    assert ok.sum() >= len(used) // 3
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
