"""The live loop: an observer that redraws a view's panels at a rate of sim time and feeds its sinks.

:class:`LiveView` is what the agents call (their observer); it decides when a picture is due, has its
panels (:class:`~lab.viz.live.identification.IdentificationPanels` or
:class:`~lab.viz.live.search.SearchPanels`) draw on a :class:`~lab.viz.live.canvas.PanelCanvas`, and
pushes the picture to an ``ipywidgets.Image``, a :class:`~lab.viz.recorder.Recorder` and a window.
"""

from __future__ import annotations

import math
import os

import numpy as np

from lab.errors import ConfigError
from lab.viz.images import png_bytes
from lab.viz.live.canvas import PanelCanvas
from lab.viz.live.identification import IdentificationPanels
from lab.viz.live.search import SearchPanels

__all__ = ["LiveView", "in_background"]


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


class LiveView:
    """A live picture of a run, redrawn at most ``rate_hz`` times per second of sim time.

    Build it with :meth:`for_identification` or :meth:`for_search`; it installs itself as the agent's
    observer. Calling the view (``view(agent, frame_or_event)``) is the observer protocol.

    Parameters
    ----------
    panels : IdentificationPanels or SearchPanels
        What the picture shows, and of which agent (``panels.agent``).
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
    """

    def __init__(
        self,
        panels: IdentificationPanels | SearchPanels,
        rate_hz: float | None = 2.0,
        recorder=None,
        widget: bool = True,
        window: bool = False,
        size_px: tuple[int, int] = (960, 540),
    ):
        if rate_hz is not None and not (math.isfinite(rate_hz) and 0.05 <= rate_hz <= 50):
            raise ConfigError(f"rate_hz must be within [0.05, 50] Hz of sim time (or None), got {rate_hz!r}")
        w, h = size_px
        if not (200 <= w <= 4000 and 150 <= h <= 4000):
            raise ConfigError(f"size_px must be within (200..4000, 150..4000) px, got {size_px!r}")
        self.panels = panels
        self.agent = panels.agent
        self.rate_hz = rate_hz
        self.recorder = recorder
        self._want_widget = widget
        self._widget = None
        self._window = window and bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
        self._win = None
        self.n_calls = 0
        self.n_draws = 0
        self.t_last: float | None = None
        self._next_t: float | None = None
        self._prev = None  # the observer this view was chained after
        self._dpi = 80
        self._size = (w / self._dpi, h / self._dpi)
        self.canvas = PanelCanvas(self._size, self._dpi)

    # --- construction ---------------------------------------------------------------------------
    @classmethod
    def for_identification(cls, agent, **kw) -> LiveView:
        """A view of an :class:`~lab.identification.agent.IdentificationAgent`, hooked in as its observer
        (an observer already there, e.g. a recording's view, is called first: they chain)."""
        view = cls(IdentificationPanels(agent), **kw)
        view._hook()
        return view

    @classmethod
    def for_search(cls, agent, follow_robot: bool = True, **kw) -> LiveView:
        """A view of a :class:`~lab.search.agent.SearchAgent`, hooked in as its observer.

        ``navigator`` (a keyword) is whose costmap to draw (default: ``agent.navigate.navigator`` when
        present). The agent reports events (a global search, an arrival, a local search), which are
        seconds to minutes apart; with ``follow_robot`` and a ``rate_hz``, the view also redraws at that
        rate while the robot drives or scans, from the robot's steps (its ``step`` is wrapped on this
        instance; :meth:`close` unwraps it). A recording (``rate_hz=None``) draws one frame per event only.
        """
        navigator = kw.pop("navigator", getattr(agent.navigate, "navigator", None))
        view = cls(SearchPanels(agent, navigator), **kw)
        view._hook()
        if follow_robot and view.rate_hz is not None:
            view._follow(agent.robot)
        return view

    def _hook(self) -> None:
        """Become the agent's observer, chained after the one there."""
        name = self.panels.observer_attribute
        self._prev = getattr(self.agent, name)
        setattr(self.agent, name, self)

    def _follow(self, robot) -> None:
        """Redraw when due from the robot's steps too (its ``step`` wrapped on the instance)."""
        base_step = robot.step

        def step(dt: float) -> None:
            base_step(dt)
            if self._due(robot.now()):
                self.update()

        robot.step = step
        self._robot_wrapped = robot

    # --- the observer protocol ------------------------------------------------------------------
    def __call__(self, agent, item) -> None:
        """Called by the agent: ``item`` is the step's StereoFrame (identification) or a SearchEvent."""
        if self._prev is not None:
            self._prev(agent, item)
        self.n_calls += 1
        self.panels.observe(agent, item)
        if self._due(float(item.t)):
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

    # --- the sinks ------------------------------------------------------------------------------
    def update(self) -> np.ndarray:
        """Draw now and push the picture to the widget, the recorder and the window; returns it (RGB)."""
        rgb = self.render()
        self.n_draws += 1
        t = self.panels.t()
        self.t_last = t
        if self._want_widget and self._widget is not None:
            self._widget.value = png_bytes(rgb)
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
                self._widget.value = png_bytes(self.render())
        return self._widget

    def _show_window(self, rgb: np.ndarray) -> None:  # pragma: no cover - needs a display
        import matplotlib.pyplot as plt

        if self._win is None:
            fig = plt.figure(f"lab live view ({self.panels.kind})", figsize=self._size, dpi=self._dpi)
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
        name = self.panels.observer_attribute
        if getattr(self.agent, name, None) is self:
            setattr(self.agent, name, self._prev)
        robot = self.__dict__.pop("_robot_wrapped", None)
        if robot is not None and "step" in vars(robot):
            del robot.step  # the class's step again
        self.canvas.close()

    # --- drawing --------------------------------------------------------------------------------
    def render(self) -> np.ndarray:
        """The current picture as an RGB ``uint8`` array, shape (H, W, 3) (no widget, no recorder)."""
        if self.canvas.fig is None:
            self.canvas.build(self.panels)
        self.canvas.suptitle.set_text(self.panels.draw(self.canvas))
        return self.canvas.render()

    @property
    def camera_image(self) -> np.ndarray | None:
        """The camera panel's picture, as last drawn (RGB), or None before the first."""
        return self.panels.camera_image

    @property
    def n_full_draws(self) -> int:
        """Renders that redrew the axes (the others blit the data only)."""
        return self.canvas.n_full_draws
