"""Figures of the identification paper, drawn from a run's arrays (algorithms never plot).

* :func:`fig5`: pose estimates against ground truth, and the model probabilities against time with the
  scanning / tracking bands and the planning instants (the paper's Fig. 5).
* :func:`fig6`: the ring of candidate poses coloured by information gain, the chosen one, the robot and
  the object, and the robot's path -- the wheel odometry's, the localized one and the true one -- (the
  paper's Fig. 6, its visual interface).
* :func:`fig7`: probabilities against time for several runs with different true models (Fig. 7).
"""

from __future__ import annotations

import math

import matplotlib.pyplot as plt
import numpy as np

from lab.viz.localization import draw_track

__all__ = ["fig5", "fig6", "fig7", "plot_probabilities"]

MODEL_COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown")


def _bands(ax, t, modes, colours=None):
    """Shade the time spans of each head mode (scanning yellow, tracking green, as in the paper)."""
    colours = colours or {"scanning": "gold", "tracking": "limegreen"}
    t = np.asarray(t)
    if len(t) < 2:
        return
    start = 0
    for k in range(1, len(t) + 1):
        if k == len(t) or modes[k] != modes[start]:
            c = colours.get(str(modes[start]))
            if c:
                ax.axvspan(t[start], t[min(k, len(t) - 1)], color=c, alpha=0.18, lw=0)
            start = k


def plot_probabilities(ax, t, posteriors, names=None, modes=None, decisions=(), true_model=None):
    """Model probabilities against time, with head-mode bands and dotted lines at planning instants."""
    P = np.asarray(posteriors)
    names = names or [f"M{i}" for i in range(P.shape[1])]
    if modes is not None:
        _bands(ax, t, modes)
    for i in range(P.shape[1]):
        label = names[i] + (" *" if true_model == i else "")
        ax.plot(
            t,
            P[:, i],
            color=MODEL_COLOURS[i % len(MODEL_COLOURS)],
            lw=2 if true_model == i else 1.2,
            label=label,
        )
    for td in decisions:
        ax.axvline(td, color="c", ls=":", lw=1)
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("P(M_i | D)")
    ax.legend(loc="center right", fontsize=8)


def fig5(t, est_xyz_yaw, true_xyz_yaw, posteriors, modes, decisions=(), names=None, true_model=None):
    """The paper's Fig. 5: object position and yaw (world frame) estimated vs true; probabilities.

    Parameters
    ----------
    t : (n,) [s]
    est_xyz_yaw, true_xyz_yaw : (n, 4)
        x, y, z [m] and yaw [rad] of the object in the world frame (NaN where there is no estimate).
    posteriors : (n, L)
    modes : sequence of str (n,)
        Head mode per step ("scanning" / "tracking").
    decisions : sequence of float
        Times at which a planning action was chosen.
    """
    est, true = np.asarray(est_xyz_yaw, float), np.asarray(true_xyz_yaw, float)
    fig, axes = plt.subplots(3, 1, figsize=(9, 8), sharex=True)
    for k, lab in enumerate("xyz"):
        axes[0].plot(t, true[:, k], ls=":", color=MODEL_COLOURS[k], lw=1.5)
        axes[0].plot(t, est[:, k], color=MODEL_COLOURS[k], lw=1.2, label=f"{lab} estimate (dotted: true)")
    axes[0].set_ylabel("position [m]")
    axes[0].legend(fontsize=8, loc="upper right")
    axes[1].plot(t, np.degrees(true[:, 3]), ls=":", color="k")
    axes[1].plot(t, np.degrees(est[:, 3]), color="tab:blue", label="yaw estimate (dotted: true)")
    axes[1].set_ylabel("yaw [deg]")
    axes[1].legend(fontsize=8, loc="upper right")
    plot_probabilities(axes[2], t, posteriors, names, modes, decisions, true_model)
    fig.suptitle("Pose estimates of the true model and model probabilities (identification paper, Fig. 5)")
    fig.tight_layout()
    return fig


