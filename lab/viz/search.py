"""Figures like the search paper's, drawn from what the search records (the algorithms never plot).

* :func:`fig2_global_search`: the object's colour model, one scan view with its colour peaks circled,
  the back-projection (window means), the peaks projected onto ``M_p``, and the growing beta of one
  peak (the paper's Fig. 2).
* :func:`fig5_trial`: the probability map after the first global search with the first planned path and
  its goal, the costmap (when given) with the robot's path -- the wheel odometry's, the localized one
  (``landmarks`` localization) and the true one (where the truth is known) --, and the 6D pose drawn on
  the image of the successful local search (the paper's Fig. 5).
* :func:`fig6_snapshots`: the panorama of the first scan and the map after each failed local search
  (the paper's Fig. 6).
* :func:`draw_pose`: a picture of an estimated pose: the object's box and axes projected on an image.
* :func:`write_figures`: all of them for one trial, plus every map snapshot, as PNG files (``lab search
  --out``).

Each returns a :class:`matplotlib.figure.Figure` (no window is opened; save it with ``savefig``). Maps
are shown the right way up (``P.T`` with ``origin="lower"``, world x to the right, y up).
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from lab.geometry import transform_points
from lab.robot import StereoCamera
from lab.search.global_search import GlobalSearchResult
from lab.search.probability_map import detection_likelihood, growing_beta_field
from lab.viz.localization import PATH_STYLES, draw_track

__all__ = [
    "draw_pose",
    "fig2_global_search",
    "fig5_trial",
    "fig6_snapshots",
    "panorama",
    "snapshot_figure",
    "write_figures",
]


def _figure(rows: int, cols: int, size=(4.0, 3.2)):
    from matplotlib.figure import Figure

    fig = Figure(figsize=(size[0] * cols, size[1] * rows), layout="constrained")
    axes = fig.subplots(rows, cols, squeeze=False)
    return fig, axes


def _show_map(ax, P: np.ndarray, spec, title: str, cmap="viridis"):
    x0, x1, y0, y1 = spec.extent
    im = ax.imshow(P.T, origin="lower", extent=(x0, x1, y0, y1), cmap=cmap, interpolation="nearest")
    ax.set_title(title)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.plot([0], [0], "+", color="lime", ms=10, mew=2)  # the world origin (the paper's green frame)
    return im


def draw_pose(
    image: np.ndarray, G_CO: np.ndarray, extent, camera: StereoCamera, colour=(255, 0, 0)
) -> np.ndarray:
    """The object's box (edges) and axes (x red, y green, z blue) at pose ``G_CO``, drawn on a copy."""
    out = image.copy()
    h = 0.5 * np.asarray(extent, dtype=float)
    corners = np.array(
        [[sx * h[0], sy * h[1], sz * h[2]] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]
    )
    p = transform_points(G_CO, corners)
    if np.any(p[:, 2] <= 0.01):
        return out
    uv = np.round(camera.project(p)).astype(int)
    for a in range(8):
        for b in range(a + 1, 8):
            if bin(a ^ b).count("1") == 1:  # corners that differ in one coordinate share an edge
                cv2.line(out, tuple(uv[a]), tuple(uv[b]), colour, 1, cv2.LINE_AA)
    L = 0.6 * float(max(extent))
    axes = transform_points(G_CO, np.array([[0, 0, 0], [L, 0, 0], [0, L, 0], [0, 0, L]], dtype=float))
    if np.all(axes[:, 2] > 0.01):
        a_uv = np.round(camera.project(axes)).astype(int)
        for k, c in enumerate(((255, 0, 0), (0, 200, 0), (0, 0, 255))):
            cv2.line(out, tuple(a_uv[0]), tuple(a_uv[k + 1]), c, 2, cv2.LINE_AA)
    return out


