"""Teleoperation of the moving box: buttons that drive a :class:`~lab.sim.movers.TeleopMover`'s carrier.

``TeleopPanel(mover).widget`` in a notebook (or the classroom demo) shows the buttons; without
ipywidgets, :meth:`TeleopPanel.press` is what a button does (for keyboard bindings). Run the episode with
:func:`lab.viz.live.in_background` so that the clicks are handled while it runs.
"""

from __future__ import annotations

from dataclasses import dataclass

from lab.errors import ConfigError

__all__ = ["TeleopPanel", "TeleopSpeeds"]


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

        from lab.viz.teleop import TeleopPanel
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