def fig6(
    candidates_xy_theta,
    gains,
    chosen,
    robot_xy_theta,
    object_xy,
    path_xy=None,
    object_cov_xy=None,
    ax=None,
    track=None,
):
    """The paper's Fig. 6: the equatorial ring of candidate poses coloured by information gain.

    Parameters
    ----------
    candidates_xy_theta : (K, 3)
        Candidate robot poses (x, y [m], heading [rad]) on the ring.
    gains : (K,)
        Information gain of each candidate (NaN for blocked ones).
    chosen : int
        Index of the chosen candidate (the peak).
    robot_xy_theta : (3,)
    object_xy : (2,)
        The probability-weighted object estimate (the ring's centre).
    path_xy : (m, 2), optional
        The robot's path so far (drawn when there is no ``track``).
    object_cov_xy : (2, 2), optional
        Covariance of the object's position, drawn as a 2-sigma ellipse.
    track : RobotTrack, optional
        The robot's path three ways (:class:`lab.runs.tracks.RobotTrack`): the wheel odometry, the
        localized estimate (with ``landmarks`` localization) and the true path where it is known
        (:func:`lab.viz.localization.draw_track`).
    """
    cand = np.asarray(candidates_xy_theta, float)
    g = np.asarray(gains, float)
    if ax is None:
        fig, ax = plt.subplots(figsize=(6, 6))
    else:
        fig = ax.figure
    ok = np.isfinite(g)
    sc = ax.scatter(cand[ok, 0], cand[ok, 1], c=g[ok], cmap="viridis", s=60, zorder=3)
    ax.scatter(cand[~ok, 0], cand[~ok, 1], marker="x", color="grey", s=40, zorder=3, label="blocked")
    fig.colorbar(sc, ax=ax, label="information gain [nats]", shrink=0.8)
    ax.plot(*cand[chosen, :2], marker="*", color="gold", ms=22, mec="k", zorder=4, label="next-best view")
    ax.plot([object_xy[0], cand[chosen, 0]], [object_xy[1], cand[chosen, 1]], color="gold", lw=1.5)
    ax.plot(*object_xy, "s", color="tab:red", ms=10, label="object estimate")
    if object_cov_xy is not None:
        w, V = np.linalg.eigh(np.asarray(object_cov_xy))
        a = np.linspace(0, 2 * math.pi, 60)
        ell = (V @ (2 * np.sqrt(np.maximum(w, 0))[:, None] * np.stack([np.cos(a), np.sin(a)]))).T + object_xy
        ax.plot(ell[:, 0], ell[:, 1], color="tab:red", lw=1)
    x, y, th = robot_xy_theta
    ax.add_patch(plt.Circle((x, y), 0.2, color="tab:green", alpha=0.7, zorder=2))
    ax.arrow(x, y, 0.3 * math.cos(th), 0.3 * math.sin(th), width=0.02, color="k", zorder=3)
    if track is not None and len(track):
        draw_track(ax, track)
    elif path_xy is not None and len(path_xy):
        p = np.asarray(path_xy)
        ax.plot(p[:, 0], p[:, 1], color="tab:green", lw=1, label="path")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(fontsize=8, loc="upper left")
    ax.set_title("Candidate views coloured by information gain\n(identification paper, Fig. 6)")
    return fig


def fig7(runs, names=None):
    """The paper's Fig. 7: probabilities against time, one panel per run (true model starred).

    ``runs`` is a sequence of dicts with keys ``t``, ``posteriors``, ``modes``, ``decisions``, ``true_model``.
    """
    n = len(runs)
    fig, axes = plt.subplots(n, 1, figsize=(9, 2.6 * n), squeeze=False)
    for ax, r in zip(axes[:, 0], runs, strict=True):
        plot_probabilities(
            ax, r["t"], r["posteriors"], names, r.get("modes"), r.get("decisions", ()), r.get("true_model")
        )
    fig.suptitle("Model probabilities for different true models (identification paper, Fig. 7)")
    fig.tight_layout()
    return fig


def save_episode_figures(out, agent, true_poses, true_model: int, track=None) -> None:
    """Write an identification episode's Figs. 5-7 into ``out`` (``lab identify --out``).

    Parameters
    ----------
    out : Path
    agent : IdentificationAgent
        After its run: its steps and decisions are drawn.
    true_poses : sequence of ndarray, shape (4, 4)
        The box's true pose in W at each step's frame (scoring only).
    true_model : int
    track : RobotTrack, optional
        The robot's path (odometry, estimate, truth) for Fig. 6; without it Fig. 6 draws the frames'
        poses (the pose the agent used).
    """
    from pathlib import Path

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    steps = agent.steps
    t = np.array([s.t for s in steps])
    P = np.array([s.posterior for s in steps])
    modes = [s.head_mode for s in steps]
    est = np.array(
        [
            [
                *s.estimates_W[true_model][:3, 3],
                math.atan2(s.estimates_W[true_model][1, 0], s.estimates_W[true_model][0, 0]),
            ]
            for s in steps
        ]
    )
    true = np.array([[*G[:3, 3], math.atan2(G[1, 0], G[0, 0])] for G in true_poses])
    names = list(agent.names)
    decisions = [d.t for d in agent.decisions]
    fig5(t, est, true, P, modes, decisions, names, true_model).savefig(
        out / "fig5_pose_and_probabilities.png", dpi=90
    )
    if agent.decisions:
        d = agent.decisions[-1]
        odom = np.array([s.odom for s in steps])
        gains = d.gains if np.isfinite(d.gains).any() else np.zeros(len(d.candidates))
        fig6(
            d.candidates, gains, d.chosen, odom[-1], d.centre_W[:2], path_xy=odom[:, :2], track=track
        ).savefig(out / "fig6_information_gain_ring.png", dpi=90)
    fig7(
        [{"t": t, "posteriors": P, "modes": modes, "decisions": decisions, "true_model": true_model}], names
    ).savefig(out / "fig7_probabilities.png", dpi=90)
    plt.close("all")