def panorama(result: GlobalSearchResult, tilt: float | None = None) -> np.ndarray:
    """The scan's left images at one tilt (the one nearest level by default), left to right from the
    largest pan (the robot's left) to the smallest: a panoramic view like the paper's Fig. 6."""
    tilts = np.array([v.frame.pan_tilt.tilt for v in result.views])
    t = tilts[np.argmin(np.abs(tilts))] if tilt is None else tilt
    row = [v for v in result.views if abs(v.frame.pan_tilt.tilt - t) < 1e-6]
    row.sort(key=lambda v: -v.frame.pan_tilt.pan)
    return np.concatenate([v.frame.left for v in row], axis=1)


def fig2_global_search(result: GlobalSearchResult, spec, db=None, view: int | None = None, object_image=None):
    """The paper's Fig. 2 for one global search.

    Parameters
    ----------
    result : GlobalSearchResult
    spec : GridSpec
        The probability map's grid.
    db : FeatureDatabase, optional
        For the model histogram panel (else the back-projected ratio model is shown).
    view : int, optional
        The view to show (default: the one with the strongest used peak).
    object_image : ndarray, optional
        A picture of the object (top-left panel); the colour model is shown in its place if omitted.
    """
    fig, ax = _figure(2, 3)
    used = result.used_peaks
    if view is None:
        view = max(used, key=lambda p: p.strength).view if used else 0
    v = result.views[view]
    # top row: object, its histogram, the view with its peaks
    if object_image is not None:
        ax[0, 0].imshow(object_image)
        ax[0, 0].set_title("object")
    else:
        ax[0, 0].imshow(result.colour_model, origin="lower", extent=(0, 1, 0, 1), cmap="magma")
        ax[0, 0].set_title("back-projected model R(r, g)")
        ax[0, 0].set_xlabel("g")
        ax[0, 0].set_ylabel("r")
    hist = db.histogram if db is not None else result.colour_model
    ax[0, 1].imshow(hist, origin="lower", extent=(0, 1, 0, 1), cmap="magma")
    ax[0, 1].set_title("model histogram (red-green chromaticity)")
    ax[0, 1].set_xlabel("g")
    ax[0, 1].set_ylabel("r")
    img = v.frame.left.copy()
    for p in v.peaks:
        colour = (255, 0, 0) if p.used else (255, 200, 0)
        cv2.circle(img, (int(p.uv[0]), int(p.uv[1])), 9, colour, 2)
    pan, tilt = math.degrees(v.frame.pan_tilt.pan), math.degrees(v.frame.pan_tilt.tilt)
    ax[0, 2].imshow(img)
    ax[0, 2].set_title(f"view {view} (pan {pan:.0f}, tilt {tilt:.0f} deg): peaks")
    ax[0, 2].axis("off")
    # bottom row: back-projection, map with peaks, growing beta of the strongest peak
    ax[1, 0].imshow(v.window_mean, cmap="gray", vmin=0, vmax=1)
    ax[1, 0].set_title("back-projection, window mean")
    ax[1, 0].axis("off")
    _show_map(ax[1, 1], result.P_after, spec, "M_p after the global search")
    for p in used:
        ax[1, 1].plot(p.p_W[0], p.p_W[1], "o", mfc="none", mec="red", ms=8)
    if used:
        best = max(used, key=lambda p: p.strength)
        B = growing_beta_field(spec, best.cell, 0.05, max(0.1, 1 - best.strength), 0.2)
        im = _show_map(
            ax[1, 2], detection_likelihood(1, B), spec, "P(y=1 | h_ij) of the strongest peak", "magma"
        )
        fig.colorbar(im, ax=ax[1, 2], shrink=0.8)
    else:
        ax[1, 2].set_title("no colour peak used")
        ax[1, 2].axis("off")
    return fig


