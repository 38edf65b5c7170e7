"""The search's part of the recorded 3D view (:mod:`lab.viz.view3d`): one event's nodes.

* ``M_p`` as a heat map on the floor (an image, log colour scale over :data:`HEAT_DECADES` decades below
  its peak) and, for every surface an object may stand on (table and shelf tops: ``surfaces``), the
  cells over it again at its height, as tiles of the same colours: the map is a floor grid, and a cell
  under a shelf holds the belief that the object stands anywhere in that column, on the shelf too;
* each global scan's views (red frustums) and its colour peaks (red: used), where the robot believed
  its camera was;
* each local search's views (blue frustums: its pan-tilt states from where the robot stood), its last
  frame (orange) and its pose estimate with the 3-sigma ellipsoid of its position;
* the target cell (gold) and a status line.
"""

from __future__ import annotations

import numpy as np

from lab.viz.view3d_nodes import Node, ellipsoid_mesh, frustum_node

__all__ = ["HEAT_DECADES", "MAX_LOCAL_VIEWS", "MAX_SCAN_VIEWS", "SearchScene", "heat_colours"]

HEAT_DECADES = 4.0  # the heat map's colour scale: this many decades below the map's peak
MAX_SCAN_VIEWS = 24  # frustum slots of a global scan's views
MAX_LOCAL_VIEWS = 24  # frustum slots of a local search's views
LOCAL_RGB = (40, 110, 255)


def heat_colours(P: np.ndarray) -> np.ndarray:
    """RGB (uint8, shape ``P.shape + (3,)``) of each cell of ``M_p``: viridis over the log10 of ``P``
    relative to its peak, :data:`HEAT_DECADES` decades down to the bottom of the scale."""
    from matplotlib import colormaps

    P = np.asarray(P, float)
    L = np.log10(np.maximum(P, 1e-300) / P.max())
    return (255 * colormaps["viridis"](np.clip(1.0 + L / HEAT_DECADES, 0.0, 1.0))[..., :3]).astype(np.uint8)


def _cell_rows(spec, polygon, tol_m: float = 1e-6) -> np.ndarray:
    """Indices (k, 2) of the map cells whose centres lie inside the convex ``polygon`` (k, 2) [m] of
    either orientation, its edges included (a cell centred on a table's edge is half on the table)."""
    X, Y = spec.cell_centers()
    pts = np.column_stack([X.ravel(), Y.ravel()])
    poly = np.asarray(polygon, float)
    edges = np.roll(poly, -1, axis=0) - poly
    rel = pts[:, None, :] - poly[None, :, :]
    # signed distance of each point to each edge's line (positive on the left)
    d = (edges[None, :, 0] * rel[:, :, 1] - edges[None, :, 1] * rel[:, :, 0]) / np.linalg.norm(edges, axis=1)
    inside = np.all(d >= -tol_m, axis=1) | np.all(d <= tol_m, axis=1)
    return np.argwhere(inside.reshape(X.shape))


