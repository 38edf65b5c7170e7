"""Live views of a run: watch the robot think, in JupyterLab, in a window, or in a recording.

One drawing code path (:meth:`LiveView.render`, a matplotlib figure drawn by Agg into an RGB array)
feeds three sinks: an ``ipywidgets.Image`` (PNG bytes) for a notebook, a :class:`~lab.viz.recorder.Recorder`
for ``--record``, and a matplotlib window when a display exists. The view is an *observer*: the agents
call it once per step (identification) or per event (search) and it draws at most ``rate_hz`` times per
second of **sim time**, so a run is never blocked on it; a run with no view asked for draws nothing
(the agents' observer is ``None``; this module is not even imported).

Identification (the paper's Fig. 6 visual interface, live)::

    from lab.viz.live import LiveView
    agent = IdentificationAgent(robot, planner="lut")
    view = LiveView.for_identification(agent)   # hooks itself in as the agent's observer
    display(view.widget)                        # an ipywidgets.Image, refreshed at 2 Hz of sim time
    agent.run()

Panels: the top-down scene (robot with heading and pan direction, the object estimate with its 2-sigma
ellipse, the ring of candidate poses coloured by information gain, the chosen goal, the path driven so
far); the left camera image with the frame's SIFT features, the most probable model's matches and RANSAC
/ gate inliers, and that model's estimated pose drawn as box edges and axes (projected with the camera's
``K``); the model probabilities against time with the scanning spans shaded and the head/base state.

The whole episode of ``lab identify`` with the box driven by hand (``attach`` is called once the agent
and the carrier exist, before the run)::

    from lab.identification.run import run_identify
    from lab.viz.live import LiveView, TeleopPanel

    def attach(agent, carrier):
        display(LiveView.for_identification(agent).widget, TeleopPanel(carrier.mover).widget)

    run = in_background(run_identify, 1, mover="teleop", attach=attach)   # returns at once
    ...                                  # press the buttons while it runs
    result = run.result()                # waits for the end of the episode

A notebook handles a widget's clicks only while no cell is running: :func:`in_background` runs the
episode in a worker thread so the teleoperation buttons work during the run (the view's picture is
updated from the worker; a plain ``run_identify(...)`` in a cell shows the view but queues the clicks).

Search::

    view = LiveView.for_search(agent)           # agent: a SearchAgent; its navigate may carry .navigator
    display(view.widget)
    agent.run()
    # or the whole trial: run_search(..., attach=lambda agent: display(LiveView.for_search(agent).widget))

Panels: the probability map ``M_p`` with the trajectory, the colour peaks and the target cell; the
costmap ``M_c`` (free / unknown / obstacle) with the trajectory and the planned path; the camera image of
the last global search with its back-projection peaks circled, or of the last local search with the
found pose drawn.

Recording: ``LiveView.for_identification(agent, rate_hz=None, recorder=Recorder("run.gif"),
widget=False)`` draws every step into the recorder (one frame per step, sim time stamped); close the
recorder after the run to write the file. A second view (a notebook's) chains after it.

Cost: the axes are drawn once and the data blitted over them (a full redraw only when a limit moves, in
coarse steps), and the status lines are drawn with OpenCV: about 20-25 ms of CPU per picture at
960 x 540 px, plus ~5 ms for the widget's PNG; ``benchmarks/bench_live.py`` measures the share of a
run's wall time at the default 2 Hz.

Teleoperation of the moving box is :class:`TeleopPanel` (``TeleopPanel(mover).widget``): buttons that
drive the :class:`~lab.sim.movers.TeleopMover`'s carrier robot and turn the box on it.

The view reads only what the agent has (its records, filters and frames), never the simulator's truth.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import cv2
import numpy as np

from lab.errors import ConfigError

__all__ = ["LiveView", "TeleopPanel", "identification_inliers", "in_background"]

MODEL_COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown")


def in_background(fn, *args, **kwargs):
    """Run ``fn(*args, **kwargs)`` in a worker thread; returns a :class:`concurrent.futures.Future`
    (``.done()``, ``.result()``, which re-raises the run's error). For notebooks: the cell returns at once
    and the kernel keeps handling the widgets' clicks (a teleoperation panel) while the run goes on.
    Start one simulated run at a time (each builds its own world in that thread)."""
    from concurrent.futures import ThreadPoolExecutor

    pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="lab-run")
    future = pool.submit(fn, *args, **kwargs)
    pool.shutdown(wait=False)  # the worker finishes the run, then the thread ends
    return future


def _png(rgb: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".png", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    if not ok:  # pragma: no cover - OpenCV always encodes a uint8 image
        raise RuntimeError("PNG encoding failed")
    return buf.tobytes()


def _ellipse_xy(centre_xy, cov_xy, n_sigma: float = 2.0, n: int = 40) -> np.ndarray:
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


class _Label:
    """A status text that changes at every picture, drawn with OpenCV over the rendered figure (Agg text
    layout costs ~5 ms a string; this ~0.1 ms). Placed at the fraction ``(fx, fy)`` of its axes (or of
    the figure when ``ax`` is None): its top-left corner there, or its top-centre (``center``), or
    its bottom-left (``above``: just above that point)."""

    FONT = cv2.FONT_HERSHEY_SIMPLEX
    SCALE = 0.38
    LINE_PX = 13

    def __init__(self, ax, fx: float, fy: float, how: str = "left"):
        self.ax, self.fx, self.fy, self.how = ax, fx, fy, how
        self.text = ""
        self.xy = (0, 0)

    def set_text(self, text: str) -> None:
        self.text = text

    def place(self, fig) -> None:
        """Pixel anchor from the axes' position (after a full draw)."""
        W, H = fig.canvas.get_width_height()
        if self.ax is None:
            x, y = self.fx * W, self.fy * H
        else:
            bb = self.ax.get_window_extent()
            x, y = bb.x0 + self.fx * bb.width, bb.y0 + self.fy * bb.height
        self.xy = (int(round(x)), int(round(H - y)))

    def draw(self, rgb: np.ndarray) -> None:
        lines = [ln for ln in self.text.split("\n") if ln]
        if not lines:
            return
        w = max(cv2.getTextSize(ln, self.FONT, self.SCALE, 1)[0][0] for ln in lines)
        h = self.LINE_PX * len(lines)
        x, y = self.xy
        if self.how == "center":
            x -= w // 2
        elif self.how == "above":
            y -= h + 3
        cv2.rectangle(rgb, (x - 2, y), (x + w + 2, y + h + 2), (255, 255, 255), -1)
        for k, ln in enumerate(lines):
            cv2.putText(rgb, ln, (x, y + self.LINE_PX * (k + 1) - 2), self.FONT, self.SCALE, (0, 0, 0), 1,
                        cv2.LINE_AA)  # fmt: skip


class LiveView:
    """A live picture of a run, redrawn at most ``rate_hz`` times per second of sim time.

    Build it with :meth:`for_identification` or :meth:`for_search`; it installs itself as the agent's
    observer. Calling the view (``view(agent, frame_or_event)``) is the observer protocol.

    Parameters
    ----------
    kind : {"identification", "search"}
    agent : IdentificationAgent or SearchAgent
    rate_hz : float or None
        Redraws per second of sim time (default 2). ``None`` redraws at every call (every step of an
        identification run, every event of a search): what a recording whose frames match the run's
        steps needs.
    recorder : Recorder, optional
        Every drawn picture is also added to it, stamped with the sim time.
    widget : bool
        Keep an ``ipywidgets.Image`` up to date (created on first use of :attr:`widget`; ipywidgets is
        imported only then).
    window : bool
        Also show the pictures in a matplotlib window (needs a display and an interactive backend).
    size_px : (width, height)
        Size of the picture [px].
    navigator : Navigator, optional
        Search only: whose costmap to draw (default: ``agent.navigate.navigator`` when present).
    """

    def __init__(
        self,
        kind: str,
        agent,
        rate_hz: float | None = 2.0,
        recorder=None,
        widget: bool = True,
        window: bool = False,
        size_px: tuple[int, int] = (960, 540),
        navigator=None,
    ):
        if kind not in ("identification", "search"):
            raise ConfigError(f"unknown live view {kind!r}; views: identification, search")
        if rate_hz is not None and not (math.isfinite(rate_hz) and 0.05 <= rate_hz <= 50):
            raise ConfigError(f"rate_hz must be within [0.05, 50] Hz of sim time (or None), got {rate_hz!r}")
        w, h = size_px
        if not (200 <= w <= 4000 and 150 <= h <= 4000):
            raise ConfigError(f"size_px must be within (200..4000, 150..4000) px, got {size_px!r}")
        self.kind = kind
        self.agent = agent
        self.rate_hz = rate_hz
        self.recorder = recorder
        self._want_widget = widget
        self._widget = None
        self._window = window and bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
        self._win = None
        self.navigator = navigator
        self.n_calls = 0
        self.n_draws = 0
        self.t_last: float | None = None
        self._next_t: float | None = None
        self._last_frame = None  # identification: the last StereoFrame seen
        self._last_event = None  # search: the last SearchEvent seen
        self._odom: list[tuple[float, float, float]] = []  # search: the robot's poses at events
        self.camera_image: np.ndarray | None = None  # the camera panel's picture, as last drawn (RGB)
        self._prev = None  # the observer this view was chained after
        self._dpi = 80
        self._fig = None
        self.n_full_draws = 0  # renders that redrew the axes (the others blit the data only)
        self._size = (w / self._dpi, h / self._dpi)

    # --- construction ---------------------------------------------------------------------------
    @classmethod
    def for_identification(cls, agent, **kw) -> LiveView:
        """A view of an :class:`~lab.identification.agent.IdentificationAgent`, hooked in as its observer
        (an observer already there, e.g. a recording's view, is called first: they chain)."""
        view = cls("identification", agent, **kw)
        view._prev = agent.on_step
        agent.on_step = view
        return view

    @classmethod
    def for_search(cls, agent, follow_robot: bool = True, **kw) -> LiveView:
        """A view of a :class:`~lab.search.agent.SearchAgent`, hooked in as its observer.

        The agent reports events (a global search, an arrival, a local search), which are seconds to
        minutes apart; with ``follow_robot`` and a ``rate_hz``, the view also redraws at that rate while
        the robot drives or scans, from the robot's steps (its ``step`` is wrapped on this instance;
        :meth:`close` unwraps it). A recording (``rate_hz=None``) draws one frame per event only.
        """
        kw.setdefault("navigator", getattr(agent.navigate, "navigator", None))
        view = cls("search", agent, **kw)
        view._prev = agent.observer
        agent.observer = view
        if follow_robot and view.rate_hz is not None:
            robot = agent.robot
            base_step = robot.step

            def step(dt: float) -> None:
                base_step(dt)
                if view._due(robot.now()):
                    view.update()

            robot.step = step
            view._robot_wrapped = robot
        return view

    # --- the observer protocol ------------------------------------------------------------------
    def __call__(self, agent, item) -> None:
        """Called by the agent: ``item`` is the step's StereoFrame (identification) or a SearchEvent."""
        if self._prev is not None:
            self._prev(agent, item)
        self.n_calls += 1
        t = float(item.t)
        if self.kind == "identification":
            self._last_frame = item
        else:
            self._last_event = item
            p = agent.robot.odometry()
            self._odom.append((p.x, p.y, p.theta))
        if self._due(t):
            self.update()

    def _due(self, t: float) -> bool:
        """Is a redraw due at sim time ``t`` [s]? (Advances the schedule of redraws when it is.)"""
        if self.rate_hz is None:
            return True
        if self._next_t is not None and t < self._next_t - 1e-9:
            return False
        period = 1.0 / self.rate_hz
        self._next_t = t + period if self._next_t is None else self._next_t + period
        while self._next_t <= t + 1e-9:
            self._next_t += period
        return True

    def update(self) -> np.ndarray:
        """Draw now and push the picture to the widget, the recorder and the window; returns it (RGB)."""
        rgb = self.render()
        self.n_draws += 1
        t = self._t()
        self.t_last = t
        if self._want_widget and self._widget is not None:
            self._widget.value = _png(rgb)
        if self.recorder is not None:
            self.recorder.add(rgb, t)
        if self._window:
            self._show_window(rgb)
        return rgb

    @property
    def widget(self):
        """An ``ipywidgets.Image`` showing the latest picture (display it in a notebook)."""
        if self._widget is None:
            try:
                import ipywidgets
            except ImportError:
                raise ConfigError(
                    "the live view's widget needs ipywidgets (pip install ipywidgets); "
                    "without it, use render() or a Recorder"
                ) from None
            w, h = (int(s * self._dpi) for s in self._size)
            self._widget = ipywidgets.Image(format="png", width=w, height=h)
            self._want_widget = True
            if self.n_draws:
                self._widget.value = _png(self.render())
        return self._widget

    def _t(self) -> float:
        """Sim time of the picture [s]: the frame's (identification), the robot's clock (search)."""
        if self.kind == "identification" and self._last_frame is not None:
            return float(self._last_frame.t)
        try:
            return float(self.agent.robot.now())
        except Exception:  # noqa: BLE001 - a closed robot: the last event's time, or 0
            return 0.0 if self._last_event is None else float(self._last_event.t)

    def _show_window(self, rgb: np.ndarray) -> None:  # pragma: no cover - needs a display
        import matplotlib.pyplot as plt

        if self._win is None:
            fig = plt.figure(f"lab live view ({self.kind})", figsize=self._size, dpi=self._dpi)
            ax = fig.add_axes((0, 0, 1, 1))
            ax.set_axis_off()
            self._win = ax.imshow(rgb)
            plt.show(block=False)
        else:
            self._win.set_data(rgb)
        self._win.figure.canvas.draw_idle()
        self._win.figure.canvas.flush_events()

    def close(self) -> None:
        """Detach from the agent (its observer back to the one before) and free the figure."""
        if self.kind == "identification" and getattr(self.agent, "on_step", None) is self:
            self.agent.on_step = self._prev
        if self.kind == "search" and getattr(self.agent, "observer", None) is self:
            self.agent.observer = self._prev
        robot = self.__dict__.pop("_robot_wrapped", None)
        if robot is not None and "step" in vars(robot):
            del robot.step  # the class's step again
        self._fig = None

    # --- drawing --------------------------------------------------------------------------------
    def render(self) -> np.ndarray:
        """The current picture as an RGB ``uint8`` array, shape (H, W, 3) (no widget, no recorder)."""
        if self._fig is None:
            self._build()
        if self.kind == "identification":
            self._draw_identification()
        else:
            self._draw_search()
        # Blitting: the axes, ticks and labels change only when a limit does (rarely: the limits move
        # in coarse steps); the data artists are "animated" and drawn over a saved background.
        fig, canvas = self._fig, self._fig.canvas
        if self._dirty or self._bg is None:
            canvas.draw()  # everything but the animated artists
            self._bg = canvas.copy_from_bbox(fig.bbox)
            self._dirty = False
            self.n_full_draws += 1
            for lab in self._labels:
                lab.place(fig)
        else:
            canvas.restore_region(self._bg)
        for art in self._dyn:
            fig.draw_artist(art)
        rgb = np.ascontiguousarray(np.asarray(canvas.buffer_rgba())[..., :3])
        for lab in self._labels:
            lab.draw(rgb)
        return rgb

    def _label(self, ax, fx: float, fy: float, how: str = "left") -> _Label:
        lab = _Label(ax, fx, fy, how)
        self._labels.append(lab)
        return lab

    def _animate(self, art, first: bool = False):
        """Mark an artist as redrawn at every render (drawn first, under the others, when ``first``)."""
        art.set_animated(True)
        if first:
            self._dyn.insert(0, art)
        else:
            self._dyn.append(art)
        return art

    def _set_lims(self, ax, xlim, ylim) -> None:
        """Set the axes' limits; a change makes the next render a full one (new ticks)."""
        if not (np.allclose(ax.get_xlim(), xlim) and np.allclose(ax.get_ylim(), ylim)):
            ax.set_xlim(*xlim)
            ax.set_ylim(*ylim)
            self._dirty = True

    def _image(self, key: str, ax, img: np.ndarray, **kw):
        """Show ``img`` in ``ax`` (an animated image made on first use; a new size re-makes it)."""
        a = self._a
        im = a.get(key)
        if im is not None and im.get_array().shape[:2] != img.shape[:2]:
            self._dyn.remove(im)
            im.remove()
            im = None
        if im is None:
            im = a[key] = self._animate(ax.imshow(img, interpolation="nearest", **kw), first=True)
            self._dirty = True  # imshow sets the axes' limits
        else:
            im.set_data(img)
        return im

    def _build(self) -> None:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        fig = Figure(figsize=self._size, dpi=self._dpi)
        FigureCanvasAgg(fig)
        gs = fig.add_gridspec(
            2,
            2,
            width_ratios=(1.0, 1.15),
            left=0.06,
            right=0.93,
            bottom=0.08,
            top=0.93,
            wspace=0.18,
            hspace=0.32,
        )
        self._fig = fig
        self._a = {}
        self._dyn = []
        self._labels: list[_Label] = []
        self._bg = None
        self._dirty = True
        if self.kind == "identification":
            self._build_identification(fig, gs)
        else:
            self._build_search(fig, gs)
        a = self._a
        a["suptitle"] = self._label(None, 0.5, 0.995, "center")
        # every data artist made in _build_*: animated
        for k, v in list(a.items()):
            if k in ("scene", "cam", "prob", "costax", "cross") or v is None or isinstance(v, _Label):
                continue
            for art in v if isinstance(v, list) else [v]:
                self._animate(art)

    # identification -------------------------------------------------------------------------------
    def _build_identification(self, fig, gs) -> None:
        a = self._a
        names = list(getattr(self.agent, "names", ()))
        ax = fig.add_subplot(gs[:, 0])
        ax.set_aspect("equal", adjustable="box")
        ax.set_xlabel("x [m] (odometry frame)", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.set_title("scene (top-down)", fontsize=9)
        a["scene"] = ax
        a["path"] = ax.plot([], [], color="tab:green", lw=1)[0]
        a["ring"] = ax.scatter(np.zeros(0), np.zeros(0), c=np.zeros(0), cmap="viridis", s=40, zorder=3)
        a["blocked"] = ax.scatter(np.zeros(0), np.zeros(0), marker="x", color="grey", s=30, zorder=3)
        a["cross"] = a["blocked"].get_paths()
        a["goal"] = ax.plot([], [], "*", color="gold", ms=16, mec="k", zorder=4)[0]
        a["goal_line"] = ax.plot([], [], color="gold", lw=1)[0]
        a["obj"] = ax.plot([], [], "s", color="tab:red", ms=8, zorder=4)[0]
        a["ellipse"] = ax.plot([], [], color="tab:red", lw=1)[0]
        a["robot"] = ax.plot([], [], "o", color="tab:green", ms=12, alpha=0.8, zorder=5)[0]
        a["heading"] = ax.plot([], [], color="k", lw=2, zorder=6)[0]
        a["pan"] = ax.plot([], [], color="tab:cyan", lw=1.5, ls="--", zorder=6)[0]
        a["scene_text"] = self._label(ax, 0.01, 0.99)
        cam = fig.add_subplot(gs[0, 1])
        cam.set_axis_off()
        a["cam_title"] = self._label(cam, 0.0, 1.0, "above")
        a["cam"] = cam
        a["img"] = None
        a["feat"] = cam.scatter(np.zeros(0), np.zeros(0), s=4, color="w", alpha=0.6, lw=0)
        a["matched"] = cam.scatter(
            np.zeros(0), np.zeros(0), s=14, facecolors="none", edgecolors="yellow", lw=0.8
        )
        a["used"] = cam.scatter(np.zeros(0), np.zeros(0), s=18, facecolors="none", edgecolors="lime", lw=1.2)
        pr = fig.add_subplot(gs[1, 1])
        pr.set_ylim(-0.02, 1.02)
        pr.set_xlabel("sim time [s]", fontsize=8)
        pr.set_ylabel("P(M_i | D)", fontsize=8)
        pr.tick_params(labelsize=7)
        a["prob"] = pr
        L = len(names) or 4
        a["lines"] = [
            pr.plot(
                [],
                [],
                color=MODEL_COLOURS[i % len(MODEL_COLOURS)],
                lw=1.4,
                label=names[i] if i < len(names) else f"M{i}",
            )[0]
            for i in range(L)
        ]
        # outside the axes, drawn once with the background (the lines never cross it)
        pr.legend(loc="upper left", bbox_to_anchor=(1.005, 1.0), fontsize=7, borderaxespad=0.0)
        pr.set_title("model probabilities (shaded: scanning)", fontsize=8)
        a["prob_title"] = self._label(pr, 0.01, 0.99)
        a["bands"] = None
        a["decisions"] = pr.plot([], [], color="c", ls=":", lw=1)[0]

    def _draw_identification(self) -> None:
        ag, a = self.agent, self._a
        frame = self._last_frame
        steps = list(ag.steps)
        P_now = np.asarray(ag.P, float)
        # --- top-down scene
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
        centre, cov = self._object_estimate(steps, frame)
        if centre is not None:
            a["obj"].set_data([centre[0]], [centre[1]])
            pts.append(centre[None, :2])
            if cov is not None:
                e = _ellipse_xy(centre[:2], cov)
                a["ellipse"].set_data(e[:, 0], e[:, 1])
                pts.append(e)
        else:
            a["obj"].set_data([], [])
            a["ellipse"].set_data([], [])
        decisions = list(ag.decisions)
        if decisions:
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
            a["blocked"].set_paths(a["ring"].get_paths() if not ok.any() else a["cross"])
            gx, gy = cand[d.chosen, :2]
            a["goal"].set_data([gx], [gy])
            c = np.asarray(d.centre_W, float)
            a["goal_line"].set_data([c[0], gx], [c[1], gy])
            pts.append(cand[:, :2])
        pts.append(np.array([[x, y]]))
        allp = np.concatenate(pts)
        # square limits (equal aspect) on a 0.5 m lattice: they move rarely, each move a full redraw
        # (at least 1.5 m each side of the centre: the robot, the object and the ring fit from the start)
        q = 0.5
        mid = np.round(0.5 * (allp.min(axis=0) + allp.max(axis=0)) / (2 * q)) * (2 * q)
        half = max(1.5, q * math.ceil((0.5 * float(np.max(allp.max(axis=0) - allp.min(axis=0))) + 0.4) / q))
        mid = np.clip(mid, allp.max(axis=0) - half + 0.2, allp.min(axis=0) + half - 0.2)  # all inside
        self._set_lims(a["scene"], (mid[0] - half, mid[0] + half), (mid[1] - half, mid[1] + half))
        rec = steps[-1] if steps else None
        gain_txt = ""
        if decisions:
            g = decisions[-1].gains[decisions[-1].chosen]
            gain_txt = f"\nlast goal gain: {g:.3f} nats" if np.isfinite(g) else "\nlast goal: baseline"
        a["scene_text"].set_text(
            f"actions: {len(decisions)}"
            + ("" if rec is None else f"\nhead: {rec.head_mode}, base: {rec.base_mode}")
            + gain_txt
        )
        # --- camera image, features, matches, the most probable model's pose
        if frame is not None:
            img = frame.left
            i_top = self._top_model()
            if i_top is not None:
                img = self._draw_pose(img, frame, i_top)
            self.camera_image = img
            self._image("img", a["cam"], img)
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
        # --- probabilities against time, with the scanning spans
        pr = a["prob"]
        if steps:
            t = np.array([s.t for s in steps])
            P = np.array([s.posterior for s in steps])
            for i, ln in enumerate(a["lines"]):
                if i < P.shape[1]:
                    ln.set_data(t, P[:, i])
            t0 = float(t[0])
            t1 = t0 + 20.0 * max(1, math.ceil((float(t[-1]) - t0) / 20.0))  # in 20 s steps
            self._set_lims(pr, (t0, t1), (-0.02, 1.02))
            if a["bands"] is not None:
                self._dyn.remove(a["bands"])
                a["bands"].remove()
            scanning = np.array([s.head_mode == "scanning" for s in steps])
            bands = pr.fill_between(t, 0, 1, where=scanning, step="post", color="gold", alpha=0.25, lw=0)
            a["bands"] = self._animate(bands, first=True)
            td = [d.t for d in decisions]
            a["decisions"].set_data(np.repeat(td, 3), np.tile([0.0, 1.0, np.nan], len(td)))
        state = steps[-1].head_mode if steps else "-"
        ident = getattr(ag, "identified", None)
        best = int(np.argmax(P_now))
        a["prob_title"].set_text(
            f"head {state}; max: {ag.names[best]} {P_now[best]:.2f}"
            + ("" if ident is None else f"   identified: {ag.names[ident]}"),
        )
        a["suptitle"].set_text(f"identification, planner {ag.planner.value}   t = {self._t():.1f} s")

    def _top_model(self) -> int | None:
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
        i = self._top_model()
        if i is not None and frame is not None:
            R_WC = (frame.odom.G() @ frame.G_RC)[:3, :3]
            S_C = ag.bank.estimates[i].Sigma[:3, :3]  # the position of O in C [m^2]
            cov = (R_WC @ S_C @ R_WC.T)[:2, :2]
        return centre, cov

    def _draw_pose(self, img: np.ndarray, frame, i: int) -> np.ndarray:
        from lab.viz.search import draw_pose

        e = self.agent.bank.estimates[i]
        extent = getattr(self.agent.dbs[i], "extent", None)
        if e is None or extent is None:
            return img
        return draw_pose(img, e.G_CO, extent, frame.camera)

    # search ---------------------------------------------------------------------------------------
    def _build_search(self, fig, gs) -> None:
        a = self._a
        ag = self.agent
        spec = ag.pmap.spec
        x0, x1, y0, y1 = spec.extent
        mp = fig.add_subplot(gs[0, 0])
        a["map"] = mp.imshow(
            ag.pmap.P.T, origin="lower", extent=(x0, x1, y0, y1), cmap="viridis", interpolation="nearest"
        )
        mp.set_title("probability map M_p", fontsize=9)
        mp.tick_params(labelsize=7)
        a["map_traj"] = mp.plot([], [], color="w", lw=1)[0]
        a["map_robot"] = mp.plot([], [], "o", color="tab:green", mec="w", ms=7)[0]
        a["map_peaks"] = mp.plot([], [], "x", color="tab:red", ms=6)[0]
        a["map_target"] = mp.plot([], [], "s", mfc="none", mec="gold", ms=10, mew=2)[0]
        a["map_plan"] = mp.plot([], [], color="gold", lw=1.2, ls="--")[0]
        cm = fig.add_subplot(gs[1, 0])
        cm.set_title("costmap M_c (white free, grey unknown, black obstacle)", fontsize=8)
        cm.tick_params(labelsize=7)
        a["cost"] = None
        a["costax"] = cm
        a["cost_traj"] = cm.plot([], [], color="tab:green", lw=1)[0]
        a["cost_robot"] = cm.plot([], [], "o", color="tab:green", ms=6)[0]
        a["cost_plan"] = cm.plot([], [], color="tab:orange", lw=1.2, ls="--")[0]
        cam = fig.add_subplot(gs[:, 1])
        cam.set_axis_off()
        a["cam"] = cam
        a["cam_title"] = self._label(cam, 0.0, 1.0, "above")
        a["img"] = None
        a["peaks"] = cam.scatter(np.zeros(0), np.zeros(0), s=160, facecolors="none", edgecolors="red", lw=1.5)

    def _trajectory(self) -> np.ndarray:
        """The robot's odometry path (x, y) [m]: the budgeted robot's record when there is one."""
        tr = getattr(self.agent.robot, "trajectory", None)
        if tr:
            return np.asarray(tr, float)[:, 1:3]
        return np.asarray(self._odom, float)[:, :2] if self._odom else np.zeros((0, 2))

    def _draw_search(self) -> None:
        ag, a = self.agent, self._a
        P = np.asarray(ag.pmap.P, float)
        a["map"].set_data(P.T)
        a["map"].set_clim(float(P.min()), float(P.max()) + 1e-12)
        traj = self._trajectory()
        p = ag.robot.odometry()
        a["map_traj"].set_data(traj[:, 0], traj[:, 1])
        a["map_robot"].set_data([p.x], [p.y])
        globals_ = list(getattr(ag, "_globals", ()))
        used = [pk for pk in (globals_[-1].peaks if globals_ else ()) if pk.used and pk.p_W is not None]
        a["map_peaks"].set_data([pk.p_W[0] for pk in used], [pk.p_W[1] for pk in used])
        ev = self._last_event
        target = None
        if ev is not None and ev.cell is not None:
            target = ag.pmap.centre(ev.cell)
            a["map_target"].set_data([target[0]], [target[1]])
        plan = self._planned_path(target, p)
        a["map_plan"].set_data(plan[:, 0], plan[:, 1])
        nav = self.navigator
        if nav is not None:
            state = np.asarray(nav.costmap.state, float)
            shade = np.select([state == 2, state == 1], [0.0, 1.0], 0.6)  # obstacle, free, unknown
            x0, x1, y0, y1 = nav.costmap.spec.extent
            self._image("cost", a["costax"], shade.T, origin="lower", extent=(x0, x1, y0, y1), cmap="gray",
                        vmin=0, vmax=1)  # fmt: skip
        a["cost_traj"].set_data(traj[:, 0], traj[:, 1])
        a["cost_robot"].set_data([p.x], [p.y])
        a["cost_plan"].set_data(plan[:, 0], plan[:, 1])
        if nav is None:
            x0, x1, y0, y1 = ag.pmap.spec.extent
            self._set_lims(a["costax"], (x0, x1), (y0, y1))
        # camera: the found pose, else the last global scan's back-projection peaks
        img, uv, title = self._search_picture(globals_)
        if img is not None:
            self.camera_image = img
            self._image("img", a["cam"], img)
            a["peaks"].set_offsets(uv)
        a["cam_title"].set_text(title)
        what = "" if ev is None else f"{ev.kind}: {ev.detail}"
        a["suptitle"].set_text(
            f"search for {ag.db.name}   t = {self._t():.1f} s   global {ag.global_searches}, "
            f"local {ag.local_searches}\n{what[:110]}"
        )

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
        local = getattr(self.agent, "last_local", None)
        if local is not None and local.found and local.frame is not None and local.estimate is not None:
            from lab.viz.search import draw_pose

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


@dataclass(frozen=True)
class TeleopSpeeds:
    """Commands of the teleoperation buttons: speed [m/s], turn rate [rad/s], box turn rate [rad/s]
    (clipped by the mover's limits in any case)."""

    speed: float = 0.1
    turn_rate: float = 0.5
    box_turn_rate: float = 0.15


class TeleopPanel:
    """Buttons that drive a :class:`~lab.sim.movers.TeleopMover`'s carrier robot by hand.

    ``forward`` / ``back`` drive straight, ``left`` / ``right`` turn on the spot, ``box left`` /
    ``box right`` turn the box on the carrier (the operator hiding its unique face), ``stop`` stops all.
    A command holds until another button is pressed (the mover keeps its last ``set``). Use it in a
    notebook or the classroom demo::

        from lab.viz.live import TeleopPanel
        panel = TeleopPanel(carrier.mover)     # the run's mover, made with make_mover("teleop", ...)
        display(panel.widget)

    Without ipywidgets the handlers still work (:meth:`press`), e.g. from keyboard bindings.

    Parameters
    ----------
    mover : TeleopMover
    speeds : TeleopSpeeds, optional
    """

    BUTTONS = ("forward", "back", "left", "right", "stop", "box left", "box right")

    def __init__(self, mover, speeds: TeleopSpeeds | None = None):
        if not hasattr(mover, "set") or getattr(getattr(mover, "kind", None), "value", None) != "teleop":
            raise ConfigError(
                f"the teleoperation panel drives a teleop mover (make_mover('teleop', ...)), "
                f"got {type(mover).__name__}"
            )
        self.mover = mover
        self.speeds = speeds or TeleopSpeeds()
        self.command = (0.0, 0.0, 0.0)  # v [m/s], omega [rad/s], box rate [rad/s]
        self._widget = None
        self._buttons: dict = {}
        self._label = None

    def press(self, name: str) -> tuple[float, float, float]:
        """What a button does: set the mover's command; returns ``(v, omega, box_rate)``."""
        s = self.speeds
        v, w, b = self.command
        table = {
            "forward": (s.speed, 0.0, b),
            "back": (-s.speed, 0.0, b),
            "left": (0.0, s.turn_rate, b),
            "right": (0.0, -s.turn_rate, b),
            "stop": (0.0, 0.0, 0.0),
            "box left": (v, w, s.box_turn_rate),
            "box right": (v, w, -s.box_turn_rate),
        }
        if name not in table:
            raise ConfigError(f"unknown teleop button {name!r}; buttons: {', '.join(self.BUTTONS)}")
        self.command = table[name]
        self.mover.set(*self.command)
        if self._label is not None:
            self._label.value = self._status()
        return self.command

    def _status(self) -> str:
        v, w, b = self.command
        return f"v = {v:+.2f} m/s, turn = {w:+.2f} rad/s, box = {b:+.2f} rad/s"

    @property
    def buttons(self) -> dict:
        """The ipywidgets buttons by name (built with :attr:`widget`)."""
        self.widget  # noqa: B018 - builds them
        return self._buttons

    @property
    def widget(self):
        """An ipywidgets box with the buttons and a status line."""
        if self._widget is None:
            try:
                import ipywidgets as W
            except ImportError:
                raise ConfigError(
                    "the teleoperation panel needs ipywidgets (pip install ipywidgets)"
                ) from None
            icons = {
                "forward": "arrow-up",
                "back": "arrow-down",
                "left": "rotate-left",
                "right": "rotate-right",
                "stop": "stop",
                "box left": "undo",
                "box right": "redo",
            }
            for name in self.BUTTONS:
                b = W.Button(description=name, icon=icons[name], layout=W.Layout(width="110px"))
                b.on_click(lambda _b, name=name: self.press(name))
                self._buttons[name] = b
            self._label = W.Label(self._status())
            bt = self._buttons
            grid = W.VBox(
                [
                    W.HBox([bt["forward"]]),
                    W.HBox([bt["left"], bt["stop"], bt["right"]]),
                    W.HBox([bt["back"]]),
                    W.HBox([bt["box left"], bt["box right"]]),
                    self._label,
                ]
            )
            self._widget = grid
        return self._widget
