"""Figures like the search paper's, drawn from what the search records (the algorithms never plot).

* :func:`fig2_global_search`: the object's colour model, one scan view with its colour peaks circled,
  the back-projection (window means), the peaks projected onto ``M_p``, and the growing beta of one
  peak (the paper's Fig. 2).
* :func:`fig5_trial`: the probability map after the first global search (the trial's log colour scale,
  its colour peaks circled) with the first planned path and its goal, the costmap (when given) with
  the robot's path -- the wheel odometry's, the localized one (``landmarks`` localization) and the
  true one (where the truth is known) --, and the 6D pose drawn on the image of the successful local
  search (the paper's Fig. 5).
* :func:`fig6_snapshots`: the panorama of the first scan and, in a grid, the map after every global scan
  and every failed local search and at the end (:func:`trial_panels`), on one log colour scale
  (:func:`map_norm`), each with the robot, its path, the cells searched and the object (the paper's
  Fig. 6, over the whole trial).
* :func:`draw_pose`: a picture of an estimated pose: the object's box and axes projected on an image.
* :func:`write_figures`: all of them for one trial, plus every map snapshot, as PNG files (``lab search
  --out``).

Each returns a :class:`matplotlib.figure.Figure` (no window is opened; save it with ``savefig``). Maps
are shown the right way up (``P.T`` with ``origin="lower"``, world x to the right, y up).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from lab.geometry import Pose2D, transform_points
from lab.robot import StereoCamera
from lab.search.global_search import GlobalSearchResult
from lab.search.probability_map import detection_likelihood, growing_beta_field
from lab.viz.localization import PATH_STYLES, draw_track

__all__ = [
    "draw_pose",
    "fig2_global_search",
    "fig5_trial",
    "fig6_snapshots",
    "MAX_DECADES",
    "MapPanel",
    "map_norm",
    "panorama",
    "snapshot_figure",
    "trial_panels",
    "write_figures",
]

MAX_DECADES = 8  # the maps' log colour scale spans at most this many decades below the largest cell


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
    # one row: the head's angle at each image's stamp differs from view to view by up to a degree (a late
    # camera's frame is taken back to its exposure along the head's readings, the backlash); rows are
    # tens of degrees apart
    row = [v for v in result.views if abs(v.frame.pan_tilt.tilt - t) < math.radians(5.0)]
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
    _first_map(fig, ax[0, 0], result, P)
    if agent.nav_paths:
        goal, path = agent.nav_paths[0]
        if path is not None and len(path):
            ax[0, 0].plot(path[:, 0], path[:, 1], "-", color="yellow", lw=2, label="planned path")
        ax[0, 0].plot(goal[0], goal[1], "s", mfc="none", mec="red", ms=9, mew=2, label="goal")
        ax[0, 0].legend(loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=3, fontsize=7, frameon=False)
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


def _first_map(fig, a, result, P) -> None:
    """Fig. 5's first panel: ``M_p`` after the first global search on the trial's log colour scale
    (:func:`map_norm` over every snapshot: the prior's level sits mid-scale, the colour peaks' cells
    above it, and the colourbar reads off both), with that scan's colour peaks circled."""
    agent, spec = result.trace.agent, result.trace.spec
    norm = map_norm([s.P for s in agent.snapshots] or [P])
    im = _show_map(a, np.maximum(P, norm.vmin), spec, "M_p after the first global search")
    im.set_norm(norm)
    fig.colorbar(im, ax=a, shrink=0.85, label="P(object in cell), log scale")
    peaks = [p.p_W for p in agent.globals_[0].used_peaks if p.p_W is not None] if agent.globals_ else []
    if peaks:
        xy = np.array(peaks, float)[:, :2]
        a.plot(xy[:, 0], xy[:, 1], "o", mfc="none", mec="orange", ms=11, mew=1.6, label="colour peaks")


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


def _true_xy(result):
    """The true object position (world x, y) of a trial, or None where there is no truth."""
    pose = getattr(result, "true_pose", None)
    if not pose or pose.get("position_m") is None:
        return None
    return pose["position_m"][0], pose["position_m"][1]


def map_norm(maps):
    """One logarithmic colour scale for maps of a probability ``P``, from the smallest cell of any of
    them to the largest (the mass the searches moved spans decades, a linear scale shows only the
    peak). A cell at exactly 0 (none in a Bayes update with ``beta > 0``) is left out of the minimum;
    the scale spans at most :data:`MAX_DECADES` decades."""
    from matplotlib.colors import LogNorm

    vmax = max(float(np.max(m)) for m in maps)
    positive = [float(m[m > 0].min()) for m in maps if np.any(m > 0)]
    vmin = min(positive) if positive else vmax
    vmax = max(vmax, 1e-300)
    vmin = float(np.clip(vmin, vmax * 10.0**-MAX_DECADES, vmax / 1.0001))
    return LogNorm(vmin=vmin, vmax=vmax, clip=True)


