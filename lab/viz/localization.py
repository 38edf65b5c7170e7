"""Figures of a localization drive: the true, odometry and localized trajectories, and 3-sigma ellipses;
and :func:`draw_track`, the same three paths of a search trial or an identification episode."""

from __future__ import annotations

import numpy as np

from lab.localization import LandmarkMap

__all__ = ["PATH_STYLES", "draw_track", "drive_figure", "trajectories_axes"]

#: How :func:`draw_track` draws the robot's paths: (colour, line style, width, label).
PATH_STYLES = {
    "truth": ("limegreen", "-", 2.4, "true path"),
    "odometry": ("magenta", "-", 1.3, "odometry"),
    "estimate": ("cyan", "--", 1.3, "localized (landmarks)"),
}


def draw_track(ax, track, end_marks: bool = True) -> list[str]:
    """Draw a run's track (:class:`lab.runs.tracks.RobotTrack`) on ``ax``: the true path where the
    truth is known, the wheel odometry, and the localized estimate when the run localized against
    landmarks (with odometry alone the estimate is the odometry: not drawn twice), each labelled for a
    legend (:data:`PATH_STYLES`; a localized run that saw no landmark says so in its label: its estimate
    is dead reckoning); ``end_marks`` puts a dot where each path ends. Returns the kinds drawn, in order
    (``truth``, ``odometry``, ``estimate``)."""
    paths = []
    if track.truth is not None:
        paths.append(("truth", track.truth))
    paths.append(("odometry", track.odometry))
    if track.localized:
        paths.append(("estimate", track.estimate))
    for kind, xy in paths:
        colour, ls, lw, label = PATH_STYLES[kind]
        if kind == "estimate" and track.landmark_updates == 0:
            label = "localized (no landmark seen)"
        ax.plot(xy[:, 0], xy[:, 1], ls=ls, color=colour, lw=lw, label=label)
    if end_marks and len(track):
        for kind, xy in paths:
            ax.plot(xy[-1, 0], xy[-1, 1], "o", color=PATH_STYLES[kind][0], ms=4)
    return [kind for kind, _ in paths]


def _ellipse(x, Sigma, k: float = 3.0, n: int = 60) -> np.ndarray:
    """Points (n, 2) of the ``k``-sigma ellipse of the position part of ``Sigma`` around ``x``."""
    lam, V = np.linalg.eigh(Sigma[:2, :2])
    a = np.linspace(0, 2 * np.pi, n)
    circle = np.stack([np.cos(a), np.sin(a)])
    return (V @ (k * np.sqrt(np.maximum(lam, 0.0))[:, None] * circle)).T + np.asarray(x)[:2]


def trajectories_axes(ax, odometry_run, localized_run, landmarks: LandmarkMap | None = None) -> None:
    """Draw, on ``ax``, the true path, the odometry of the odometry-only drive and the estimate of the
    localized one (each ``DriveResult``), with the localized drive's 3-sigma ellipses at the corners."""
    for run, col, lab in (
        (odometry_run, "tab:red", "odometry alone"),
        (localized_run, "tab:blue", "localized"),
    ):
        tr = run.trajectory
        ax.plot(
            tr[:, 1],
            tr[:, 2],
            color="0.3",
            lw=1.0,
            ls="--" if run is odometry_run else "-",
            label=f"true ({lab} drive)",
        )
        cols = slice(4, 6) if run is odometry_run else slice(7, 9)
        ax.plot(tr[:, cols][:, 0], tr[:, cols][:, 1], color=col, lw=1.2, label=f"{lab}: estimate")
    for x, Sigma in localized_run.ellipses:
        e = _ellipse(x, Sigma)
        ax.plot(e[:, 0], e[:, 1], color="tab:blue", lw=0.6)
    if landmarks is not None:
        for lm in landmarks:
            ax.plot(*lm.centre_W[:2], "ks", ms=5)
            # the name inside the room, away from the wall the poster hangs on (its face normal)
            n = np.asarray(lm.normal_W, float)
            ax.annotate(
                lm.name,
                lm.centre_W[:2],
                xytext=tuple(6 * n),
                textcoords="offset points",
                fontsize=6,
                ha="left" if n[0] > 0.5 else "right" if n[0] < -0.5 else "center",
                va="bottom" if n[1] > 0.5 else "top" if n[1] < -0.5 else "center",
                annotation_clip=False,
            )
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0)


def drive_figure(odometry_run, localized_run, path, landmarks: LandmarkMap | None = None):
    """Write the trajectories figure (and the NEES of the updates) as a PNG at ``path``."""
    import io

    from matplotlib.figure import Figure  # no pyplot: the caller's backend (a notebook's) is left alone
    from scipy.stats import chi2

    from lab.io import write_bytes_atomic

    fig = Figure(figsize=(13, 5), layout="constrained")
    a, b = fig.subplots(1, 2, width_ratios=(1.5, 1))
    trajectories_axes(a, odometry_run, localized_run, landmarks)
    a.set_title(
        f"seed {localized_run.seed}: final error odometry {odometry_run.odometry_error_m * 100:.1f} cm, "
        f"localized {localized_run.localization_error_m * 100:.1f} cm",
        fontsize=8,
    )
    b.semilogy(localized_run.nees, ".", ms=4)
    for q in (0.025, 0.975):
        b.axhline(chi2.ppf(q, 3), color="0.5", ls=":")
    b.set_xlabel("accepted landmark update")
    b.set_ylabel("NEES")
    b.set_title("NEES with the chi-square(3) 95 % band", fontsize=8)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    write_bytes_atomic(path, buf.getvalue())
    return path
