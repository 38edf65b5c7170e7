"""The page of a recorded 3D view (:mod:`lab.viz.view3d`): its log of steps replayed into a `viser
<https://viser.studio>`_ scene recorder, written as one self-contained HTML page (viser's client and the
recording inlined: no fetch from the web), and shown inline in a notebook.

viser is the optional extra ``view3d`` (``pip install 'lab[view3d]'``); without it,
:func:`require_viser` raises the one line that says so.
"""

from __future__ import annotations

import contextlib
import html as html_module
import io
from pathlib import Path

import numpy as np

from lab.errors import ConfigError

__all__ = [
    "CHART_LENGTH_M",
    "INSTALL_HINT",
    "LAST_STEP_HOLD_S",
    "iframe",
    "require_viser",
    "show_page",
    "write_page",
]

CHART_LENGTH_M = 3.0  # the time series chart: its time axis spans the whole run [m]
#: The page's timeline runs this long past the last step [s]: viser's player stops at the end of the
#: recording without applying the messages stamped exactly there, so the last step would never show.
LAST_STEP_HOLD_S = 1.0

#: The one line a user reads when the viewer library is missing.
INSTALL_HINT = (
    "the 3D view (--view3d) needs the optional package viser: pip install 'lab[view3d]' "
    "(in a clone: uv sync --extra view3d)"
)


def require_viser():
    """The viser module, or :class:`ConfigError` with :data:`INSTALL_HINT` (one line)."""
    try:
        import viser
    except ImportError:
        raise ConfigError(INSTALL_HINT) from None
    return viser


def show_page(path, height: int = 520):
    """A saved 3D view inline in a notebook: an iframe holding the page itself (no server, no web
    access; the notebook keeps it in its output)."""
    return iframe(Path(path).read_text(encoding="utf-8"), height)


def iframe(page: str, height: int):
    """The page inline, in an iframe of its own (its scripts apart from the notebook's)."""
    import warnings

    from IPython.display import HTML

    with warnings.catch_warnings():  # IPython suggests IFrame, which needs a URL: the page has none
        warnings.filterwarnings("ignore", message="Consider using IPython.display.IFrame")
        return HTML(
            f'<iframe srcdoc="{html_module.escape(page, quote=True)}" width="100%" '
            f'height="{int(height)}" style="border:1px solid #ddd"></iframe>'
        )


def _wxyz(R: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(R).as_quat()
    return np.array([w, x, y, z])


def write_page(steps, camera) -> str:
    """Replay the log (:class:`lab.viz.view3d.Step3D`, in time order) into a viser scene recorder (a
    local server on 127.0.0.1, never contacted; its banner kept off stdout) and return its standalone
    HTML page, first seen from ``camera`` = (position, look at) [m]."""
    viser = require_viser()
    quiet = io.StringIO()  # viser announces its server on stdout, where `lab identify` writes its JSON
    with contextlib.redirect_stdout(quiet):
        server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        scene = server.scene
        scene.set_up_direction("+z")
        server.initial_camera.position, server.initial_camera.look_at = camera
        duration = steps[-1].t - steps[0].t if steps else 0.0
        chart_scale = CHART_LENGTH_M / max(duration, 1e-6)  # [m/s] on the time series chart
        rec = server.get_scene_serializer()
        t_prev = steps[0].t if steps else 0.0
        with server.atomic():  # one batch for a server nobody connects to: no wake-up per message
            for st in steps:
                rec.insert_sleep(max(0.0, st.t - t_prev))
                t_prev = max(t_prev, st.t)
                for name, node in st.nodes.items():
                    if node is None:
                        scene.remove_by_name(name)
                    else:
                        _add(scene, name, node, chart_scale)
            rec.insert_sleep(LAST_STEP_HOLD_S)  # the player never applies what falls on its very end
        return rec.as_html()
    finally:
        with contextlib.redirect_stdout(quiet):
            server.stop()


def _add(scene, name: str, node, chart_scale: float = 1.0) -> None:
    p = node.props
    pose = {}
    if "G_W" in p:
        pose = {"wxyz": _wxyz(p["G_W"][:3, :3]), "position": p["G_W"][:3, 3]}
    k = node.kind
    if k == "box":
        scene.add_box(
            name,
            color=p["color"],
            dimensions=p["size"],
            opacity=p.get("opacity"),
            wireframe=p.get("wireframe", False),
            **pose,
        )
    elif k == "cylinder":
        scene.add_cylinder(
            name,
            radius=p["radius"],
            height=p["height"],
            color=p["color"],
            opacity=p.get("opacity"),
            wireframe=p.get("wireframe", False),
            **pose,
        )
    elif k == "lines":
        seg = np.array(p["segments"], np.float32)
        if "chart_x0" in p:  # a time series: x in seconds from the start, scaled to the chart's length
            seg[..., 0] = p["chart_x0"] + chart_scale * seg[..., 0]
        colors = p["colors"] if "colors" in p else p["color"]
        if isinstance(colors, np.ndarray) and colors.ndim == 2:
            colors = np.repeat(colors[:, None, :], 2, axis=1)
        scene.add_line_segments(name, seg, colors, thickness=p.get("thickness", 0.015))
    elif k == "points":
        if len(p["points"]):
            scene.add_point_cloud(
                name,
                np.asarray(p["points"], np.float32),
                p["colors"],
                point_size=p.get("size", 0.02),
                point_shape=p.get("shape", "circle"),
            )
        else:
            scene.remove_by_name(name)
    elif k == "frustum":
        scene.add_camera_frustum(
            name, fov=p["fov"], aspect=p["aspect"], scale=p["scale"], color=p["color"], **pose
        )
    elif k == "mesh":
        scene.add_mesh_simple(
            name,
            np.asarray(p["vertices"], np.float32),
            p["faces"],
            color=p["color"],
            opacity=p.get("opacity"),
        )
    elif k == "image":
        scene.add_image(name, p["image"], p["width"], p["height"], format="png", **pose)
    elif k == "label":
        scene.add_label(name, p["text"], position=np.asarray(p["position"], float))
    else:  # pragma: no cover - a kind this writer does not know is a bug of the recorder
        raise ValueError(f"unknown node kind {k!r}")
