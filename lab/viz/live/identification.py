"""The live identification view: the paper's Fig. 6 visual interface, redrawn as the agent runs.

Panels: the top-down scene (robot with heading and pan direction, the object estimate with its 2-sigma
ellipse, the ring of candidate poses coloured by information gain, the chosen goal, the path driven so
far); the left camera image with the frame's SIFT features, the most probable model's matches and RANSAC
/ gate inliers, and that model's estimated pose drawn as box edges and axes (projected with the camera's
``K``); the model probabilities against time with the scanning spans shaded and the head/base state.

The panels read only what the agent has (its records, filters and frames), never the simulator's truth.
"""

from __future__ import annotations

import math

import numpy as np

from lab.viz.search import draw_pose

__all__ = ["IdentificationPanels", "ellipse_xy", "identification_inliers"]

#: One colour per model (as in :mod:`lab.viz.identification`).
MODEL_COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown")


def ellipse_xy(centre_xy, cov_xy, n_sigma: float = 2.0, n: int = 40) -> np.ndarray:
    """Points of the ``n_sigma`` ellipse of a 2-D covariance ``cov_xy`` [m^2] around ``centre_xy`` [m]."""
    w, V = np.linalg.eigh(0.5 * (cov_xy + cov_xy.T))
    a = np.linspace(0.0, 2.0 * math.pi, n)
    return (
        V @ (n_sigma * np.sqrt(np.maximum(w, 0.0))[:, None] * np.stack([np.cos(a), np.sin(a)]))
    ).T + centre_xy


def identification_inliers(agent, i: int):
    """Pixel positions of the last frame's features matched to model ``i`` and of the matches its EKF
    update used (RANSAC or gate inliers): ``(uv_matched (m, 2), uv_used (k, 2))`` [px] in the left image.

    Matches again with the agent's own matcher (deterministic) to recover which measured feature each
    candidate row of the update was; empty arrays when the agent keeps no perception of the last frame.
    """
    f = getattr(agent, "last_features", None)
    obs = getattr(agent, "last_observation", None)
    empty = np.zeros((0, 2))
    if f is None or obs is None or len(f) == 0:
        return empty, empty
    corr = agent.matchers[i].match(f)
    upd = obs.updates[i]
    matched = f.uv[np.unique(corr.idx_meas)] if len(corr) else empty
    inl = np.asarray(getattr(upd, "inliers", np.zeros(0, bool)), bool)
    used = f.uv[np.unique(corr.idx_meas[inl])] if len(inl) == len(corr) and inl.any() else empty
    return matched, used


def _scene_limits(points_xy: np.ndarray, q: float = 0.5) -> tuple[tuple[float, float], tuple[float, float]]:
    """Square limits (equal aspect) that hold all ``points_xy`` [m], on a ``q`` [m] lattice: they move
    rarely, each move a full redraw (at least 1.5 m each side of the centre: the robot, the object and
    the ring fit from the start)."""
    lo, hi = points_xy.min(axis=0), points_xy.max(axis=0)
    mid = np.round(0.5 * (lo + hi) / (2 * q)) * (2 * q)
    half = max(1.5, q * math.ceil((0.5 * float(np.max(hi - lo)) + 0.4) / q))
    mid = np.clip(mid, hi - half + 0.2, lo + half - 0.2)  # all inside
    return (mid[0] - half, mid[0] + half), (mid[1] - half, mid[1] + half)


