"""A searched-for object that moves: the search's object carried by a small carrier, over the floor or
over a table's top.

The object (a scene body on the floor or on a table's top) rides an unseen carrier that drives straight
legs between free points at ``speed_mps`` and pauses ``pause_s`` after each leg. Its free space is
where it stands:

* **the floor**: the room's floor less every body's footprint grown by ``clearance_m``;
* **a table's top** (the object placed on a table): the top less a margin at its edges, so that the
  object's footprint (the circle that covers it) never overhangs an edge and it never falls off, and
  less the other bodies standing on the top (another object). The carrier cannot leave the top, and
  the robot's base cannot come onto it, so it needs no proximity stop there (``keep_away_m`` is for
  the floor).

Two behaviours (:class:`MovingKind`):

* ``random``: a random walk in free space: each leg goes to a random free point within
  ``leg_m`` that the straight line reaches without coming within ``clearance_m`` of an obstacle or
  within ``keep_away_m`` of the robot;
* ``evasive``: as ``random`` while unseen; when it stands in the robot's camera's field of view
  (within ``sight_range_m``) it drops its pause and leaves on the leg that ends farthest outside the
  camera's view cone (the identification paper's operator, who keeps the box from the camera).

Like the identification paper's carrier and its movers (:mod:`lab.sim.carrier`, :mod:`lab.sim.movers`),
it is part of the world: it may read the true occupancy and the robot's true camera, which the
searching agent never can. It keeps its track of true poses, ``(t, G_WO)``, for scoring a find
against the truth at the moment of the find (:meth:`MovingObject.G_WO_at`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

import numpy as np

from lab.errors import ConfigError
from lab.geometry import se3

__all__ = ["MovingKind", "MovingObject", "MovingObjectConfig", "make_moving_object"]


class MovingKind(Enum):
    RANDOM = "random"
    EVASIVE = "evasive"


@dataclass(frozen=True)
class MovingObjectConfig:
    """How the object moves.

    Attributes
    ----------
    kind : MovingKind
    speed_mps : float [m/s]
        Its speed on a leg (the speed bound a search may assume).
    pause_s : float [s]
        How long it stands after each leg.
    leg_m : (float, float) [m]
        Shortest and longest leg.
    clearance_m : float [m]
        Distance its centre keeps from every obstacle's footprint.
    keep_away_m : float [m]
        Distance its legs keep from the robot's base (it never drives into the robot): a leg is chosen
        clear of where the robot stands, and a step that would bring it nearer than this to where the
        robot stands now ends the leg there (the robot moved since; a carrier robot's proximity stop).
        It never approaches a robot that stands still, so whatever it stands next to, the robot saw
        come (a robot's camera does not see the floor within about half a metre of its base).
    sight_range_m : float [m]
        How far the evasive object notices the camera.
    top_margin_m : float [m]
        On a table's top: the gap the object's footprint circle keeps from the top's edges and from the
        other bodies' footprints there (a leg that starts nearer one than this never comes nearer).
    top_leg_m : (float, float) [m]
        Shortest and longest leg on a table's top (a top is about a metre long: the floor's legs would
        seldom fit).
    """

    kind: MovingKind = MovingKind.RANDOM
    speed_mps: float = 0.1
    pause_s: float = 5.0
    leg_m: tuple[float, float] = (0.4, 1.5)
    clearance_m: float = 0.3
    keep_away_m: float = 0.8
    sight_range_m: float = 5.0
    top_margin_m: float = 0.03
    top_leg_m: tuple[float, float] = (0.1, 0.8)

    def __post_init__(self):
        if not (math.isfinite(self.speed_mps) and self.speed_mps > 0):
            raise ConfigError(f"the object's speed must be a finite number > 0 m/s, got {self.speed_mps!r}")
        if not (math.isfinite(self.pause_s) and self.pause_s >= 0):
            raise ConfigError(f"the pause must be a finite number >= 0 s, got {self.pause_s!r}")
        for name, (lo, hi) in (("leg_m", self.leg_m), ("top_leg_m", self.top_leg_m)):
            if not 0 < lo <= hi:
                raise ConfigError(f"{name} must be 0 < shortest <= longest, got {(lo, hi)!r}")
        if not (math.isfinite(self.top_margin_m) and self.top_margin_m >= 0):
            raise ConfigError(f"top_margin_m must be a finite number >= 0 m, got {self.top_margin_m!r}")


class MovingObject:
    """Moves the scene body ``name`` of ``world`` as its config says; the world calls :meth:`advance`
    at every step (it sits in ``world.carriers``).

    Parameters
    ----------
    world : SimWorld
    name : str
        The object's body (standing on the floor or on a table's top: it drives there).
    config : MovingObjectConfig
    rng : numpy Generator
        Its legs (seeded by the trial).
    """

    GRID_M = 0.05  # the occupancy grid it plans its legs on [m]

    def __init__(self, world, name: str, config: MovingObjectConfig, rng: np.random.Generator):
        self.world, self.name, self.config, self.rng = world, name, config, rng
        G = world.truth.G_W(name)
        self.xy = np.array(G[:3, 3][:2], dtype=float)
        self.z = float(G[2, 3])
        self.R = G[:3, :3].copy()
        x0, x1, y0, y1 = self._room(world)
        self.spec = _Grid(
            (x0, y0), self.GRID_M, (round((x1 - x0) / self.GRID_M), round((y1 - y0) / self.GRID_M))
        )
        body = world.scene.body(name)
        self.top = _table_under(world.scene, body, self.xy, self.z - 0.5 * body.height)
        if self.top is None:
            occ = world.truth.occupancy(self.spec, 0.02, 2.0, exclude=("floor", "robot", name))
            self.free = ~_grow(occ, config.clearance_m / self.GRID_M)
        else:
            self.r_m = body.footprint_radius  # the circle that covers its footprint [m]
            z = self.top.pose[2] + self.top.height
            occ = world.truth.occupancy(self.spec, z + 0.01, z + 2.0, exclude=("floor", "robot", name))
            X, Y = _centres(self.spec)
            reach = 0.5 * math.hypot(*self.top.size[:2]) + 0.5  # the cells within half a metre of the top
            occ &= np.hypot(X - self.top.pose[0], Y - self.top.pose[1]) < reach
            self.occupied_xy = np.column_stack([X[occ], Y[occ]])  # what stands on the top, or over it
            gaps = self._top_gaps(np.column_stack([X.ravel(), Y.ravel()]))
            self.free = (gaps >= config.top_margin_m).reshape(self.spec.shape)
        self.goal: np.ndarray | None = None
        self.pause_left = config.pause_s
        self.track: list[tuple[float, np.ndarray]] = [(world.t, G.copy())]
        self.legs = self.evasions = 0

    @property
    def surface(self) -> str:
        """Where it drives: ``"floor"`` or the name of the table whose top it is on."""
        return "floor" if self.top is None else self.top.name

    def path_length_m(self) -> float:
        """How far it has driven [m] (its track of true poses)."""
        xy = np.array([G[:2, 3] for _, G in self.track])
        return float(np.hypot(*np.diff(xy, axis=0).T).sum()) if len(xy) > 1 else 0.0

    @staticmethod
    def _room(world) -> tuple[float, float, float, float]:
        sx, sy = (float(v) for v in world.scene.room.size)
        return -sx / 2, sx / 2, -sy / 2, sy / 2

    # -- the truth, for scoring ---------------------------------------------------------------------
    @property
    def G_WO(self) -> np.ndarray:
        return se3(self.R, np.array([self.xy[0], self.xy[1], self.z]))

    def G_WO_at(self, t: float) -> np.ndarray:
        """The true pose at world time ``t`` [s] (the last recorded at or before ``t``)."""
        k = max(0, int(np.searchsorted([s for s, _ in self.track], t, side="right")) - 1)
        return self.track[k][1]

    # -- motion ------------------------------------------------------------------------------------
    def advance(self, dt: float) -> None:
        """Move for ``dt`` [s]: along the current leg, or pause, or choose the next leg."""
        cfg = self.config
        if cfg.kind is MovingKind.EVASIVE and self.seen() and (self.goal is None or self._goal_in_view()):
            self.goal = self._leg(evade=True)
            self.evasions += self.goal is not None
        if self.goal is None:
            self.pause_left -= dt
            if self.pause_left > 0:
                return
            self.goal = self._leg(evade=False)
            self.pause_left = cfg.pause_s
            if self.goal is None:
                return
            self.legs += 1
        step = self.goal - self.xy
        d = float(np.hypot(*step))
        move = cfg.speed_mps * dt
        nxt = self.goal.copy() if d <= move else self.xy + step * (move / d)
        if self._nearing_robot(nxt):
            self.goal = None  # the proximity stop: the leg ends here, and the pause begins
            return
        self.xy = nxt
        if d <= move:
            self.goal = None
        self.world.set_body_pose(self.name, self.G_WO)
        self.track.append((self.world.t + dt, self.G_WO))

    def _nearing_robot(self, nxt: np.ndarray) -> bool:
        """Whether the step to ``nxt`` [m] comes nearer to the robot's base than ``keep_away_m`` and
        nearer than it stands now (a step away from a robot that came close is allowed)."""
        if self.world.robot is None or self.top is not None:  # on a top it cannot reach the robot
            return False
        r = self.world.truth.robot_pose()
        d_next = math.hypot(nxt[0] - r.x, nxt[1] - r.y)
        return d_next < self.config.keep_away_m and d_next < math.hypot(self.xy[0] - r.x, self.xy[1] - r.y)

    def seen(self, xy=None) -> bool:
        """Whether a point (default: the object) is in the robot camera's view cone within range."""
        if self.world.robot is None:
            return False
        p = np.array([*(self.xy if xy is None else xy), self.z, 1.0])
        G_WC = self.world.truth.G_WC()
        p_C = np.linalg.solve(G_WC, p)[:3]
        if not 0.1 < p_C[2] < self.config.sight_range_m:
            return False
        cam = self.world.robot.camera
        return (
            abs(p_C[0] / p_C[2]) < cam.width / 2 / cam.fx and abs(p_C[1] / p_C[2]) < cam.height / 2 / cam.fy
        )

    def _goal_in_view(self) -> bool:
        return self.goal is not None and self.seen(self.goal)

    def _leg(self, evade: bool) -> np.ndarray | None:
        """The next leg's end: a random reachable free point, or (evading) the one of a few that is
        out of view and farthest from the robot."""
        lo, hi = self.config.leg_m if self.top is None else self.config.top_leg_m
        robot = self.world.truth.robot_pose() if self.world.robot is not None else None
        cands = []
        for _ in range(40):
            a, r = self.rng.uniform(0, 2 * math.pi), self.rng.uniform(lo, hi)
            end = self.xy + r * np.array([math.cos(a), math.sin(a)])
            if self._clear(end, robot):
                cands.append(end)
                if not evade:
                    return end
        if not cands:
            return None
        rx, ry = (robot.x, robot.y) if robot is not None else (0.0, 0.0)
        return max(cands, key=lambda e: (not self.seen(e), math.hypot(e[0] - rx, e[1] - ry)))

    def _clear(self, end: np.ndarray, robot) -> bool:
        n = max(2, int(np.hypot(*(end - self.xy)) / (self.GRID_M / 2)))
        pts = self.xy + np.linspace(0, 1, n)[:, None] * (end - self.xy)
        if self.top is not None:  # the top's edges and what stands on it: never nearer than now
            gaps = self._top_gaps(pts)
            return bool(gaps.min() >= min(self.config.top_margin_m, gaps[0]))
        ij = np.floor((pts - self.spec.origin_xy) / self.GRID_M).astype(int)
        nx, ny = self.spec.shape
        if not ((ij >= 0).all() and (ij[:, 0] < nx).all() and (ij[:, 1] < ny).all()):
            return False
        if not self.free[ij[:, 0], ij[:, 1]].all():
            return False
        if robot is None:
            return True
        return bool(np.min(np.hypot(pts[:, 0] - robot.x, pts[:, 1] - robot.y)) > self.config.keep_away_m)

    def _top_gaps(self, pts: np.ndarray) -> np.ndarray:
        """The gap [m] between the object's footprint circle at each point ``pts`` (n, 2) [m] and the
        nearest of the table top's edges and the other bodies standing on it (negative: over an edge,
        or into a body). A body's footprint lies within its occupied cells, each within half a cell's
        diagonal of its centre, so the gap stated to a body is never more than the true one."""
        x, y, _, yaw_deg = self.top.pose
        c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
        d = pts - (x, y)
        u, v = c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]  # in the table's frame
        gap = np.minimum(0.5 * self.top.size[0] - np.abs(u), 0.5 * self.top.size[1] - np.abs(v)) - self.r_m
        for k in range(0, len(self.occupied_xy), 256):  # in blocks: (n, 256) distances at a time
            o = self.occupied_xy[k : k + 256]
            near = np.hypot(pts[:, None, 0] - o[None, :, 0], pts[:, None, 1] - o[None, :, 1]).min(axis=1)
            gap = np.minimum(gap, near - self.GRID_M / math.sqrt(2.0) - self.r_m)
        return gap