def fig5_trial(result, costmap_state: np.ndarray | None = None, costmap_spec=None):
    """The paper's Fig. 5 for one trial (a :class:`~lab.runs.search.SearchResult`).

    Parameters
    ----------
    result : SearchResult
    costmap_state : ndarray, optional
        Costmap labels (``lab.navigation.CellState`` values) to show under the trajectory, e.g. the
        Navigator's final ``Costmap.state``; without it only the trajectory is drawn. The trajectory
        panel draws the robot's track (``result.trace.track``): the wheel odometry, the localized
        estimate when the trial localized against landmarks, and the true path and object where the
        truth is known (:func:`lab.viz.localization.draw_track`), with a legend; its title gives the
        final errors.
    costmap_spec : GridSpec, optional
        The costmap's grid.
    """
    tr = result.trace
    agent, spec = tr.agent, tr.spec
    fig, ax = _figure(1, 3)
    first = next((s for s in agent.snapshots if s.label == "global search"), None)
    P = first.P if first is not None else agent.P_final
    _show_map(ax[0, 0], P, spec, "M_p after the first global search")
    if agent.nav_paths:
        goal, path = agent.nav_paths[0]
        if path is not None and len(path):
            ax[0, 0].plot(path[:, 0], path[:, 1], "-", color="yellow", lw=2, label="planned path")
        ax[0, 0].plot(goal[0], goal[1], "s", mfc="none", mec="red", ms=9, mew=2, label="goal")
        ax[0, 0].legend(loc="lower right", fontsize=7)
    # costmap and trajectory
    x0, x1, y0, y1 = spec.extent
    if costmap_state is not None and costmap_spec is not None:
        cx0, cx1, cy0, cy1 = costmap_spec.extent
        shade = np.choose(
            np.asarray(costmap_state, int), [0.5, 0.0, 1.0]
        )  # unknown grey, free black, obstacle white
        ax[0, 1].imshow(shade.T, origin="lower", extent=(cx0, cx1, cy0, cy1), cmap="gray", vmin=0, vmax=1)
    else:
        ax[0, 1].set_facecolor("0.2")
    _draw_paths(ax[0, 1], tr)
    truth = _true_xy(result)
    if truth is not None:
        ax[0, 1].plot(*truth, "*", color="orange", ms=12, label="object (truth)")
    ax[0, 1].set_xlim(x0, x1)
    ax[0, 1].set_ylim(y0, y1)
    ax[0, 1].set_aspect("equal")
    title = "costmap and trajectory" if costmap_state is not None else "trajectory"
    ax[0, 1].set_title(title + _end_errors(result), fontsize=9)
    # below the panel: inside it the legend hides the paths near the room's edges
    ax[0, 1].legend(loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=2, fontsize=7, frameon=False)
    # the pose on the image
    loc = agent.local
    if loc is not None and loc.found and loc.frame is not None:
        ext = result.trace.db.extent  # the database the agent searched with
        ax[0, 2].imshow(draw_pose(loc.frame.left, loc.estimate.G_CO, ext, loc.frame.camera))
        ax[0, 2].set_title(
            f"6D pose: {result.position_error_m * 100:.1f} cm, {result.orientation_error_deg:.1f} deg"
        )
    else:
        ax[0, 2].set_title(f"not found: {result.reason}")
    ax[0, 2].axis("off")
    return fig


def _draw_paths(ax, trace) -> None:
    """The robot's path on ``ax``: the trial's track (:func:`lab.viz.localization.draw_track`); a trace
    without one (recorded before tracks were) draws its single trajectory as the odometry."""
    track = getattr(trace, "track", None)
    if track is not None and len(track):
        draw_track(ax, track)
    elif len(trace.trajectory):
        colour, ls, lw, label = PATH_STYLES["odometry"]
        ax.plot(trace.trajectory[:, 1], trace.trajectory[:, 2], ls=ls, color=colour, lw=lw, label=label)


