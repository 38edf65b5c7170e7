"""Figures and pictures. Algorithms never plot; they return data that these modules draw.

* :mod:`lab.viz.images`: PNG bytes, an RGB image saved atomically, the dense disparity as colour.
* :mod:`lab.viz.identification`: the identification paper's Figs. 5, 6 and 7.
* :mod:`lab.viz.search`: the search paper's Figs. 2, 5 and 6, and a pose drawn on an image.
* :mod:`lab.viz.live`: live views of a run (notebook widget, window, recording): the loop, the canvas,
  the identification and the search panels.
* :mod:`lab.viz.teleop`: buttons that drive the teleop mover's carrier by hand.
* :mod:`lab.viz.recorder`: a run's frames stamped with sim time, written as GIF or MP4.

Importing this package starts neither the simulator (pybullet) nor matplotlib; the figure modules
import matplotlib when they are imported.
"""

from __future__ import annotations

from lab.vision.dense import disparity_map
from lab.viz.images import disparity_picture, png_bytes, save_rgb

__all__ = ["disparity_map", "disparity_picture", "png_bytes", "save_rgb"]