class SearchScene:
    """The search's nodes, event by event, for :class:`lab.viz.view3d.View3D` (it keeps what it drew
    last: the scans and local searches already shown).

    Parameters
    ----------
    surfaces : sequence of (name, z, polygon)
        The tops an object may stand on besides the floor: their name, height [m] and footprint (k, 2)
        [m] (the scene's tables and shelves; :func:`lab.runs.placement.supports`).
    """

    def __init__(self, surfaces=()):
        self.surfaces = [(str(n), float(z), np.asarray(poly, float)) for n, z, poly in surfaces]
        self._cells: dict | None = None  # surface name -> its cells, once the map's grid is known
        self._n_globals = 0
        self._last_local = None

    def nodes(self, agent, event) -> dict:
        """The nodes one search event adds or replaces."""
        pmap = agent.pmap
        colours = heat_colours(pmap.P)
        out = {"/map/heat": self._heat_map(pmap, colours)} | self._surface_tiles(pmap, colours)
        out |= self._scan(agent) | self._local(agent)
        if event.cell is not None:
            cx, cy = pmap.centre(event.cell)
            r = 0.5 * pmap.spec.resolution
            sq = np.array(
                [[cx - r, cy - r], [cx + r, cy - r], [cx + r, cy + r], [cx - r, cy + r], [cx - r, cy - r]]
            )
            sq = np.column_stack([sq, np.full(5, 0.03)])
            out["/map/target"] = Node(
                "lines", {"segments": np.stack([sq[:-1], sq[1:]], 1), "color": (255, 200, 0)}
            )
        out["/status"] = Node(
            "label",
            {
                "text": f"t = {event.t:.1f} s  {event.kind}",
                "position": np.array([*pmap.spec.extent[0::2], 2.8]),
            },
        )
        return out

    @staticmethod
    def _heat_map(pmap, colours) -> Node:
        """``M_p`` as an RGB image on the floor (:func:`heat_colours`)."""
        x0, x1, y0, y1 = pmap.spec.extent
        img = colours.transpose(1, 0, 2)[::-1].copy()  # rows: y from the top (max) down; columns: x
        G = np.eye(4)
        G[:3, 3] = (0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.005)
        return Node(
            "image", {"image": img, "width": x1 - x0, "height": y1 - y0, "G_W": G, "P": pmap.P.copy()}
        )

    def _surface_tiles(self, pmap, colours) -> dict:
        """The map's cells over each table or shelf top, at its height, in the heat map's colours."""
        spec = pmap.spec
        if self._cells is None:
            self._cells = {name: _cell_rows(spec, poly) for name, _, poly in self.surfaces}
        out = {}
        for name, z, _ in self.surfaces:
            cells = self._cells[name]
            if not len(cells):
                continue
            xy = spec.centers_of(cells)
            out[f"/map/surface/{name.replace('/', '.')}"] = Node(
                "points",
                {
                    "points": np.column_stack([xy, np.full(len(cells), z + 0.01)]),
                    "colors": colours[cells[:, 0], cells[:, 1]],
                    "size": 0.9 * spec.resolution,
                    "shape": "square",
                    "cells": cells,
                },
            )
        return out

    def _scan(self, agent) -> dict:
        """A new global scan's views and its colour peaks (nothing when there is none)."""
        globals_ = list(getattr(agent, "_globals", ()))
        if len(globals_) <= self._n_globals:
            return {}
        self._n_globals = len(globals_)
        g = globals_[-1]
        out = {}
        for k in range(MAX_SCAN_VIEWS):
            f = g.views[k].frame if k < len(g.views) else None
            out[f"/camera/scan/{k}"] = (
                None if f is None else frustum_node(f.odom.G() @ f.G_RC, f.camera, (200, 60, 60), 0.3)
            )
        for k in range(MAX_LOCAL_VIEWS):  # the last local search's views belong to the last scan's round
            out[f"/camera/local/{k}"] = None
        pk = [p for p in g.peaks if p.p_W is not None]
        out["/map/peaks"] = Node(
            "points",
            {
                "points": np.array([p.p_W for p in pk], float).reshape(-1, 3),
                "colors": np.array(
                    [(255, 0, 0) if p.used else (255, 160, 160) for p in pk], np.uint8
                ).reshape(-1, 3),
                "size": 0.1,
            },
        )
        return out

    def _local(self, agent) -> dict:
        """A new local search's views (its pan-tilt states, from where the robot stood), its last frame
        and its pose estimate (nothing when there is none)."""
        local = getattr(agent, "last_local", None)
        if local is None or local is self._last_local:
            return {}
        self._last_local = local
        camera = local.frame.camera if local.frame is not None else agent.robot.camera
        G_WR = (local.frame.odom if local.frame is not None else agent.robot.odometry()).G()
        out = {}
        for k in range(MAX_LOCAL_VIEWS):
            v = local.views[k] if k < len(local.views) else None
            out[f"/camera/local/{k}"] = (
                None if v is None else frustum_node(G_WR @ camera.G_RC(v.pan, v.tilt), camera, LOCAL_RGB, 0.3)
            )
        if local.frame is not None:
            f = local.frame
            out["/camera/frustum"] = frustum_node(f.odom.G() @ f.G_RC, f.camera)
        if local.frame is not None and local.estimate is not None:
            out |= _estimate(agent, local)
        return out


def _estimate(agent, local) -> dict:
    """A local search's pose estimate: the object's box and the 3-sigma ellipsoid of its position."""
    G_WC = local.frame.odom.G() @ local.frame.G_RC
    G_WO = G_WC @ local.estimate.G_CO
    Sigma_W = G_WC[:3, :3] @ local.estimate.Sigma[:3, :3] @ G_WC[:3, :3].T
    rgb = (0, 200, 0) if local.found else (255, 150, 0)
    box = {
        "G_W": G_WO,
        "size": tuple(float(v) for v in agent.db.extent),
        "color": rgb,
        "opacity": 1.0,
        "wireframe": True,
    }
    return {
        "/object/estimate": Node("box", box),
        "/object/ellipsoid": Node(
            "mesh",
            ellipsoid_mesh(G_WO[:3, 3], Sigma_W).props | {"color": rgb, "opacity": 0.45, "Sigma_W": Sigma_W},
        ),
    }