@dataclass(frozen=True)
class _Grid:
    """A floor grid as :meth:`lab.sim.truth.Truth.occupancy` takes it."""

    origin_xy: tuple[float, float]
    resolution: float
    shape: tuple[int, int]


def _centres(spec: _Grid) -> tuple[np.ndarray, np.ndarray]:
    """The grid's cell centres [m], each of shape ``spec.shape``."""
    (ox, oy), r, (nx, ny) = spec.origin_xy, spec.resolution, spec.shape
    return np.meshgrid(ox + (np.arange(nx) + 0.5) * r, oy + (np.arange(ny) + 0.5) * r, indexing="ij")


def _table_under(scene, body, xy: np.ndarray, z_underside: float, tol_m: float = 0.02):
    """The table whose top the object stands on (its scene body), or None on the floor.

    Raises
    ------
    ConfigError
        It stands on neither the floor nor a table's top (a shelf, or in mid-air).
    """
    if abs(z_underside) <= tol_m:
        return None
    for b in scene.bodies:
        if not (b.supports and b.shape == "table") or abs(b.pose[2] + b.height - z_underside) > tol_m:
            continue
        c, s = math.cos(b.yaw), math.sin(b.yaw)
        dx, dy = xy[0] - b.pose[0], xy[1] - b.pose[1]
        if abs(c * dx + s * dy) <= 0.5 * b.size[0] and abs(-s * dx + c * dy) <= 0.5 * b.size[1]:
            return b
    raise ConfigError(
        f"a carrier drives on the floor or on a table's top; {body.name} stands at z = {z_underside:.2f} m "
        "on neither"
    )


def _grow(occ: np.ndarray, r_cells: float) -> np.ndarray:
    """Occupied cells grown by a disc of ``r_cells`` cells."""
    r = int(math.ceil(r_cells))
    out = occ.copy()
    nx, ny = occ.shape
    for di in range(-r, r + 1):
        for dj in range(-r, r + 1):
            if di * di + dj * dj > r_cells * r_cells:
                continue
            src = occ[max(0, -di) : nx - max(0, di), max(0, -dj) : ny - max(0, dj)]
            out[max(0, di) : nx - max(0, -di), max(0, dj) : ny - max(0, -dj)] |= src
    return out


def make_moving_object(
    world, name: str, config: MovingObjectConfig, rng: np.random.Generator
) -> MovingObject:
    """Put a :class:`MovingObject` on ``name`` and register it with the world's carriers."""
    m = MovingObject(world, name, config, rng)
    world.carriers[f"{name}/carrier"] = m
    return m