@dataclass(frozen=True)
class MapPanel:
    """One map of Fig. 6: ``M_p`` at time ``t`` [s] after ``what``, the robot's ``pose`` then (its own
    estimate), the cell ``cell`` that step searched (None after a global scan), the cells the local
    searches covered before it, and, in the last panel of a found run, the cell it was found at."""

    t: float
    P: np.ndarray = field(repr=False)
    what: str
    cell: tuple[int, int] | None
    pose: Pose2D | None
    searched_before: tuple[tuple[int, int], ...]
    found_cell: tuple[int, int] | None = None
    peaks_xy: np.ndarray | None = field(default=None, repr=False)  # a global scan's used colour peaks [m]


def trial_panels(result) -> list[MapPanel]:
    """The maps of a trial in order: every map snapshot (each global scan and each failed local search
    changed the map), then the end -- where the object was found, or the final map when it differs
    from the last snapshot (a moving object's prediction steps)."""
    agent = result.trace.agent
    locals_ = [(e.t, e.cell) for e in agent.events if e.kind == "local" and e.cell is not None]
    scans = iter(agent.globals_)  # one snapshot per global scan, in order
    panels = []
    for s in agent.snapshots:
        before = tuple(dict.fromkeys(c for t, c in locals_ if t <= s.t + 1e-9 and c != s.cell))
        peaks = None
        if s.cell is None:
            g = next(scans, None)
            used = [] if g is None else [p.p_W[:2] for p in g.used_peaks if p.p_W is not None]
            peaks = np.array(used, float).reshape(-1, 2)
        what = "global scan" if s.cell is None else f"cell {s.cell} searched, not found"
        panels.append(MapPanel(s.t, s.P, what, s.cell, s.pose, before, peaks_xy=peaks))
    # the search that found it: the run's last local search (a side look's too)
    found = next((e for e in reversed(agent.events) if e.kind == "local"), None) if agent.found else None
    P_end = agent.P_final
    changed = P_end is not None and (not panels or not np.array_equal(P_end, panels[-1].P))
    if P_end is not None and (found is not None or changed):
        traj = result.trace.trajectory
        pose = Pose2D(*traj[-1, 1:4]) if len(traj) else None
        before = tuple(dict.fromkeys(c for _, c in locals_ if found is None or c != found.cell))
        what = f"found at cell {found.cell}" if found is not None else "the end: not found"
        t_end = found.t if found is not None else agent.t_end
        panels.append(MapPanel(t_end, P_end, what, None, pose, before, None if found is None else found.cell))
    return panels


def _grid_columns(n: int) -> int:
    """Columns of Fig. 6's grid of ``n`` maps: one row up to 4, then 3 or 4 across (fewest empty slots;
    an empty slot holds the legend)."""
    if n <= 4:
        return max(n, 1)
    return 3 if n % 3 == 0 or n == 5 else 4


