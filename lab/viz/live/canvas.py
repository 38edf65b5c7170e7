"""The live view's figure: drawn once, then only its data blitted over a saved background.

A :class:`PanelCanvas` holds a matplotlib figure on the Agg backend with the 2 x 2 grid the panels are
laid out in. The axes, ticks and labels are drawn only when a limit moves (a *full* draw, rare: the
panels move their limits in coarse steps); every other picture restores the saved background and
draws the *animated* data artists over it. Status texts that change at every picture are
:class:`StatusLabel` s, drawn with OpenCV on the RGB array (Agg lays out a string in ~5 ms, OpenCV in
~0.1 ms).
"""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["PanelCanvas", "StatusLabel"]


class StatusLabel:
    """A status text that changes at every picture, drawn with OpenCV over the rendered figure.

    Placed at the fraction ``(fx, fy)`` of its axes (or of the figure when ``ax`` is None): its
    top-left corner there (``how="left"``), or its top-centre (``"center"``), or its bottom-left
    (``"above"``: just above that point).
    """

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


class PanelCanvas:
    """A figure of ``size_in`` inches at ``dpi``, drawn by blitting (see the module's docstring).

    :meth:`build` makes the figure and lets a view's panels add their axes and artists; every artist
    they keep in their ``a`` dict is animated (redrawn at every picture). :meth:`render` returns the
    picture as an RGB array.
    """

    def __init__(self, size_in: tuple[float, float], dpi: int):
        self.size_in = size_in
        self.dpi = dpi
        self.fig = None
        self.suptitle: StatusLabel | None = None
        self.n_full_draws = 0  # renders that redrew the axes (the others blit the data only)

    def build(self, panels) -> None:
        """A new figure with the panels' grid; ``panels.build(self, fig, gs)`` adds their axes."""
        from matplotlib.artist import Artist
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        fig = Figure(figsize=self.size_in, dpi=self.dpi)
        FigureCanvasAgg(fig)
        gs = fig.add_gridspec(
            2, 2, width_ratios=(1.0, 1.15), left=0.06, right=0.93, bottom=0.08, top=0.93,
            wspace=0.18, hspace=0.32,
        )  # fmt: skip
        self.fig = fig
        self._dyn: list = []
        self._labels: list[StatusLabel] = []
        self._bg = None
        self._dirty = True
        panels.build(self, fig, gs)
        self.suptitle = self.label(None, 0.5, 0.995, "center")
        for v in list(panels.a.values()):  # every data artist the panels made: animated
            for art in v if isinstance(v, list) else [v]:
                if isinstance(art, Artist):
                    self.animate(art)

    def close(self) -> None:
        """Free the figure (the next :meth:`build` makes a new one)."""
        self.fig = None

    def render(self) -> np.ndarray:
        """The picture as an RGB ``uint8`` array, shape (H, W, 3).

        Blitting: the axes, ticks and labels change only when a limit does; the data artists are
        "animated" and drawn over a saved background.
        """
        fig, canvas = self.fig, self.fig.canvas
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

    def label(self, ax, fx: float, fy: float, how: str = "left") -> StatusLabel:
        """A :class:`StatusLabel` drawn over every picture (in the order they were made)."""
        lab = StatusLabel(ax, fx, fy, how)
        self._labels.append(lab)
        return lab

    def animate(self, art, first: bool = False):
        """Mark an artist as redrawn at every render (drawn first, under the others, when ``first``)."""
        art.set_animated(True)
        if first:
            self._dyn.insert(0, art)
        else:
            self._dyn.append(art)
        return art

    def remove(self, art) -> None:
        """Take an animated artist out of the picture (and out of its axes)."""
        self._dyn.remove(art)
        art.remove()

    def set_lims(self, ax, xlim, ylim) -> None:
        """Set the axes' limits; a change makes the next render a full one (new ticks)."""
        if not (np.allclose(ax.get_xlim(), xlim) and np.allclose(ax.get_ylim(), ylim)):
            ax.set_xlim(*xlim)
            ax.set_ylim(*ylim)
            self._dirty = True

    def image(self, im, ax, img: np.ndarray, **kw):
        """Show ``img`` in ``ax`` through the animated image ``im`` (None: made here; one of another size:
        re-made); returns the image artist to keep."""
        if im is not None and im.get_array().shape[:2] != img.shape[:2]:
            self.remove(im)
            im = None
        if im is None:
            im = self.animate(ax.imshow(img, interpolation="nearest", **kw), first=True)
            self._dirty = True  # imshow sets the axes' limits
        else:
            im.set_data(img)
        return im