class IdentificationPanels:
    """The panels of a live view of an :class:`~lab.identification.agent.IdentificationAgent`.

    Made by :meth:`lab.viz.live.LiveView.for_identification`; the view calls :meth:`observe` with each
    step's StereoFrame, :meth:`build` once and :meth:`draw` before each picture.
    """

    kind = "identification"
    observer_attribute = "on_step"  # the agent's observer hook

    def __init__(self, agent):
        self.agent = agent
        self.last_frame = None  # the last StereoFrame seen
        self.camera_image: np.ndarray | None = None  # the camera panel's picture, as last drawn (RGB)
        self.a: dict = {}  # the data artists and status labels, by name

    def observe(self, agent, frame) -> None:
        self.last_frame = frame

    def t(self) -> float:
        """Sim time of the picture [s]: the last frame's (else the robot's clock, else 0)."""
        if self.last_frame is not None:
            return float(self.last_frame.t)
        try:
            return float(self.agent.robot.now())
        except Exception:  # noqa: BLE001 - a closed robot
            return 0.0

    # --- the figure, made once ------------------------------------------------------------------
    def build(self, canvas, fig, gs) -> None:
        self.a = {}
        self._build_scene(canvas, fig.add_subplot(gs[:, 0]))
        self._build_camera(canvas, fig.add_subplot(gs[0, 1]))
        self._build_probabilities(canvas, fig.add_subplot(gs[1, 1]))

    def _build_scene(self, canvas, ax) -> None:
        a = self.a
        ax.set_aspect("equal", adjustable="box")
        ax.set_xlabel("x [m] (odometry frame)", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.set_title("scene (top-down)", fontsize=9)
        self.ax_scene = ax
        a["path"] = ax.plot([], [], color="tab:green", lw=1)[0]
        a["ring"] = ax.scatter(np.zeros(0), np.zeros(0), c=np.zeros(0), cmap="viridis", s=40, zorder=3)
        a["blocked"] = ax.scatter(np.zeros(0), np.zeros(0), marker="x", color="grey", s=30, zorder=3)
        self._cross = a["blocked"].get_paths()
        a["goal"] = ax.plot([], [], "*", color="gold", ms=16, mec="k", zorder=4)[0]
        a["goal_line"] = ax.plot([], [], color="gold", lw=1)[0]
        a["obj"] = ax.plot([], [], "s", color="tab:red", ms=8, zorder=4)[0]
        a["ellipse"] = ax.plot([], [], color="tab:red", lw=1)[0]
        a["robot"] = ax.plot([], [], "o", color="tab:green", ms=12, alpha=0.8, zorder=5)[0]
        a["heading"] = ax.plot([], [], color="k", lw=2, zorder=6)[0]
        a["pan"] = ax.plot([], [], color="tab:cyan", lw=1.5, ls="--", zorder=6)[0]
        a["scene_text"] = canvas.label(ax, 0.01, 0.99)

    def _build_camera(self, canvas, cam) -> None:
        a = self.a
        cam.set_axis_off()
        a["cam_title"] = canvas.label(cam, 0.0, 1.0, "above")
        self.ax_cam = cam
        a["img"] = None
        a["feat"] = cam.scatter(np.zeros(0), np.zeros(0), s=4, color="w", alpha=0.6, lw=0)
        a["matched"] = cam.scatter(
            np.zeros(0), np.zeros(0), s=14, facecolors="none", edgecolors="yellow", lw=0.8
        )
        a["used"] = cam.scatter(np.zeros(0), np.zeros(0), s=18, facecolors="none", edgecolors="lime", lw=1.2)

    def _build_probabilities(self, canvas, pr) -> None:
        a = self.a
        names = list(getattr(self.agent, "names", ()))
        pr.set_ylim(-0.02, 1.02)
        pr.set_xlabel("sim time [s]", fontsize=8)
        pr.set_ylabel("P(M_i | D)", fontsize=8)
        pr.tick_params(labelsize=7)
        self.ax_prob = pr
        L = len(names) or 4
        a["lines"] = [
            pr.plot(
                [], [], color=MODEL_COLOURS[i % len(MODEL_COLOURS)], lw=1.4,
                label=names[i] if i < len(names) else f"M{i}",
            )[0]
            for i in range(L)
        ]  # fmt: skip
        # outside the axes, drawn once with the background (the lines never cross it)
        pr.legend(loc="upper left", bbox_to_anchor=(1.005, 1.0), fontsize=7, borderaxespad=0.0)
        pr.set_title("model probabilities (shaded: scanning)", fontsize=8)
        a["prob_title"] = canvas.label(pr, 0.01, 0.99)
        a["bands"] = None
        a["decisions"] = pr.plot([], [], color="c", ls=":", lw=1)[0]

    # --- each picture: one step per panel -------------------------------------------------------
    def draw(self, canvas) -> str:
        """Update every panel from the agent's records; returns the figure's title line."""
        ag = self.agent
        steps, decisions = list(ag.steps), list(ag.decisions)
        self._draw_scene(canvas, steps, decisions)
        self._draw_camera(canvas)
        self._draw_probabilities(canvas, steps, decisions)
        return f"identification, planner {ag.planner.value}   t = {self.t():.1f} s"

    def _draw_scene(self, canvas, steps, decisions) -> None:
        """The top-down scene: robot, head direction, object estimate, candidate ring; limits to fit."""
        x, y, pts = self._draw_robot(steps)
        pts += self._draw_object(steps)
        pts += self._draw_ring(decisions)
        pts.append(np.array([[x, y]]))
        canvas.set_lims(self.ax_scene, *_scene_limits(np.concatenate(pts)))
        rec = steps[-1] if steps else None
        gain_txt = ""
        if decisions:
            g = decisions[-1].gains[decisions[-1].chosen]
            gain_txt = f"\nlast goal gain: {g:.3f} nats" if np.isfinite(g) else "\nlast goal: baseline"
        self.a["scene_text"].set_text(
            f"actions: {len(decisions)}"
            + ("" if rec is None else f"\nhead: {rec.head_mode}, base: {rec.base_mode}")
            + gain_txt
        )

    def _draw_robot(self, steps):
        """The path driven, the robot with its heading and where the head looks; returns the robot's
        position ``x, y`` [m] and the points the scene must show."""
        a, frame = self.a, self.last_frame
        pts = []
        if steps:
            odom = np.array([s.odom for s in steps])
            a["path"].set_data(odom[:, 0], odom[:, 1])
            pts.append(odom[:, :2])
            x, y, th = odom[-1]
        elif frame is not None:
            x, y, th = frame.odom.x, frame.odom.y, frame.odom.theta
        else:
            x = y = th = 0.0
        a["robot"].set_data([x], [y])
        a["heading"].set_data([x, x + 0.3 * math.cos(th)], [y, y + 0.3 * math.sin(th)])
        if frame is not None:  # the camera's optical axis (z of C) in the world: where the head looks
            G_WC = frame.odom.G() @ frame.G_RC
            z = G_WC[:3, 2]
            yaw_c = math.atan2(z[1], z[0])
            a["pan"].set_data([x, x + 0.6 * math.cos(yaw_c)], [y, y + 0.6 * math.sin(yaw_c)])
        return x, y, pts

    def _draw_object(self, steps) -> list:
        """The object estimate and its 2-sigma ellipse; returns the points the scene must show."""
        a = self.a
        centre, cov = self._object_estimate(steps, self.last_frame)
        if centre is None:
            a["obj"].set_data([], [])
            a["ellipse"].set_data([], [])
            return []
        a["obj"].set_data([centre[0]], [centre[1]])
        pts = [centre[None, :2]]
        if cov is not None:
            e = ellipse_xy(centre[:2], cov)
            a["ellipse"].set_data(e[:, 0], e[:, 1])
            pts.append(e)
        return pts

    def _draw_ring(self, decisions) -> list:
        """The last decision's candidate poses coloured by gain, and the chosen goal; returns the points
        the scene must show."""
        a = self.a
        if not decisions:
            return []
        d = decisions[-1]
        cand = np.asarray(d.candidates, float)
        g = np.asarray(d.gains, float)
        ok = np.isfinite(g)
        a["ring"].set_offsets(cand[ok, :2] if ok.any() else np.zeros((0, 2)))
        a["ring"].set_array(g[ok] if ok.any() else np.zeros(0))
        if ok.any():
            a["ring"].set_clim(float(g[ok].min()), float(g[ok].max()) + 1e-12)
        a["blocked"].set_offsets(cand[~ok, :2] if (~ok).any() else np.zeros((0, 2)))
        # a baseline computes no gains: its candidates are plain dots, not "blocked" crosses
        a["blocked"].set_paths(a["ring"].get_paths() if not ok.any() else self._cross)
        gx, gy = cand[d.chosen, :2]
        a["goal"].set_data([gx], [gy])
        c = np.asarray(d.centre_W, float)
        a["goal_line"].set_data([c[0], gx], [c[1], gy])
        return [cand[:, :2]]

    def _draw_camera(self, canvas) -> None:
        """The left image with the features, the most probable model's matches and inliers, its pose."""
        ag, a, frame = self.agent, self.a, self.last_frame
        if frame is None:
            return
        img = frame.left
        i_top = self.top_model()
        if i_top is not None:
            img = self._draw_pose(img, frame, i_top)
        self.camera_image = img
        a["img"] = canvas.image(a["img"], self.ax_cam, img)
        f = getattr(ag, "last_features", None)
        a["feat"].set_offsets(f.uv if f is not None and len(f) else np.zeros((0, 2)))
        if i_top is not None:
            matched, used = identification_inliers(ag, i_top)
        else:
            matched = used = np.zeros((0, 2))
        a["matched"].set_offsets(matched)
        a["used"].set_offsets(used)
        name = ag.names[i_top] if i_top is not None else "none"
        a["cam_title"].set_text(
            f"left camera: {0 if f is None else len(f)} features, {len(matched)} matched to {name}, "
            f"{len(used)} used",
        )

    def _draw_probabilities(self, canvas, steps, decisions) -> None:
        """The model probabilities against time, the scanning spans shaded, the planning instants."""
        ag, a, pr = self.agent, self.a, self.ax_prob
        if steps:
            t = np.array([s.t for s in steps])
            P = np.array([s.posterior for s in steps])
            for i, ln in enumerate(a["lines"]):
                if i < P.shape[1]:
                    ln.set_data(t, P[:, i])
            t0 = float(t[0])
            t1 = t0 + 20.0 * max(1, math.ceil((float(t[-1]) - t0) / 20.0))  # in 20 s steps
            canvas.set_lims(pr, (t0, t1), (-0.02, 1.02))
            if a["bands"] is not None:
                canvas.remove(a["bands"])
            scanning = np.array([s.head_mode == "scanning" for s in steps])
            bands = pr.fill_between(t, 0, 1, where=scanning, step="post", color="gold", alpha=0.25, lw=0)
            a["bands"] = canvas.animate(bands, first=True)
            td = [d.t for d in decisions]
            a["decisions"].set_data(np.repeat(td, 3), np.tile([0.0, 1.0, np.nan], len(td)))
        P_now = np.asarray(ag.P, float)
        state = steps[-1].head_mode if steps else "-"
        ident = getattr(ag, "identified", None)
        best = int(np.argmax(P_now))
        a["prob_title"].set_text(
            f"head {state}; max: {ag.names[best]} {P_now[best]:.2f}"
            + ("" if ident is None else f"   identified: {ag.names[ident]}"),
        )

    # --- what the panels show, from the agent -----------------------------------------------------
    def top_model(self) -> int | None:
        """The most probable model that has a pose estimate (None when no filter has one)."""
        est = self.agent.bank.estimates
        P = np.asarray(self.agent.P, float)
        known = [i for i, e in enumerate(est) if e is not None]
        return max(known, key=lambda i: P[i]) if known else None

    def _object_estimate(self, steps, frame):
        """The probability-weighted object position (world/odometry frame) [m], and the most probable
        model's position covariance rotated into that frame (xy block) [m^2], from the agent's filters."""
        ag = self.agent
        if not steps:
            return None, None
        est_W = steps[-1].estimates_W
        P = np.asarray(steps[-1].posterior, float)
        ok = np.isfinite(est_W[:, 0, 3])
        if not ok.any():
            return None, None
        w = P[ok] / P[ok].sum()
        centre = (w[:, None] * est_W[ok, :3, 3]).sum(axis=0)
        cov = None
        i = self.top_model()
        if i is not None and frame is not None:
            R_WC = (frame.odom.G() @ frame.G_RC)[:3, :3]
            S_C = ag.bank.estimates[i].Sigma[:3, :3]  # the position of O in C [m^2]
            cov = (R_WC @ S_C @ R_WC.T)[:2, :2]
        return centre, cov

    def _draw_pose(self, img: np.ndarray, frame, i: int) -> np.ndarray:
        e = self.agent.bank.estimates[i]
        extent = getattr(self.agent.dbs[i], "extent", None)
        if e is None or extent is None:
            return img
        return draw_pose(img, e.G_CO, extent, frame.camera)