def _end_errors(result) -> str:
    """The run's final robot position errors against the truth, for a title ("" without a truth)."""
    odo, loc = getattr(result, "odometry_error_m", None), getattr(result, "localization_error_m", None)
    if odo is None:
        return ""
    text = f"\nat the end: odometry {100 * odo:.1f} cm"
    if getattr(result, "localization", "odometry") == "landmarks" and loc is not None:
        text += f", localized {100 * loc:.1f} cm"
    return text + " off the truth"


def _map_norm(maps):
    """One colour scale for maps of a probability ``P``: logarithmic from 1e-4 of the largest cell up
    (the mass the searches moved spans decades, a linear scale shows only the peak)."""
    from matplotlib.colors import LogNorm

    vmax = max(float(m.max()) for m in maps)
    return LogNorm(vmin=max(vmax * 1e-4, 1e-12), vmax=max(vmax, 1e-11), clip=True)


def _true_xy(result):
    """The true object position (world x, y) of a trial, or None where there is no truth."""
    pose = getattr(result, "true_pose", None)
    if not pose or pose.get("position_m") is None:
        return None
    return pose["position_m"][0], pose["position_m"][1]


def fig6_snapshots(result, max_snapshots: int = 6):
    """The paper's Fig. 6: the first scan's panorama, and ``M_p`` after each failed local search.

    All maps share one logarithmic colour scale (one colourbar), so a panel that looks brighter holds
    more probability. Each panel marks the robot where the snapshot was taken, the cell just searched,
    the cells searched before it and, where the truth is known (the simulator; the robot with
    ``--truth``), the true object; the legend names every mark.
    """
    from matplotlib.lines import Line2D

    agent, spec = result.trace.agent, result.trace.spec
    snaps = [s for s in agent.snapshots if s.label == "local search failed"][:max_snapshots]
    first = next((s for s in agent.snapshots if s.label == "global search"), None)
    maps = ([first] if first is not None else []) + snaps
    n = max(1, len(maps))
    from matplotlib.figure import Figure

    fig = Figure(figsize=(2.6 * n + 1.2, 6.8), layout="constrained")
    gs = fig.add_gridspec(2, n, height_ratios=(1.0, 1.7))
    top = fig.add_subplot(gs[0, :])
    if agent.globals_:
        top.imshow(panorama(agent.globals_[0]))
    top.set_title("panorama of the first scan (robot's left on the left)")
    top.axis("off")
    norm = _map_norm([s.P for s in maps]) if maps else None
    truth = _true_xy(result)
    x0, x1, y0, y1 = spec.extent
    searched: list[tuple[float, float]] = []
    axes, im = [], None
    for k, s in enumerate(maps):
        a = fig.add_subplot(gs[1, k], sharey=axes[0] if axes else None)
        axes.append(a)
        im = a.imshow(
            np.maximum(s.P.T, norm.vmin), origin="lower", extent=(x0, x1, y0, y1), cmap="viridis", norm=norm
        )
        if searched:
            xs, ys = zip(*searched, strict=True)
            a.plot(xs, ys, "s", mfc="none", mec="red", ms=5, mew=1)
        if s.cell is not None:
            cx, cy = spec.cell_to_world(*s.cell)
            a.plot(cx, cy, "x", color="red", ms=9, mew=2)
            searched.append((cx, cy))
        if s.pose is not None:
            a.plot(s.pose.x, s.pose.y, "o", color="white", mec="black", ms=5)
            a.plot(
                [s.pose.x, s.pose.x + 0.4 * math.cos(s.pose.theta)],
                [s.pose.y, s.pose.y + 0.4 * math.sin(s.pose.theta)],
                "-",
                color="white",
                lw=1.2,
            )
        if truth is not None:
            a.plot(*truth, "*", color="gold", mec="black", ms=11)
        what = "after the first global search" if s.cell is None else f"cell {s.cell} searched, not found"
        a.set_title(f"t = {s.t:.0f} s\n{what}", fontsize=8)
        a.set_xlabel("x [m]", fontsize=8)
        a.tick_params(labelsize=7)
        if k == 0:
            a.set_ylabel("y [m]", fontsize=8)
        else:
            a.tick_params(labelleft=False)
    if im is not None:
        fig.colorbar(im, ax=axes, shrink=0.9, label="P(object in cell), log scale")
    handles = [
        Line2D([], [], ls="none", marker="o", color="white", mec="black", label="robot (line: heading)"),
        Line2D([], [], ls="none", marker="x", color="red", mew=2, label="cell just searched"),
        Line2D([], [], ls="none", marker="s", mfc="none", mec="red", label="cells searched before"),
    ]
    if truth is not None:
        handles.append(
            Line2D([], [], ls="none", marker="*", color="gold", mec="black", ms=11, label="true object")
        )
    fig.legend(handles=handles, loc="outside lower center", ncol=len(handles), fontsize=8, frameon=False)
    return fig


