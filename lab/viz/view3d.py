"""The recorded 3D view of a run: a scrubbable 3D scene on a timeline, one step per frame or event.

``lab identify --view3d FILE``, ``lab search --view3d FILE`` and ``lab demo --view3d FILE`` write it; in a
notebook, hook a :class:`View3D` onto the agent (``attach=``) and call :meth:`View3D.show` after the run.
The file is one self-contained HTML page (the viewer's JavaScript inlined, no fetch from the web) that
any browser opens offline, on a machine without this package: drag the time slider to scrub.

What a step shows (the run's own records; the truth only where the simulator knows it, for display):

* the world's bodies (boxes, furniture, posters; walls translucent) and the robot, at their true poses;
* the robot's estimated path (green) and true path (black), and the localizer's 3-sigma ellipse;
* the camera frustum of the step's stereo frame(s), from the robot's own estimate of the camera;
* identification: that frame's triangulated features coloured by fate for the most probable model with
  an estimate (green: matched and used by its EKF update, orange: matched but gated out, grey:
  unmatched); each model's pose (its box, wireframe) with the 3-sigma ellipsoid of its position,
  coloured by the model's probability; the ring of candidate views coloured by expected information
  gain (gold: the chosen goal); the model probabilities and the normalised entropy as time series on a
  chart standing behind the scene;
* search (:mod:`lab.viz.view3d_search`): the probability map ``M_p`` as a heat map on the floor (log
  colour scale) and again on the table and shelf tops at their height (:meth:`View3D.set_surfaces`),
  the global scan's views and colour peaks (red), the target cell (gold), the local search's views
  (blue), its last frame and its pose estimate.

The recorder keeps a neutral log while the run goes (:attr:`View3D.steps`: small numpy copies, no
library call); :meth:`View3D.html` turns it into the viewer's scene with `viser <https://viser.studio>`_
(the optional extra ``view3d``: ``pip install 'lab[view3d]'``), which records a scene as timed messages
and writes them with its client inlined. Algorithms never import this module.
"""

from __future__ import annotations

import math
import os
import time
from pathlib import Path

import numpy as np

from lab.errors import ConfigError
from lab.viz.view3d_nodes import (
    N_SIGMA,
    Node,
    Step3D,
    cmap_rgb,
    ellipse_xy,
    ellipsoid_axes,
    ellipsoid_mesh,
    frustum_node,
)
from lab.viz.view3d_page import CHART_LENGTH_M, INSTALL_HINT, iframe, require_viser, show_page, write_page
from lab.viz.view3d_search import SearchScene

__all__ = [
    "INSTALL_HINT",
    "N_SIGMA",
    "Node",
    "Step3D",
    "View3D",
    "ellipse_xy",
    "ellipsoid_axes",
    "ellipsoid_mesh",
    "frustum_node",
    "body_node_name",
    "require_viser",
    "show_page",
]

MODEL_RGB = ((31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189), (140, 86, 75))


def _body_rgb(name: str, rgba) -> tuple[tuple[int, int, int], float]:
    """A body's colour and opacity: its own, or (textured bodies report white) one by its name; walls
    translucent so that the room's inside stays visible."""
    if name.startswith("wall"):
        return (205, 200, 185), 0.15
    if tuple(rgba[:3]) != (1.0, 1.0, 1.0):
        return tuple(int(255 * c) for c in rgba[:3]), 1.0
    for key, rgb in (
        ("floor", (200, 200, 200)),
        ("poster", (120, 170, 230)),
        ("table", (150, 110, 70)),
        ("shelf", (150, 110, 70)),
        ("cabinet", (150, 150, 160)),
    ):
        if key in name:
            return rgb, 1.0
    return (230, 150, 60), 1.0


def body_node_name(body: str) -> str:
    """A world body's node: flat under ``/world`` (a "/" in a viewer's name makes a child node whose
    pose is relative to its parent's, and ``table_a/leg0`` is a body of its own, posed in W)."""
    return "/world/" + body.replace("/", ".")


