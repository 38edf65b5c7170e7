"""The live search view: the probability map, the costmap and the camera, redrawn as the agent runs.

Panels: the probability map ``M_p`` with the trajectory, the colour peaks and the target cell; the
costmap ``M_c`` (free / unknown / obstacle) with the trajectory and the planned path; the camera image of
the last global search with its back-projection peaks circled, or of the last local search with the
found pose drawn.

The panels read only what the agent has (its map, records and frames), never the simulator's truth.
"""

from __future__ import annotations

import numpy as np

from lab.viz.search import draw_pose

__all__ = ["SearchPanels"]


class SearchPanels:
    """The panels of a live view of a :class:`~lab.search.agent.SearchAgent`.

    Made by :meth:`lab.viz.live.LiveView.for_search`; the view calls :meth:`observe` with each
    SearchEvent, :meth:`build` once and :meth:`draw` before each picture.

    Parameters
    ----------
    agent : SearchAgent
    navigator : Navigator, optional
        Whose costmap to draw (without one, the costmap panel shows the trajectory only).
    """

    kind = "search"
    observer_attribute = "observer"  # the agent's observer hook

    def __init__(self, agent, navigator=None):
        self.agent = agent
        self.navigator = navigator
        self.last_event = None  # the last SearchEvent seen
        self._odom: list[tuple[float, float, float]] = []  # the robot's poses at events
        self.camera_image: np.ndarray | None = None  # the camera panel's picture, as last drawn (RGB)
        self.a: dict = {}  # the data artists and status labels, by name

    def observe(self, agent, event) -> None:
        self.last_event = event
        p = agent.robot.odometry()
        self._odom.append((p.x, p.y, p.theta))

    def t(self) -> float:
        """Sim time of the picture [s]: the robot's clock (a closed robot: the last event's, else 0)."""
        try:
            return float(self.agent.robot.now())
        except Exception:  # noqa: BLE001 - a closed robot
            return 0.0 if self.last_event is None else float(self.last_event.t)

    # --- the figure, made once ------------------------------------------------------------------
    def build(self, canvas, fig, gs) -> None:
        self.a = {}
        self._build_map(fig.add_subplot(gs[0, 0]))
        self._build_costmap(fig.add_subplot(gs[1, 0]))
        self._build_camera(canvas, fig.add_subplot(gs[:, 1]))

    def _build_map(self, mp) -> None:
        a, pmap = self.a, self.agent.pmap
        x0, x1, y0, y1 = pmap.spec.extent
        a["map"] = mp.imshow(
            pmap.P.T, origin="lower", extent=(x0, x1, y0, y1), cmap="viridis", interpolation="nearest"
        )
        mp.set_title("probability map M_p", fontsize=9)
        mp.tick_params(labelsize=7)
        a["map_traj"] = mp.plot([], [], color="w", lw=1)[0]
        a["map_robot"] = mp.plot([], [], "o", color="tab:green", mec="w", ms=7)[0]
        a["map_peaks"] = mp.plot([], [], "x", color="tab:red", ms=6)[0]
        a["map_target"] = mp.plot([], [], "s", mfc="none", mec="gold", ms=10, mew=2)[0]
        a["map_plan"] = mp.plot([], [], color="gold", lw=1.2, ls="--")[0]

    def _build_costmap(self, cm) -> None:
        a = self.a
        cm.set_title("costmap M_c (white free, grey unknown, black obstacle)", fontsize=8)
        cm.tick_params(labelsize=7)
        a["cost"] = None
        self.ax_cost = cm
        a["cost_traj"] = cm.plot([], [], color="tab:green", lw=1)[0]
        a["cost_robot"] = cm.plot([], [], "o", color="tab:green", ms=6)[0]
        a["cost_plan"] = cm.plot([], [], color="tab:orange", lw=1.2, ls="--")[0]

    def _build_camera(self, canvas, cam) -> None:
        a = self.a
        cam.set_axis_off()
        self.ax_cam = cam
        a["cam_title"] = canvas.label(cam, 0.0, 1.0, "above")
        a["img"] = None
        a["peaks"] = cam.scatter(np.zeros(0), np.zeros(0), s=160, facecolors="none", edgecolors="red", lw=1.5)

    # --- each picture: one step per panel -------------------------------------------------------
    def draw(self, canvas) -> str:
        """Update every panel from the agent's records; returns the figure's title lines."""
        ag = self.agent
        traj, p = self._trajectory(), ag.robot.odometry()
        globals_ = list(getattr(ag, "_globals", ()))
        plan = self._draw_map(traj, p, globals_)
        self._draw_costmap(canvas, traj, p, plan)
        self._draw_camera(canvas, globals_)
        ev = self.last_event
        what = "" if ev is None else f"{ev.kind}: {ev.detail}"
        return (
            f"search for {ag.db.name}   t = {self.t():.1f} s   global {ag.global_searches}, "
            f"local {ag.local_searches}\n{what[:110]}"
        )

    def _draw_map(self, traj, p, globals_) -> np.ndarray:
        """``M_p`` with the trajectory, the robot, the last scan's used peaks and the target cell;
        returns the planned path drawn (also on the costmap), shape (n, 2) [m]."""
        ag, a = self.agent, self.a
        P = np.asarray(ag.pmap.P, float)
        a["map"].set_data(P.T)
        a["map"].set_clim(float(P.min()), float(P.max()) + 1e-12)
        a["map_traj"].set_data(traj[:, 0], traj[:, 1])
        a["map_robot"].set_data([p.x], [p.y])
        used = [pk for pk in (globals_[-1].peaks if globals_ else ()) if pk.used and pk.p_W is not None]
        a["map_peaks"].set_data([pk.p_W[0] for pk in used], [pk.p_W[1] for pk in used])
        ev = self.last_event
        target = None
        if ev is not None and ev.cell is not None:
            target = ag.pmap.centre(ev.cell)
            a["map_target"].set_data([target[0]], [target[1]])
        plan = self._planned_path(target, p)
        a["map_plan"].set_data(plan[:, 0], plan[:, 1])
        return plan

    def _draw_costmap(self, canvas, traj, p, plan) -> None:
        """The navigator's costmap (when there is one) with the trajectory, the robot and the plan."""
        a, nav = self.a, self.navigator
        if nav is not None:
            state = np.asarray(nav.costmap.state, float)
            shade = np.select([state == 2, state == 1], [0.0, 1.0], 0.6)  # obstacle, free, unknown
            x0, x1, y0, y1 = nav.costmap.spec.extent
            a["cost"] = canvas.image(
                a["cost"],
                self.ax_cost,
                shade.T,
                origin="lower",
                extent=(x0, x1, y0, y1),
                cmap="gray",
                vmin=0,
                vmax=1,
            )
        a["cost_traj"].set_data(traj[:, 0], traj[:, 1])
        a["cost_robot"].set_data([p.x], [p.y])
        a["cost_plan"].set_data(plan[:, 0], plan[:, 1])
        if nav is None:
            x0, x1, y0, y1 = self.agent.pmap.spec.extent
            canvas.set_lims(self.ax_cost, (x0, x1), (y0, y1))

    def _draw_camera(self, canvas, globals_) -> None:
        """The found pose, else the last local search's image, else the last global scan's peaks."""
        a = self.a
        img, uv, title = self._search_picture(globals_)
        if img is not None:
            self.camera_image = img
            a["img"] = canvas.image(a["img"], self.ax_cam, img)
            a["peaks"].set_offsets(uv)
        a["cam_title"].set_text(title)

    # --- what the panels show, from the agent -----------------------------------------------------
    def _trajectory(self) -> np.ndarray:
        """The robot's odometry path (x, y) [m]: the budgeted robot's record when there is one."""
        tr = getattr(self.agent.robot, "trajectory", None)
        if tr:
            return np.asarray(tr, float)[:, 1:3]
        return np.asarray(self._odom, float)[:, :2] if self._odom else np.zeros((0, 2))

    def _planned_path(self, target, p) -> np.ndarray:
        """The path the navigator is driving (its replanned A* waypoints), else the last one the agent
        kept (``nav_paths``), else the straight line to the target."""
        driving = getattr(self.navigator, "planned_path", None)
        if driving is not None and len(driving):
            return np.vstack([[p.x, p.y], np.asarray(driving, float)])
        paths = list(getattr(self.agent, "_nav_paths", ()))
        if paths and paths[-1][1] is not None:
            return np.asarray(paths[-1][1], float)
        if target is None:
            return np.zeros((0, 2))
        return np.array([[p.x, p.y], [target[0], target[1]]])

    def _search_picture(self, globals_):
        """The camera panel's image, the pixels to circle (n, 2) [px] and its title."""
        local = getattr(self.agent, "last_local", None)
        if local is not None and local.found and local.frame is not None and local.estimate is not None:
            img = draw_pose(local.frame.left, local.estimate.G_CO, self.agent.db.extent, local.frame.camera)
            return img, np.zeros((0, 2)), f"local search: found, {local.n_inliers} inliers, pose drawn"
        if local is not None and local.frame is not None:
            return local.frame.left, np.zeros((0, 2)), f"local search: {local.reason}"[:80]
        if globals_:
            g = globals_[-1]
            counts = np.bincount([pk.view for pk in g.peaks], minlength=len(g.views)) if g.peaks else None
            k = int(np.argmax(counts)) if counts is not None and counts.max() > 0 else 0
            view = g.views[k]
            uv = np.array([pk.uv for pk in g.peaks if pk.view == k], float).reshape(-1, 2)
            return view.frame.left, uv, f"global search view {k + 1}/{len(g.views)}: {len(uv)} colour peaks"
        return None, np.zeros((0, 2)), "camera: no view yet"
