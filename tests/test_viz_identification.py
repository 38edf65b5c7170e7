"""The identification figures draw what they are given (checked on the artists, not by eye)."""

import matplotlib

matplotlib.use("Agg")
import numpy as np  # noqa: E402

from lab.viz.identification import fig5, fig6, fig7  # noqa: E402


def test_fig5_fig6_fig7_draw_their_data():
    t = np.linspace(0, 10, 21)
    P = np.tile([0.25, 0.25, 0.25, 0.25], (21, 1))
    P[12:] = [0.02, 0.94, 0.02, 0.02]
    modes = ["scanning"] * 5 + ["tracking"] * 16
    est = np.c_[np.ones(21), np.zeros(21), 0.5 * np.ones(21), np.zeros(21)]
    f = fig5(t, est, est + 0.01, P, modes, decisions=[2.0, 6.0], true_model=1)
    ax = f.axes[2]
    assert len(ax.lines) == 4 + 2  # four models and two planning markers
    np.testing.assert_allclose(ax.lines[1].get_ydata(), P[:, 1])
    assert len(ax.patches) == 2  # the scanning and the tracking band
    a = np.radians(np.arange(0, 360, 10))
    cand = np.c_[np.cos(a), np.sin(a), a + np.pi]
    gains = np.linspace(0, 1, 36)
    gains[3] = np.nan
    f = fig6(
        cand, gains, chosen=35, robot_xy_theta=(-1, 0, 0), object_xy=(0, 0), object_cov_xy=np.eye(2) * 0.01
    )
    sc = f.axes[0].collections[0]
    assert len(sc.get_offsets()) == 35  # the blocked candidate is drawn apart
    f = fig7(
        [{"t": t, "posteriors": P, "true_model": 1}, {"t": t, "posteriors": P[:, ::-1], "true_model": 2}]
    )
    assert len(f.axes) == 2


def _track(localization="landmarks", truth=True, updates=3):
    from lab.runs.tracks import RobotTrack

    t = np.linspace(0.0, 4.0, 9)
    true = np.c_[-1.2 + 0.1 * t, 0.05 * t**2, 0.1 * t]
    odom = true + np.c_[0.02 * t, -0.01 * t, 0.0 * t]  # drifting wheels
    est = true + 0.003
    return RobotTrack(
        t,
        odom,
        est if localization == "landmarks" else odom,
        true if truth else None,
        localization,
        updates if localization == "landmarks" else 0,
    )


def _ring():
    a = np.radians(np.arange(0, 360, 30))
    return np.c_[1.2 * np.cos(a), 1.2 * np.sin(a), a + np.pi], np.linspace(0, 1, 12)


def test_fig6_draws_the_robots_track_three_ways():
    """The true, odometry and localized paths are the track's, each named in the legend; with odometry
    alone there is no localized path, without a truth no true path; without a track the frames' path."""
    cand, gains = _ring()
    tr = _track()
    f = fig6(cand, gains, 3, tr.estimate[-1], (0, 0), path_xy=tr.estimate[:, :2], track=tr)
    lines = {ln.get_label(): ln for ln in f.axes[0].lines}
    for label, xy in (
        ("true path", tr.truth),
        ("odometry", tr.odometry),
        ("localized (landmarks)", tr.estimate),
    ):
        np.testing.assert_array_equal(lines[label].get_xydata(), xy[:, :2])
    assert "path" not in lines  # the track replaces the frames' path
    legend = {t.get_text() for t in f.axes[0].get_legend().get_texts()}
    assert {"true path", "odometry", "localized (landmarks)", "next-best view"} <= legend
    f = fig6(cand, gains, 3, tr.estimate[-1], (0, 0), track=_track("odometry", truth=False))
    legend = {t.get_text() for t in f.axes[0].get_legend().get_texts()}
    assert "odometry" in legend and not legend & {"true path", "localized (landmarks)"}
    # localized against landmarks, none of which was seen: the label says the estimate is dead reckoning
    f = fig6(cand, gains, 3, tr.estimate[-1], (0, 0), track=_track(updates=0))
    legend = {t.get_text() for t in f.axes[0].get_legend().get_texts()}
    assert "localized (no landmark seen)" in legend and "localized (landmarks)" not in legend
    f = fig6(cand, gains, 3, tr.estimate[-1], (0, 0), path_xy=tr.estimate[:, :2])
    assert "path" in {t.get_text() for t in f.axes[0].get_legend().get_texts()}


def test_drive_figure_names_every_poster_inside_the_room_and_leaves_the_backend_alone(tmp_path):
    """The localization benchmark's figure: each landmark's name sits inside the room on the side its
    face looks at (none cut off at the plot's edge), the legend does not cover the room, and writing it
    does not switch the caller's matplotlib backend (a notebook's inline one)."""
    from types import SimpleNamespace

    import matplotlib
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from lab.training.landmarks import landmark_map_from_scene
    from lab.viz.localization import drive_figure, trajectories_axes

    t = np.linspace(0.0, 30.0, 60)
    xy = np.c_[2 * np.cos(t / 5), 3 * np.sin(t / 5), t / 5]
    tr = np.c_[t, xy, xy + 0.01, xy + 0.001]
    runs = [
        SimpleNamespace(trajectory=tr, ellipses=e, seed=1, odometry_error_m=0.4, localization_error_m=0.01,
                        nees=np.full(5, 2.0))
        for e in ([], [(xy[30], np.diag([1e-4, 2e-4, 1e-5]))])
    ]  # fmt: skip
    landmarks = landmark_map_from_scene("lab_room")
    backend = matplotlib.get_backend()
    assert drive_figure(*runs, tmp_path / "d.png", landmarks).stat().st_size > 10_000
    assert matplotlib.get_backend() == backend

    fig = Figure(figsize=(8, 5), layout="constrained")
    ax = fig.subplots()
    trajectories_axes(ax, *runs, landmarks)
    renderer = FigureCanvasAgg(fig).get_renderer()
    fig.draw(renderer)
    box = ax.get_window_extent(renderer)
    names = {a.get_text(): a for a in ax.texts}
    assert set(names) == {lm.name for lm in landmarks}
    for lm in landmarks:
        text = names[lm.name].get_window_extent(renderer)
        assert box.x0 <= text.x0 and text.x1 <= box.x1 and box.y0 <= text.y0 and text.y1 <= box.y1, lm.name
    assert not ax.get_legend().get_window_extent(renderer).overlaps(box)