class View3D:
    """A recorder of a run as a 3D scene on a timeline, hooked onto an agent as its observer.

    Parameters
    ----------
    path : path, optional
        Where :meth:`save` writes the HTML page.
    world : lab.sim.SimWorld, optional
        The simulated world whose bodies to draw (display only; None on the real robot).

    The paths come from the robot's track (:class:`lab.runs.tracks.TrackedRobot`, which the runs wrap
    around the robot they hand the agent): its estimate, and its truth where there is one.
    """

    def __init__(self, path=None, world=None):
        require_viser()  # one clear line before the run starts
        self.path = None if path is None else Path(path)
        if self.path is not None and self.path.suffix.lower() not in (".html", ".htm"):
            raise ConfigError(f"--view3d writes one self-contained HTML page: give a .html path, got {path}")
        self.world = world
        self.steps: list[Step3D] = []
        self.agent = None
        self.kind = None
        self._prev = None
        self._poses: dict[str, np.ndarray] = {}
        self._n_track = 0
        self._last_P = None
        self._n_decisions = 0
        self.search = SearchScene()  # the search's nodes; set_surfaces adds the tables and shelves
        self._chart_origin = None
        self.recording_s = 0.0  # wall time spent recording during the run [s] (benchmarks/bench_view3d.py)
        self.writing_s = 0.0  # wall time spent writing the page [s]
        self.camera = ((-1.0, -7.0, 6.5), (0.0, 0.0, 0.3))  # the page's first view: (position, look at) [m]

    # --- hooking ------------------------------------------------------------------------------------
    @classmethod
    def for_identification(cls, agent, path=None, world=None) -> View3D:
        """Record an :class:`~lab.identification.agent.IdentificationAgent`: one step per stereo frame
        (chained after the agent's observer already there)."""
        v = cls(path, world)
        v._hook(agent, "identification", "on_step")
        return v

    @classmethod
    def for_search(cls, agent, path=None, world=None) -> View3D:
        """Record a :class:`~lab.search.agent.SearchAgent`: one step per search event."""
        v = cls(path, world)
        v._hook(agent, "search", "observer")
        return v

    def attach_search(self, then=None):
        """An ``attach(agent)`` hook for :func:`lab.runs.search.run_search` that makes this recorder
        the search agent's observer, then calls ``then(agent)`` (a notebook's own hook)."""

        def attach(agent) -> None:
            self._hook(agent, "search", "observer")
            if then is not None:
                then(agent)

        return attach

    def add_step(self, t: float, label: str, nodes: dict) -> None:
        """A step of the caller's own on the timeline (a notebook's one update, before and after): the
        ``nodes`` (name -> :class:`Node`, or None to remove one) at time ``t`` [s], with the world's
        bodies that moved since the last step."""
        if self.steps and t < self.steps[-1].t:
            raise ConfigError(f"a step's time must not go back: {t} after {self.steps[-1].t}")
        self.steps.append(Step3D(float(t), str(label), self._bodies() | dict(nodes)))

    def _hook(self, agent, kind: str, attribute: str) -> None:
        self.agent, self.kind = agent, kind
        self._prev = getattr(agent, attribute, None)
        setattr(agent, attribute, self)
        self.steps.append(Step3D(0.0 if not self.steps else self.steps[-1].t, "start", self._bodies()))

    def __call__(self, agent, item) -> None:
        if self._prev is not None:
            self._prev(agent, item)
        t_wall = time.perf_counter()
        try:
            self._record(agent, item)
        finally:
            self.recording_s += time.perf_counter() - t_wall

    def _record(self, agent, item) -> None:
        nodes = self._bodies() | self._robot_nodes(agent)
        if self.kind == "identification":
            nodes |= self._identification_nodes(agent, item)
            label = f"frame {len(self.steps)}"
        else:
            nodes |= self._search_nodes(agent, item)
            label = f"{item.kind}: {item.detail}"[:100]
        t = float(item.t)
        if len(self.steps) == 1 and self.kind == "identification":  # look at the robot and the box
            o = agent.robot.odometry()
            c, s_ = math.cos(o.theta), math.sin(o.theta)
            at = np.array([o.x + 0.8 * c, o.y + 0.8 * s_, 0.3])
            self.camera = (tuple(at + (-1.5 * c + 3.0 * s_, -1.5 * s_ - 3.0 * c, 2.4)), tuple(at))
        if len(self.steps) == 1:  # the start step shows the world as the first frame found it
            self.steps[0] = Step3D(t, self.steps[0].label, self.steps[0].nodes)
        self.steps.append(Step3D(t, label, nodes))

    # --- the world and the robot ----------------------------------------------------------------------
    def _bodies(self) -> dict:
        """The bodies that moved since the last step (all of them at the first)."""
        if self.world is None:
            return {}
        out = {}
        for s in self.world.truth.shapes():
            last = self._poses.get(s.name)
            if last is not None and np.allclose(last, s.G_W, atol=1e-5):
                continue
            self._poses[s.name] = s.G_W.copy()
            rgb, opacity = _body_rgb(s.name, s.rgba)
            props = {"G_W": s.G_W.copy(), "color": rgb, "opacity": opacity}
            node = body_node_name(s.name)
            if s.shape == "box":
                out[node] = Node("box", props | {"size": tuple(s.size)})
            else:
                out[node] = Node("cylinder", props | {"radius": s.size[0], "height": s.size[1]})
        return out

    def _robot_nodes(self, agent) -> dict:
        """The new pieces of the estimated and true paths, the localizer's ellipse, the estimated pose."""
        robot = agent.robot
        out = {}
        track = robot.track() if hasattr(robot, "track") else None
        if track is not None and len(track) > 0:
            k0 = max(self._n_track - 1, 0)
            for name, xyt, rgb in (
                ("estimated", track.estimate, (30, 160, 60)),
                ("true", track.truth, (0, 0, 0)),
            ):
                if xyt is None or len(xyt) - k0 < 2:
                    continue
                p = np.column_stack([xyt[k0:, :2], np.full(len(xyt) - k0, 0.02)])
                out[f"/paths/{name}/{len(self.steps)}"] = Node(
                    "lines", {"segments": np.stack([p[:-1], p[1:]], axis=1), "color": rgb}
                )
            self._n_track = len(track)
        est = robot.pose_estimate() if hasattr(robot, "pose_estimate") else None
        pose = est.pose if est is not None else robot.odometry()
        c, s = math.cos(pose.theta), math.sin(pose.theta)
        out["/robot/estimate"] = Node(
            "lines",
            {
                "segments": np.array(
                    [[[pose.x, pose.y, 0.03], [pose.x + 0.35 * c, pose.y + 0.35 * s, 0.03]]]
                ),
                "color": (30, 160, 60),
            },
        )
        if "robot" not in self._poses:  # no simulated body (a rehearsal, the real robot): the estimate's
            G = np.eye(4)
            G[:3, :3] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
            G[:3, 3] = (pose.x, pose.y, 0.15)
            limits = getattr(robot, "base_limits", None)
            radius = float(getattr(limits, "radius", 0.17))
            out["/robot/body_estimate"] = Node(
                "cylinder",
                {"G_W": G, "radius": radius, "height": 0.3, "color": (30, 160, 60), "wireframe": True},
            )
        if est is not None:
            out["/robot/ellipse"] = Node(
                "lines",
                {"segments": ellipse_xy((pose.x, pose.y), est.Sigma[:2, :2], 0.03), "color": (30, 160, 60)},
            )
        return out

    # --- identification -------------------------------------------------------------------------------
    def _identification_nodes(self, agent, frame) -> dict:
        out = {"/camera/frustum": frustum_node(frame.odom.G() @ frame.G_RC, frame.camera)}
        G_WC = frame.odom.G() @ frame.G_RC
        out["/camera/features"] = self._features(agent, G_WC)
        P = np.asarray(agent.P, float)
        est_W = agent.steps[-1].estimates_W if agent.steps else None
        for i, e in enumerate(agent.bank.estimates):
            name = agent.names[i] if i < len(agent.names) else f"M{i}"
            if e is None or est_W is None or not np.isfinite(est_W[i, 0, 3]):
                out[f"/models/{name}/box"] = out[f"/models/{name}/ellipsoid"] = out[
                    f"/models/{name}/label"
                ] = None
                continue
            rgb = cmap_rgb("plasma", P[i])
            G_WO = est_W[i]
            extent = getattr(agent.dbs[i], "extent", None)
            if extent is not None:
                out[f"/models/{name}/box"] = Node(
                    "box",
                    {
                        "G_W": G_WO.copy(),
                        "size": tuple(float(v) for v in extent),
                        "color": rgb,
                        "opacity": 1.0,
                        "wireframe": True,
                    },
                )
            R_WC = G_WC[:3, :3]
            Sigma_W = R_WC @ e.Sigma[:3, :3] @ R_WC.T  # the position of O: C's covariance turned into W [m^2]
            ell = ellipsoid_mesh(G_WO[:3, 3], Sigma_W)
            out[f"/models/{name}/ellipsoid"] = Node(
                "mesh", ell.props | {"color": rgb, "opacity": 0.45, "Sigma_W": Sigma_W}
            )
            out[f"/models/{name}/label"] = Node(
                "label",
                {"text": f"{name}  P = {P[i]:.2f}", "position": G_WO[:3, 3] + (0, 0, 0.25 + 0.12 * i)},
            )
        out |= self._model_chart(agent, frame.t, P)
        if len(agent.decisions) > self._n_decisions:
            self._n_decisions = len(agent.decisions)
            out |= self._ring(agent.decisions[-1])
        return out

    def _features(self, agent, G_WC) -> Node:
        """The frame's triangulated features in W, coloured by fate for the most probable model that
        has an estimate (the live view's choice): its matcher run again on the frame with the nearest
        neighbours the agent's scorer found for it (the search the step shared, not repeated), as
        :func:`lab.viz.live.identification.identification_inliers` does it."""
        f = getattr(agent, "last_features", None)
        obs = getattr(agent, "last_observation", None)
        if f is None or len(f) == 0:
            return Node(
                "points",
                {
                    "points": np.zeros((0, 3)),
                    "colors": np.zeros((0, 3), np.uint8),
                    "fate": np.zeros(0, np.int8),
                },
            )
        fate = np.zeros(len(f), np.int8)  # 0 unmatched, 1 matched and gated out, 2 matched and used
        known = [i for i, e in enumerate(agent.bank.estimates) if e is not None]
        if known and obs is not None:
            i = max(known, key=lambda k: float(agent.P[k]))
            m, sc = agent.matchers[i], agent.scorers[i]
            # the agent's own search of this frame, kept by its scorer (as the step shares it)
            nb = sc.neighbours(f) if m.db is sc.db and m.k == sc.k_neighbours else None
            corr = m.match(f, nb)
            if len(corr):
                fate[np.unique(corr.idx_meas)] = 1
                inl = np.asarray(getattr(obs.updates[i], "inliers", np.zeros(0, bool)), bool)
                if len(inl) == len(corr) and inl.any():
                    fate[np.unique(corr.idx_meas[inl])] = 2
        colors = np.array([(150, 150, 150), (255, 150, 0), (0, 200, 0)], np.uint8)[fate]
        p_W = f.points_C @ G_WC[:3, :3].T + G_WC[:3, 3]
        return Node("points", {"points": p_W, "colors": colors, "fate": fate})

    def _chart(self, t: float, vals, colors, title: str, origin) -> dict:
        """Time series as new segments on a chart standing at ``origin`` (its foot, the first time
        [m]), values in [0, 1] up to 1 m above it; the page scales the time axis to the run's length."""
        if self._chart_origin is None:
            self._chart_origin = (t, np.asarray(origin, float))
        t0, o = self._chart_origin
        x = t - t0  # [s]: the page scales the time axis to CHART_LENGTH_M once the run's length is known
        vals = np.asarray(vals, float)
        out = {}
        if self._last_P is not None:
            x0, v0 = self._last_P
            seg = np.array(
                [[[x0, o[1], o[2] + a], [x, o[1], o[2] + b]] for a, b in zip(v0, vals, strict=True)], float
            )
            out[f"/chart/series/{len(self.steps)}"] = Node(
                "lines", {"segments": seg, "colors": np.asarray(colors, np.uint8), "chart_x0": o[0]}
            )
        else:
            axes = np.array([[o, o + (0, 0, 1.0)], [o, o + (CHART_LENGTH_M, 0, 0)]])
            out["/chart/axes"] = Node("lines", {"segments": axes, "color": (90, 90, 90)})
            out["/chart/title"] = Node("label", {"text": title, "position": o + (0, 0, 1.15)})
        self._last_P = (x, vals)
        return out

    def _model_chart(self, agent, t: float, P: np.ndarray) -> dict:
        """The model probabilities and the entropy divided by log L (Eq. (5), in [0, 1]) against sim time,
        on a chart standing 2.5 m to the robot's left at the start, 1-2 m above the floor."""
        L = len(P)
        H = float(-np.sum(P * np.log(np.maximum(P, 1e-300)))) / math.log(L) if L > 1 else 0.0
        o = agent.robot.odometry()
        colors = [MODEL_RGB[i % len(MODEL_RGB)] for i in range(L)] + [(0, 0, 0)]
        title = "P(M_i | D) (model colours) and H / log L (black) vs time"
        return self._chart(t, np.append(P, H), colors, title, (o.x, o.y + 2.5, 1.0))

    def _map_chart(self, pmap, t: float) -> dict:
        """The map's entropy divided by log N (black: 1 is uniform) and its peak's share on a log scale
        over 4 decades (red) against sim time, on a chart along the room's north edge, above the walls."""
        P = np.asarray(pmap.P, float)
        H = float(-np.sum(P * np.log(np.maximum(P, 1e-300)))) / math.log(P.size)
        peak = float(np.clip(1.0 + math.log10(max(P.max(), 1e-300)) / 4.0, 0.0, 1.0))
        x0, _, _, y1 = pmap.spec.extent
        title = "map M_p: H / log N (black) and log10 max P / 4 + 1 (red) vs time"
        return self._chart(t, (H, peak), [(0, 0, 0), (220, 30, 30)], title, (x0, y1, 2.7))

    @staticmethod
    def _ring(d) -> dict:
        """The candidate views of a decision coloured by expected information gain, the chosen goal."""
        cand = np.asarray(d.candidates, float)
        g = np.asarray(d.gains, float)
        ok = np.isfinite(g)
        colors = np.full((len(cand), 3), 128, np.uint8)
        if ok.any():
            lo, hi = float(g[ok].min()), float(g[ok].max())
            colors[ok] = [cmap_rgb("viridis", (v - lo) / (hi - lo + 1e-12)) for v in g[ok]]
        pts = np.column_stack([cand[:, :2], np.full(len(cand), 0.05)])
        return {
            "/ring/candidates": Node("points", {"points": pts, "colors": colors, "gains": g, "size": 0.12}),
            "/ring/goal": Node(
                "points",
                {
                    "points": pts[d.chosen : d.chosen + 1] + (0, 0, 0.05),
                    "colors": np.array([[255, 200, 0]], np.uint8),
                    "size": 0.2,
                },
            ),
        }

    # --- search -----------------------------------------------------------------------------------------
    def set_surfaces(self, surfaces) -> None:
        """The tops an object may stand on besides the floor, as (name, z [m], footprint (k, 2) [m]):
        the search's heat map is drawn on them too, at their height (:mod:`lab.viz.view3d_search`)."""
        self.search = SearchScene(surfaces)

    def _search_nodes(self, agent, event) -> dict:
        return self.search.nodes(agent, event) | self._map_chart(agent.pmap, float(event.t))

    # --- the viewer --------------------------------------------------------------------------------------
    def html(self) -> str:
        """The recording as one self-contained HTML page (viser's client inlined)."""
        t_wall = time.perf_counter()
        try:
            return write_page(self.steps, self.camera)
        finally:
            self.writing_s += time.perf_counter() - t_wall

    def save(self, path=None) -> Path:
        """Write :meth:`html` to ``path`` (default: the recorder's) atomically; returns the path."""
        path = Path(path) if path is not None else self.path
        if path is None:
            raise ConfigError("View3D.save needs a path (.html)")
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(path.name + ".part")
        tmp.write_text(self.html(), encoding="utf-8")
        os.replace(tmp, path)
        return path

    def show(self, height: int = 520):
        """The recording inline in a notebook (:func:`show_page`)."""
        return iframe(self.html(), height)