def fig6_snapshots(result):
    """The paper's Fig. 6 over the whole trial: the first scan's panorama above ``M_p`` after every
    global scan and every failed local search, and at the end (:func:`trial_panels`), in a grid sized
    to their number.

    All maps share one logarithmic colour scale from the smallest cell of any of them to the largest
    (one colourbar: a brighter panel holds more probability). Each panel marks the robot where it
    stood (its own estimate, with its heading) and its path so far, the cell just searched, the cells
    searched before it, where the object was found and, where the truth is known (the simulator; the
    robot with ``--truth``), the true object; the legend names every mark.
    """
    from matplotlib.figure import Figure

    tr = result.trace
    panels = trial_panels(result)
    n = max(1, len(panels))
    cols = _grid_columns(n)
    rows = -(-n // cols)
    x0, x1, y0, y1 = tr.spec.extent
    panel_w = 2.7  # [in] per column: the map about 2.35 in wide, a 20 cm cell about 6 points across
    panel_h = (panel_w - 0.35) * (y1 - y0) / (x1 - x0) + 0.45  # the map plus its two title lines
    pano = panorama(tr.agent.globals_[0]) if tr.agent.globals_ else None
    pano_h = 0.0 if pano is None else (cols * panel_w - 0.4) * pano.shape[0] / pano.shape[1] + 0.25
    legend_h = 0.0 if rows * cols > n else 0.45
    fig = Figure(figsize=(cols * panel_w + 1.3, pano_h + rows * panel_h + legend_h), layout="constrained")
    heights = ([pano_h] if pano is not None else []) + [panel_h] * rows
    gs = fig.add_gridspec(len(heights), cols, height_ratios=heights)
    if pano is not None:
        top = fig.add_subplot(gs[0, :])
        top.imshow(pano)
        top.set_title("panorama of the first scan (robot's left on the left)", fontsize=9)
        top.axis("off")
    norm = map_norm([p.P for p in panels]) if panels else None
    axes, im = [], None
    first_row = 1 if pano is not None else 0
    for k, panel in enumerate(panels):
        a = fig.add_subplot(gs[first_row + k // cols, k % cols])
        axes.append(a)
        im = _draw_panel(a, panel, result, norm)
        if k % cols:
            a.tick_params(labelleft=False)
            a.set_ylabel("")
        if k < n - cols:
            a.tick_params(labelbottom=False)
            a.set_xlabel("")
    if im is not None:
        fig.colorbar(im, ax=axes, shrink=0.9, label="P(object in cell), log scale")
    handles = _panel_legend(result, panels)
    if rows * cols > n:  # the legend in the first empty slot of the grid
        slot = fig.add_subplot(gs[first_row + rows - 1, n % cols :])
        slot.axis("off")
        slot.legend(handles=handles, loc="center", fontsize=8, frameon=False)
    else:
        fig.legend(handles=handles, loc="outside lower center", ncol=3, fontsize=8, frameon=False)
    return fig


def _draw_panel(a, panel: MapPanel, result, norm):
    """One map of Fig. 6 on the axes ``a`` with its marks (:func:`fig6_snapshots`); returns the image."""
    from matplotlib.patches import Rectangle

    spec, traj = result.trace.spec, result.trace.trajectory
    x0, x1, y0, y1 = spec.extent
    im = a.imshow(
        np.maximum(panel.P.T, norm.vmin), origin="lower", extent=(x0, x1, y0, y1), cmap="viridis", norm=norm
    )
    r = spec.resolution
    for cell in panel.searched_before:
        cx, cy = spec.cell_to_world(*cell)
        a.add_patch(Rectangle((cx - r / 2, cy - r / 2), r, r, fill=False, ec="red", lw=1.2))
    upto = traj[traj[:, 0] <= panel.t + 1e-9] if len(traj) else traj
    if len(upto) > 1:
        a.plot(upto[:, 1], upto[:, 2], "-", color="magenta", lw=0.9)
    if panel.cell is not None:
        a.plot(*spec.cell_to_world(*panel.cell), "x", color="red", ms=10, mew=2.2)
    if panel.peaks_xy is not None and len(panel.peaks_xy):
        a.plot(panel.peaks_xy[:, 0], panel.peaks_xy[:, 1], "o", mfc="none", mec="orange", ms=11, mew=1.6)
    if panel.found_cell is not None:
        a.plot(*spec.cell_to_world(*panel.found_cell), "o", mfc="none", mec="lime", ms=13, mew=2.2)
    if panel.pose is not None:
        p = panel.pose
        a.plot(p.x, p.y, "o", color="white", mec="black", ms=7)
        a.annotate(
            "",
            xy=(p.x + 0.5 * math.cos(p.theta), p.y + 0.5 * math.sin(p.theta)),
            xytext=(p.x, p.y),
            arrowprops={"arrowstyle": "-|>", "color": "white", "lw": 1.4},
        )
    truth = _true_xy(result)
    if truth is not None:
        a.plot(*truth, "*", color="gold", mec="black", ms=13)
    a.set_title(f"t = {panel.t:.0f} s\n{panel.what}", fontsize=9)
    a.set_xlabel("x [m]", fontsize=8)
    a.set_ylabel("y [m]", fontsize=8)
    a.tick_params(labelsize=7)
    return im


def _panel_legend(result, panels) -> list:
    """The legend of Fig. 6: every kind of mark its panels draw."""
    from matplotlib.lines import Line2D

    mark = {"ls": "none"}
    handles = [
        Line2D([], [], marker="o", color="white", mec="black", ms=7, label="robot (arrow: heading)", **mark),
        Line2D([], [], color="magenta", lw=0.9, label="robot's path so far"),
        Line2D([], [], marker="x", color="red", mew=2.2, ms=10, label="cell just searched", **mark),
        Line2D([], [], marker="s", mfc="none", mec="red", ms=8, label="cells searched before", **mark),
    ]
    if any(p.peaks_xy is not None and len(p.peaks_xy) for p in panels):
        handles.append(
            Line2D([], [], marker="o", mfc="none", mec="orange", mew=1.6, ms=11, label="colour peaks", **mark)
        )
    if any(p.found_cell is not None for p in panels):
        handles.append(
            Line2D([], [], marker="o", mfc="none", mec="lime", mew=2.2, ms=11, label="found here", **mark)
        )
    if _true_xy(result) is not None:
        handles.append(
            Line2D([], [], marker="*", color="gold", mec="black", ms=13, label="object (truth)", **mark)
        )
    return handles


def snapshot_figure(result, k: int):
    """One map snapshot (``result.trace.agent.snapshots[k]``) with the trajectory up to its time."""
    agent, spec, traj = result.trace.agent, result.trace.spec, result.trace.trajectory
    s = agent.snapshots[k]
    fig, ax = _figure(1, 1, size=(4.2, 5.0))
    a = ax[0, 0]
    im = _show_map(a, s.P, spec, f"M_p at t = {s.t:.0f} s, after {s.label}")
    im.set_norm(map_norm([snap.P for snap in agent.snapshots]))  # the same scale in every map_NN.png
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
    6D pose on the image), ``fig6_snapshots.png`` (panorama and the map after every global scan and
    failed local search, and at the end), and ``map_NN.png`` for every map snapshot in order (the
    probability map after each global search and each failed local search, with the trajectory so
    far).

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
