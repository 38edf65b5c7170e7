"""A PyBullet world built from a scene file: bodies by name, stereo rendering, carriers, ground truth.

The carriers are :mod:`lab.sim.carrier`, the ground truth :mod:`lab.sim.truth`, and the quiet import
of pybullet :mod:`lab.sim.client`.

This module (with the rest of ``lab.sim``) is the only code that imports pybullet. Every world has its
own physics client (``p.DIRECT``: headless TinyRenderer by default), so several can live side by side.
All bodies are kinematic: robots and carriers are moved by integrating their velocity commands and
placed with ``resetBasePositionAndOrientation``; contacts are found with ``getClosestPoints``. This keeps
runs exact and repeatable: the same seed gives the same images, bit for bit.

Ground truth (true poses, collisions) is reached through :attr:`SimWorld.truth` and is meant for tests
and evaluation only; the algorithms see the world through :class:`lab.sim.SimRobot`.
"""

from __future__ import annotations

import math
import os
import pkgutil
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

import cv2
import numpy as np

from lab.errors import ConfigError
from lab.geometry import Pose2D, R_to_quat_xyzw, Rz, planar_G, se3, translation
from lab.scene import BodySpec, ModelSpec, Scene, load_scene
from lab.sim.assets import box_mesh
from lab.sim.carrier import Carrier
from lab.sim.client import BulletClient, pybullet, quiet_stdout
from lab.sim.truth import Truth

__all__ = [
    "Carrier",
    "RenderSettings",
    "SimWorld",
    "Truth",
    "box_model",
    "load_box_models",
    "pybullet",
    "viewpoint_G_WC",
]


@dataclass(frozen=True)
class RenderSettings:
    """How images are rendered.

    Attributes
    ----------
    supersample : int
        Render at this multiple of the image size and downsample with ``INTER_AREA`` (1 or 2). 2 cuts
        the stereo error at 1 m from about 13 mm to about 4 mm for 4x the render time.
    renderer : str
        ``"tiny"`` (TinyRenderer, the default, no system libraries) or ``"egl"`` (Mesa EGL, faster,
        filtered textures; textures must come from .mtl files, which ours do).
    shadows : bool
        Off by default: shadows double the render time and change about 0.6 % of the pixels.
    light_direction : tuple of 3 floats
        Direction towards the light, world frame.
    near, far : float [m]
        Clipping planes.
    """

    supersample: int = 1
    renderer: str = "tiny"
    shadows: bool = False
    light_direction: tuple[float, float, float] = (0.4, -0.3, 1.0)
    near: float = 0.05
    far: float = 20.0

    def __post_init__(self):
        if self.supersample not in (1, 2, 3, 4):
            raise ConfigError(f"supersample must be 1, 2, 3 or 4, got {self.supersample!r}")
        if self.renderer not in ("tiny", "egl"):
            raise ConfigError(f"renderer must be 'tiny' or 'egl', got {self.renderer!r}")
        if not 0 < self.near < self.far:
            raise ConfigError(f"clipping planes need 0 < near < far, got near={self.near}, far={self.far}")


def load_box_models(scene: str = "box_database") -> tuple[ModelSpec, ...]:
    """The identification database's box models (from ``worlds/box_database.toml``)."""
    models = load_scene(scene).models
    if not models:
        raise ConfigError(f"scene {scene!r} defines no [[model]] entries")
    return models


def box_model(index, scene: str = "box_database") -> ModelSpec:
    """Box model ``index`` of :func:`load_box_models`, or a ConfigError naming the models there are."""
    models = load_box_models(scene)
    if not (isinstance(index, int) and not isinstance(index, bool) and 0 <= index < len(models)):
        raise ConfigError(
            f"unknown true model {index!r}; models: 0..{len(models) - 1} "
            f"({', '.join(m.name for m in models)})"
        )
    return models[index]