def snapshot_figure(result, k: int):
    """One map snapshot (``result.trace.agent.snapshots[k]``) with the trajectory up to its time."""
    agent, spec, traj = result.trace.agent, result.trace.spec, result.trace.trajectory
    s = agent.snapshots[k]
    fig, ax = _figure(1, 1, size=(4.2, 5.0))
    a = ax[0, 0]
    im = _show_map(a, s.P, spec, f"M_p at t = {s.t:.0f} s, after {s.label}")
    im.set_norm(_map_norm([snap.P for snap in agent.snapshots]))  # the same scale in every map_NN.png
    im.set_data(np.maximum(s.P.T, im.norm.vmin))
    fig.colorbar(im, ax=a, shrink=0.8, label="P(object in cell), log scale")
    truth = _true_xy(result)
    if truth is not None:
        a.plot(*truth, "*", color="gold", mec="black", ms=11, label="true object")
    if len(traj):
        upto = traj[traj[:, 0] <= s.t + 1e-9]
        which = "localized" if getattr(result, "localization", "odometry") == "landmarks" else "odometry"
        a.plot(upto[:, 1], upto[:, 2], "-", color="magenta", lw=1.0, label=f"robot's path ({which})")
    if s.cell is not None:
        cx, cy = spec.cell_to_world(*s.cell)
        a.plot(cx, cy, "x", color="red", ms=9, mew=2, label="cell searched")
    a.lines[0].set_label("world origin")  # _show_map's first mark
    a.legend(loc="upper left", fontsize=7, framealpha=0.8)
    return fig


def _save(fig, path) -> None:
    """``savefig`` through :func:`lab.io.write_bytes_atomic` (never a half-written picture)."""
    import io

    from lab.io import write_bytes_atomic

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    write_bytes_atomic(path, buf.getvalue())


def write_figures(result, out, costmap_state: np.ndarray | None = None, costmap_spec=None) -> list:
    """Write the figures of one trial (a :class:`~lab.runs.search.SearchResult`) into the folder ``out``.

    Files: ``fig2_global_search.png`` (the first global search, when there was one),
    ``fig5_trial.png`` (map with the first planned path; costmap, when given, with the trajectory; the
    6D pose on the image), ``fig6_snapshots.png`` (panorama and the map after each failed local
    search), and ``map_NN.png`` for every map snapshot in order (the probability map after each global
    search and each failed local search, with the trajectory so far).

    Returns
    -------
    list of pathlib.Path
        The files written.
    """
    from pathlib import Path

    out = Path(out)
    agent, spec = result.trace.agent, result.trace.spec
    written = []

    def save(fig, name):
        _save(fig, out / name)
        written.append(out / name)

    if agent.globals_:
        save(fig2_global_search(agent.globals_[0], spec, db=result.trace.db), "fig2_global_search.png")
    save(fig6_snapshots(result), "fig6_snapshots.png")
    save(fig5_trial(result, costmap_state, costmap_spec), "fig5_trial.png")
    for k in range(len(agent.snapshots)):
        save(snapshot_figure(result, k), f"map_{k:02d}.png")
    return written