class SimWorld:
    """A scene loaded into its own PyBullet client.

    Parameters
    ----------
    scene : str, Path or Scene
        A world name (``"lab_room"``), a path to a scene file, or a parsed :class:`Scene`.
    render : RenderSettings, optional
    gui : bool
        Open the PyBullet GUI. Needs a display: without one, ``p.connect(p.GUI)`` would kill the whole
        process, so this raises :class:`ConfigError` instead.
    """

    def __init__(
        self, scene: str | Scene = "lab_room", render: RenderSettings | None = None, gui: bool = False
    ):
        self.scene = scene if isinstance(scene, Scene) else load_scene(scene)
        self.settings = render or RenderSettings()
        if gui and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
            raise ConfigError("gui=True needs a display (DISPLAY is not set); run headless with gui=False")
        with quiet_stdout():
            self.p = BulletClient(connection_mode=pybullet.GUI if gui else pybullet.DIRECT)
            if self.settings.renderer == "egl":
                egl = pkgutil.get_loader("eglRenderer")
                if egl is None or self.p.loadPlugin(egl.get_filename(), "_eglRendererPlugin") < 0:
                    raise ConfigError("the EGL renderer plugin could not be loaded; use renderer='tiny'")
        self.p.setGravity(0, 0, -9.81)
        self.t = 0.0
        self._ids: dict[str, int] = {}
        self._names: dict[int, str] = {}
        self._ids_view = MappingProxyType(self._ids)
        self.carriers: dict[str, Carrier] = {}
        self.robot = None  # set by SimRobot
        self.truth = Truth(self)
        self._renders: dict = {}  # the last few renders by what they saw (render())
        self.n_renders = self.n_renders_reused = 0
        self._build()

    # --- construction ---------------------------------------------------------------------------
    def register(self, name: str, body_id: int) -> None:
        """Give the PyBullet body ``body_id`` the unique ``name`` (``body_id(name)``, ``body_name(id)``).

        Every registered body counts for the robot's collision check and the true occupancy; a name
        used twice is a ConfigError.
        """
        if name in self._ids:
            raise ConfigError(f"a body named {name!r} already exists in world {self.scene.name!r}")
        self._ids[name] = body_id
        self._names[body_id] = name

    def body_id(self, name: str) -> int:
        try:
            return self._ids[name]
        except KeyError:
            raise ConfigError(
                f"world {self.scene.name!r} has no body {name!r}; bodies: {', '.join(sorted(self._ids))}"
            ) from None

    def body_name(self, body_id: int) -> str | None:
        return self._names.get(body_id)

    @property
    def names(self) -> list[str]:
        return sorted(self._ids)

    @property
    def body_ids(self) -> Mapping[str, int]:
        """Every registered body's PyBullet id by name, in the order registered (a read-only view)."""
        return self._ids_view

    def create_textured_box(
        self, size, texture, uv_mode, tile_m=1.0, mass=0.0, pos=(0, 0, 0), yaw=0.0
    ) -> int:
        """Create a box body with a textured mesh (not registered: see :meth:`register`); its PyBullet id.

        ``size`` is (sx, sy, sz) [m]; ``texture`` an image file; ``uv_mode`` and ``tile_m`` say how the
        texture is laid on the faces (:func:`lab.sim.assets.box_mesh`); ``pos`` is its centre and
        ``yaw`` [rad] its turn about z.
        """
        obj = box_mesh(size, texture, uv_mode, tile_m)
        vis = self.p.createVisualShape(pybullet.GEOM_MESH, fileName=str(obj), meshScale=(1, 1, 1))
        col = self.p.createCollisionShape(pybullet.GEOM_BOX, halfExtents=[0.5 * s for s in size])
        return self.p.createMultiBody(mass, col, vis, pos, R_to_quat_xyzw(Rz(yaw)))

    def _plain_box(self, size, color, pos, yaw=0.0) -> int:
        half = [0.5 * s for s in size]
        vis = self.p.createVisualShape(pybullet.GEOM_BOX, halfExtents=half, rgbaColor=(*color, 1))
        col = self.p.createCollisionShape(pybullet.GEOM_BOX, halfExtents=half)
        return self.p.createMultiBody(0, col, vis, pos, R_to_quat_xyzw(Rz(yaw)))

    def _box(self, size, b: BodySpec | None, pos, yaw, uv="tiled", tile_m=0.5) -> int:
        if b is not None and b.texture is not None:
            return self.create_textured_box(size, b.texture, uv, tile_m, pos=pos, yaw=yaw)
        return self._plain_box(size, b.color if b else (0.7, 0.7, 0.7), pos, yaw)

    def _build(self):
        room = self.scene.room
        if room is not None:
            sx, sy = room.size
            floor_tex = room.floor_texture
            floor = (sx + 2 * room.wall_thickness, sy + 2 * room.wall_thickness, 0.02)
            fid = (
                self.create_textured_box(floor, floor_tex, "tiled", room.tile_m, pos=(0, 0, -0.01))
                if floor_tex
                else self._plain_box(floor, (0.6, 0.6, 0.6), (0, 0, -0.01))
            )
            self.register("floor", fid)
            h, t = room.wall_height, room.wall_thickness
            walls = {
                "wall_north": ((sx + 2 * t, t, h), (0, sy / 2 + t / 2, h / 2)),
                "wall_south": ((sx + 2 * t, t, h), (0, -sy / 2 - t / 2, h / 2)),
                "wall_east": ((t, sy, h), (sx / 2 + t / 2, 0, h / 2)),
                "wall_west": ((t, sy, h), (-sx / 2 - t / 2, 0, h / 2)),
            }
            for name, (size, pos) in walls.items():
                wid = (
                    self.create_textured_box(size, room.wall_texture, "tiled", room.tile_m, pos=pos)
                    if room.wall_texture
                    else self._plain_box(size, (0.85, 0.85, 0.8), pos)
                )
                self.register(name, wid)
        else:
            # a bare floor, 12 x 12 m, for scenes without a room (the training ring)
            from lab.paths import worlds_dir

            tex = worlds_dir() / "textures" / "floor.png"
            self.register(
                "floor", self.create_textured_box((12, 12, 0.02), tex, "tiled", 1.0, pos=(0, 0, -0.01))
            )
        for b in self.scene.bodies:
            self.register(b.name, self._build_body(b))

    def _build_body(self, b: BodySpec) -> int:
        x, y, z, _ = b.pose
        yaw = b.yaw
        cx, cy, cz = b.centre
        if b.shape == "cylinder":
            r, h = b.size
            vis = self.p.createVisualShape(
                pybullet.GEOM_CYLINDER, radius=r, length=h, rgbaColor=(*b.color, 1)
            )
            col = self.p.createCollisionShape(pybullet.GEOM_CYLINDER, radius=r, height=h)
            return self.p.createMultiBody(0, col, vis, (cx, cy, cz))
        if b.shape == "textured_box":
            return self.create_textured_box(b.size, b.atlas, "atlas", pos=(cx, cy, cz), yaw=yaw)
        if b.shape == "poster":
            return self.create_textured_box(b.size, b.texture, "stretch", pos=(cx, cy, cz), yaw=yaw)
        if b.shape == "table":
            return self._table(b)
        return self._box(b.size, b, (cx, cy, cz), yaw)  # box, shelf

    def _table(self, b: BodySpec) -> int:
        """A table: a 4 cm top and four 5 cm legs, as one body (its frame at the top's centre)."""
        sx, sy, h = b.size
        x, y, z, _ = b.pose
        top_t, leg = 0.04, 0.05
        R = Rz(b.yaw)
        top_c = np.array([x, y, z + h - top_t / 2])
        top = self._box((sx, sy, top_t), b, top_c, b.yaw)
        legs_h = h - top_t
        for i, (ax, ay) in enumerate(((1, 1), (1, -1), (-1, 1), (-1, -1))):
            off = R @ np.array([ax * (sx / 2 - leg), ay * (sy / 2 - leg), 0.0])
            lid = self._box((leg, leg, legs_h), b, (x + off[0], y + off[1], z + legs_h / 2), b.yaw)
            self.register(f"{b.name}/leg{i}", lid)
        return top

    def add_carrier(
        self, model: ModelSpec, pose: Pose2D, box_yaw: float = 0.0, name: str = "target"
    ) -> Carrier:
        """Put a box model on a second robot at ``pose``; the box is addressable as ``name``."""
        c = Carrier(self, name, model, pose, box_yaw)
        self.carriers[name] = c
        return c

    def add_box(
        self,
        name: str,
        size,
        xy,
        yaw: float = 0.0,
        z: float = 0.0,
        texture: str | os.PathLike | None = "textures/metal.png",
        color=(0.7, 0.7, 0.7),
    ) -> int:
        """Add a box to the world while it runs (an obstacle dropped in the robot's way).

        Parameters
        ----------
        name : str
            Unique body name (``body_id(name)``, ``set_body_pose(name, ...)``).
        size : (sx, sy, sz) [m]
        xy : (x, y) [m]
            Centre of its footprint in the world.
        yaw : float [rad]
        z : float [m]
            Height of its underside (0: standing on the floor).
        texture : path or None
            A tiled texture relative to the worlds folder (stereo needs texture to see a face); None
            gives a plain box of ``color``.

        Returns
        -------
        int
            The PyBullet body id. The robot's collision check sees the box from the next step on.
        """
        size = tuple(float(v) for v in size)
        x, y = (float(v) for v in xy)
        if len(size) != 3 or not all(math.isfinite(v) and v > 0 for v in size):
            raise ConfigError(f"box size must be three finite numbers > 0 m, got {size!r}")
        if not all(math.isfinite(v) for v in (x, y, yaw, z)):
            raise ConfigError(f"box pose must be finite, got xy={xy!r}, yaw={yaw!r}, z={z!r}")
        if name in self._ids:
            raise ConfigError(f"a body named {name!r} already exists in world {self.scene.name!r}")
        pos = (x, y, float(z) + size[2] / 2)
        if texture is not None:
            from lab.paths import worlds_dir

            bid = self.create_textured_box(size, worlds_dir() / texture, "tiled", 0.5, pos=pos, yaw=yaw)
        else:
            bid = self._plain_box(size, color, pos, yaw)
        self.register(name, bid)
        return bid

    def set_body_pose(self, name: str, G_W: np.ndarray) -> None:
        """Move a body (for trials that place objects elsewhere); ``G_W`` is its frame in the world."""
        self.p.resetBasePositionAndOrientation(self.body_id(name), G_W[:3, 3], R_to_quat_xyzw(G_W[:3, :3]))

    # --- time -----------------------------------------------------------------------------------
    def step(self, dt: float) -> None:
        """Advance the world's clock by ``dt`` [s], moving the carriers."""
        for c in self.carriers.values():
            c.advance(dt)
        self.t += dt

    # --- rendering ------------------------------------------------------------------------------
    def render(
        self,
        G_WC: np.ndarray,
        camera,
        want_depth: bool = False,
        want_seg: bool = False,
        supersample: int | None = None,
        light_direction=None,
    ):
        """Render the view of a pinhole camera whose optical frame C is at ``G_WC``.

        Parameters
        ----------
        G_WC : ndarray, shape (4, 4)
            Camera optical frame (x right, y down, z forward) in the world.
        camera : lab.robot.StereoCamera
            Gives the image size and vertical field of view (``fx == fy``).
        want_depth, want_seg : bool
            Also return metric depth [m] along the optical axis and the body id per pixel
            (both at the rendered resolution, so use ``supersample=1`` for ground truth).
        light_direction : tuple of 3 floats, optional
            Direction towards the light, world frame; default ``RenderSettings.light_direction``.

        Returns
        -------
        rgb : ndarray, shape (H, W, 3), uint8
        depth : ndarray, shape (H', W') float32 [m], or None
        seg : ndarray, shape (H', W') int32, or None

        Notes
        -----
        A view whose camera, image settings and every body's pose are those of one of the last
        :attr:`RENDERS_KEPT` renders is not rendered again: copies of that render's images are returned
        (the renderer is deterministic, so they are the very images; a stereo pair keeps two).
        ``n_renders`` counts the calls, ``n_renders_reused`` those answered so.
        """
        s = self.settings.supersample if supersample is None else supersample
        W, H = camera.width * s, camera.height * s
        view = self._view_matrix(G_WC)
        proj = self.projection_matrix(camera, s)
        flags = 0 if want_seg else pybullet.ER_NO_SEGMENTATION_MASK
        renderer = (
            pybullet.ER_TINY_RENDERER
            if self.settings.renderer == "tiny"
            else pybullet.ER_BULLET_HARDWARE_OPENGL
        )
        light = tuple(self.settings.light_direction if light_direction is None else light_direction)
        key = (
            tuple(view),
            tuple(proj),
            W,
            H,
            s,
            flags,
            want_depth,
            want_seg,
            self.settings.shadows,
            light,
            renderer,
            self._scene_state(),
        )
        self.n_renders += 1
        kept = self._renders.get(key)
        if kept is not None:  # nothing in view moved: the same images
            self.n_renders_reused += 1
            self._renders[key] = self._renders.pop(key)  # most recent last
            return tuple(None if a is None else a.copy() for a in kept)
        out = self._render_images(camera, s, view, proj, flags, renderer, light, want_depth, want_seg)
        self._keep_render(key, out)
        return out

    def _view_matrix(self, G_WC: np.ndarray) -> list[float]:
        """OpenGL view matrix (16 floats) of the optical frame C at ``G_WC`` (z forward, y down)."""
        eye = G_WC[:3, 3]
        fwd = G_WC[:3, 2]
        up = -G_WC[:3, 1]
        return self.p.computeViewMatrix(eye.tolist(), (eye + fwd).tolist(), up.tolist())

    def _render_images(self, camera, s, view, proj, flags, renderer, light, want_depth, want_seg):
        """One call of the renderer at ``s`` times ``camera``'s size: ``(rgb, depth, seg)`` as
        :meth:`render` returns them (rgb downsampled to the camera's size)."""
        W, H = camera.width * s, camera.height * s
        _, _, rgba, depth_buf, seg = self.p.getCameraImage(
            W,
            H,
            view,
            proj,
            shadow=int(self.settings.shadows),
            lightDirection=light,
            renderer=renderer,
            flags=flags,
        )
        rgb = np.asarray(rgba, dtype=np.uint8).reshape(H, W, 4)[:, :, :3]
        if s > 1:
            rgb = cv2.resize(rgb, (camera.width, camera.height), interpolation=cv2.INTER_AREA)
        depth = None
        if want_depth:
            d = np.asarray(depth_buf, dtype=np.float32).reshape(H, W)
            near, far = self.settings.near, self.settings.far
            depth = far * near / (far - (far - near) * d)  # OpenGL depth buffer -> metric z
        segm = np.asarray(seg, dtype=np.int32).reshape(H, W) if want_seg else None
        if segm is not None:
            segm = np.where(segm >= 0, segm & ((1 << 24) - 1), -1)
        return (np.ascontiguousarray(rgb), depth, segm)

    def _keep_render(self, key: tuple, out: tuple) -> None:
        """Keep copies of a render's images under ``key``, dropping the oldest beyond RENDERS_KEPT."""
        self._renders[key] = tuple(None if a is None else a.copy() for a in out)
        while len(self._renders) > self.RENDERS_KEPT:
            self._renders.pop(next(iter(self._renders)))  # the oldest

    #: Renders kept for a view that did not change (a stereo pair is two).
    RENDERS_KEPT = 2

    def _scene_state(self) -> tuple:
        """Every body's base pose: what a render sees of the scene (the bodies have no joints and
        their looks never change after they are made)."""
        p = self.p
        poses = (p.getBasePositionAndOrientation(p.getBodyUniqueId(i)) for i in range(p.getNumBodies()))
        return tuple(pos + quat for pos, quat in poses)

    def projection_matrix(self, camera, supersample: int = 1) -> list[float]:
        """OpenGL projection (column-major, 16 floats) whose image has exactly ``camera``'s intrinsics.

        Built from ``fx, fy, cx, cy`` rather than a field of view, so any principal point is honoured.
        TinyRenderer samples each pixel at its corner, not its centre, and flips the rows; measured
        (``tests/test_sim_render.py``) that puts the principal point at ``(W/2, H/2 - 1)`` with
        ``computeProjectionMatrixFOV``. The off-centre terms below undo that, so a render at any
        supersampling factor has ``cx = W/2 - 0.5, cy = H/2 - 0.5`` as ``StereoCamera.from_fov`` says.
        EGL (real OpenGL) samples pixel centres.
        """
        s = supersample
        W, H = camera.width * s, camera.height * s
        fx, fy = camera.fx * s, camera.fy * s
        # pixel index u in the s-times image that INTER_AREA maps onto index (u - (s-1)/2)/s
        cx, cy = camera.cx * s + (s - 1) / 2, camera.cy * s + (s - 1) / 2
        if self.settings.renderer == "tiny":  # samples at x_screen = u, rows r = H - 1 - y_screen
            p02, p12 = 1.0 - 2.0 * cx / W, 2.0 * (cy - H / 2 + 1.0) / H
        else:  # samples at pixel centres: x_screen = u + 0.5, r + 0.5 = H - y_screen
            p02, p12 = 1.0 - 2.0 * (cx + 0.5) / W, 2.0 * (cy - H / 2 + 0.5) / H
        n, f = self.settings.near, self.settings.far
        P = np.array(
            [
                [2.0 * fx / W, 0.0, p02, 0.0],
                [0.0, 2.0 * fy / H, p12, 0.0],
                [0.0, 0.0, -(f + n) / (f - n), -2.0 * f * n / (f - n)],
                [0.0, 0.0, -1.0, 0.0],
            ]
        )
        return P.T.reshape(-1).tolist()  # column-major, as pybullet expects

    def render_stereo(self, G_WC: np.ndarray, camera, light_direction=None):
        """Left and right images of a rectified pair whose left optical frame is at ``G_WC``.

        ``light_direction`` (default ``RenderSettings.light_direction``) is passed to :meth:`render`.
        """
        left, _, _ = self.render(G_WC, camera, light_direction=light_direction)
        G_WC_right = G_WC @ translation(camera.baseline, 0.0, 0.0)
        right, _, _ = self.render(G_WC_right, camera, light_direction=light_direction)
        return left, right

    def close(self) -> None:
        if getattr(self, "p", None) is not None:
            try:
                self.p.disconnect()
            except Exception:  # already gone
                pass
            self.p = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass


def viewpoint_G_WC(eye, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """An optical frame C at ``eye`` looking at ``target`` (for free cameras: training, figures)."""
    eye, target, up = (np.asarray(v, dtype=float) for v in (eye, target, up))
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-9:
        raise ConfigError("viewpoint: the viewing direction is parallel to 'up'")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return se3(np.stack([x, y, z], axis=1), eye)


_ = planar_G  # re-exported helpers used by callers of this module
