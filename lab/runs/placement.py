"""Where a searchable object may stand in a scene: on the floor, on a table or on a shelf.

Used by the trials (:func:`lab.runs.search.run_search`) to place the object by seed, and to refuse a
placement that puts it inside a wall, outside the room, inside furniture or in mid-air. Footprints are
the bodies' rectangles (boxes, tables, shelves, turned by their yaw) and circles (cylinders) on the
floor; a placement's pose is the scene file's ``(x, y, z_underside, yaw_deg)``. The boxes a trial puts
on the robot's way to the object (the paper's second set of trials) are placed here too
(:func:`path_obstacles`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from lab.errors import ConfigError
from lab.scene import BodySpec, Scene, load_scene

__all__ = [
    "SURFACES",
    "Support",
    "check_placement",
    "circle_polygon",
    "footprint",
    "path_obstacles",
    "polygon_inside",
    "polygons_overlap",
    "random_placement",
    "searchable_objects",
    "supports",
]

#: The heights the trials place objects at (the paper's "three different heights").
SURFACES = ("floor", "table", "shelf")

_HEIGHT_TOL = 0.02  # [m] a placement's z must match its surface within this


def searchable_objects(scene: str | Scene = "lab_room") -> list[str]:
    """Names of the bodies with role ``object`` (what ``lab search --list-objects`` prints)."""
    sc = scene if isinstance(scene, Scene) else load_scene(scene)
    return sc.names("object")


@dataclass(frozen=True)
class Support:
    """A surface an object can stand on: its kind, the body, its top height [m] and footprint."""

    kind: str  # "floor", "table" or "shelf"
    name: str
    z: float
    polygon: np.ndarray  # (k, 2) [m], counter-clockwise; the room's interior for the floor


def _rectangle(cx: float, cy: float, sx: float, sy: float, yaw: float, grow: float = 0.0) -> np.ndarray:
    hx, hy = 0.5 * sx + grow, 0.5 * sy + grow
    c, s = math.cos(yaw), math.sin(yaw)
    corners = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
    return corners @ np.array([[c, s], [-s, c]]) + (cx, cy)


def circle_polygon(cx: float, cy: float, r: float, grow: float = 0.0, n: int = 16) -> np.ndarray:
    """A circle of radius ``r + grow`` [m] as a convex ``n``-gon (k, 2) that contains it."""
    a = np.linspace(0.0, 2.0 * math.pi, n, endpoint=False)
    # the polygon circumscribes the circle, so the test is conservative
    R = (r + grow) / math.cos(math.pi / n)
    return np.stack([cx + R * np.cos(a), cy + R * np.sin(a)], axis=1)


def footprint(body: BodySpec, grow: float = 0.0, pose=None) -> np.ndarray:
    """The body's footprint on the floor as a convex polygon (k, 2) [m], grown by ``grow``."""
    x, y, _, yaw_deg = body.pose if pose is None else pose
    if body.shape == "cylinder":
        return circle_polygon(x, y, body.size[0], grow)
    return _rectangle(x, y, body.size[0], body.size[1], math.radians(yaw_deg), grow)


def polygons_overlap(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two convex polygons overlap (separating axis theorem)."""
    for poly in (a, b):
        edges = np.roll(poly, -1, axis=0) - poly
        normals = np.stack([-edges[:, 1], edges[:, 0]], axis=1)
        pa, pb = a @ normals.T, b @ normals.T
        if np.any((pa.max(axis=0) < pb.min(axis=0)) | (pb.max(axis=0) < pa.min(axis=0))):
            return False
    return True


def polygon_inside(inner: np.ndarray, outer: np.ndarray) -> bool:
    """Whether every vertex of ``inner`` lies inside the convex, counter-clockwise polygon ``outer``."""
    edges = np.roll(outer, -1, axis=0) - outer
    rel = inner[:, None, :] - outer[None, :, :]
    cross = edges[None, :, 0] * rel[:, :, 1] - edges[None, :, 1] * rel[:, :, 0]
    return bool(np.all(cross >= -1e-12))


def _ccw(poly: np.ndarray) -> np.ndarray:
    area = 0.5 * np.sum(poly[:, 0] * np.roll(poly[:, 1], -1) - np.roll(poly[:, 0], -1) * poly[:, 1])
    return poly if area > 0 else poly[::-1]


def supports(scene: Scene) -> list[Support]:
    """The floor (the room's interior) and every body marked ``supports`` (tables and shelves)."""
    if scene.room is None:
        raise ConfigError(f"scene {scene.name!r} has no room: no floor to search")
    sx, sy = scene.room.size
    out = [Support("floor", "floor", 0.0, _rectangle(0.0, 0.0, sx, sy, 0.0))]
    for b in scene.bodies:
        if b.supports:
            kind = "table" if b.shape == "table" else "shelf"
            out.append(Support(kind, b.name, b.pose[2] + b.height, _ccw(footprint(b))))
    return out


def _object_body(scene: Scene, name: str) -> BodySpec:
    names = searchable_objects(scene)
    if name not in names:
        raise ConfigError(f"unknown object {name!r}; searchable objects: {', '.join(names)}")
    return scene.body(name)


def check_placement(
    scene: Scene, name: str, place, clearance_m: float = 0.05, robot_clearance_m: float = 0.5
) -> Support:
    """Refuse a placement that is not a valid spot; return the surface it stands on.

    Parameters
    ----------
    scene : Scene
    name : str
        The object to place.
    place : (x, y, z_underside, yaw_deg)
    clearance_m : float [m]
        Smallest gap to the other bodies on the same level.
    robot_clearance_m : float [m]
        Smallest distance from the robot's start position.

    Raises
    ------
    ConfigError
        With what is wrong: not four finite numbers, outside the room or in a wall, at a height that is
        neither the floor nor a table or shelf top under it, overlapping another body, on the robot.
    """
    vals = tuple(place) if isinstance(place, (list, tuple, np.ndarray)) else ()
    if len(vals) != 4 or not all(isinstance(v, (int, float, np.floating, np.integer)) for v in vals):
        raise ConfigError(f"a placement is X,Y,Z,YAW_DEG (4 numbers), got {place!r}")
    x, y, z, yaw = (float(v) for v in vals)
    if not all(math.isfinite(v) for v in (x, y, z, yaw)):
        raise ConfigError(f"a placement must be finite, got {place!r}")
    body = _object_body(scene, name)
    fp = footprint(body, pose=(x, y, z, yaw))
    sups = supports(scene)
    floor = sups[0]
    sx, sy = scene.room.size
    if not polygon_inside(fp, floor.polygon):
        raise ConfigError(
            f"placement ({x:.2f}, {y:.2f}) of {name} is outside the room or inside a wall "
            f"(the room spans x [{-sx / 2:.2f}, {sx / 2:.2f}], y [{-sy / 2:.2f}, {sy / 2:.2f}] m)"
        )
    under = [s for s in sups[1:] if polygons_overlap(fp, s.polygon)]
    support = None
    if abs(z) <= _HEIGHT_TOL:
        if under:
            raise ConfigError(f"placement of {name} on the floor is under or inside {under[0].name}")
        support = floor
    else:
        for s in under:
            if abs(z - s.z) <= _HEIGHT_TOL and polygon_inside(fp, s.polygon):
                support = s
                break
        if support is None:
            tops = ", ".join(f"{s.name} at z = {s.z:.2f} m" for s in sups[1:])
            raise ConfigError(
                f"placement of {name} at z = {z:.2f} m does not stand on anything: use z = 0 (floor) or "
                f"the top of a table or shelf with the object wholly on it ({tops})"
            )
    z_top = z + body.height
    for b in scene.bodies:
        if b.name == name or b.name == support.name or b.role == "decor":
            continue
        bz0, bz1 = b.pose[2], b.pose[2] + b.height
        if bz1 <= z + 1e-6 or bz0 >= z_top - 1e-6:
            continue  # not at the same level
        if polygons_overlap(fp, footprint(b, clearance_m)):
            raise ConfigError(f"placement of {name} at ({x:.2f}, {y:.2f}, {z:.2f}) overlaps {b.name}")
    rx, ry, _ = scene.robot_start
    if support is floor and polygons_overlap(fp, circle_polygon(rx, ry, robot_clearance_m)):
        raise ConfigError(
            f"placement of {name} at ({x:.2f}, {y:.2f}) is within {robot_clearance_m} m of the robot's start"
        )
    return support


def random_placement(
    scene: Scene,
    name: str,
    rng: np.random.Generator,
    surface: str | None = None,
    wall_margin_m: float = 0.45,
    floor_clearance_m: float = 0.45,
    min_start_distance_m: float = 1.0,
    max_tries: int = 2000,
) -> tuple[float, float, float, float]:
    """A seeded random valid placement ``(x, y, z_underside, yaw_deg)`` of ``name``.

    ``surface`` (``"floor"``, ``"table"`` or ``"shelf"``) picks the height; random when None. On the
    floor the object keeps ``wall_margin_m`` from the walls and ``floor_clearance_m`` from other bodies
    (so the robot can come close), and ``min_start_distance_m`` from the robot's start; on a table
    or shelf it stands wholly on the top, clear of other objects there.
    """
    if surface is not None and surface not in SURFACES:
        raise ConfigError(f"surface must be one of {', '.join(SURFACES)}, got {surface!r}")
    body = _object_body(scene, name)
    sups = supports(scene)
    kind = surface or SURFACES[int(rng.integers(len(SURFACES)))]
    cands = [s for s in sups if s.kind == kind]
    if not cands:
        raise ConfigError(f"scene {scene.name!r} has no {kind} to place {name} on")
    r_obj = body.footprint_radius
    rx, ry, _ = scene.robot_start
    for _ in range(max_tries):
        s = cands[int(rng.integers(len(cands)))]
        lo, hi = s.polygon.min(axis=0), s.polygon.max(axis=0)
        margin = wall_margin_m if kind == "floor" else r_obj + 0.02
        if np.any(hi - lo <= 2 * margin):
            continue
        x, y = (float(v) for v in rng.uniform(lo + margin, hi - margin))
        yaw = float(rng.uniform(0.0, 360.0))
        place = (x, y, s.z, yaw)
        if kind == "floor" and math.hypot(x - rx, y - ry) < min_start_distance_m:
            continue
        clearance = floor_clearance_m if kind == "floor" else 0.05
        try:
            got = check_placement(scene, name, place, clearance_m=clearance)
        except ConfigError:
            continue
        if got.kind == kind:
            return place
    raise ConfigError(f"found no valid {kind} placement for {name} in {max_tries} tries")


def path_obstacles(
    scene: Scene, name: str, place, rng: np.random.Generator, n: int = 2, size=(0.3, 0.3, 0.5)
) -> tuple[Scene, list[tuple[float, float, float, float]]]:
    """Put ``n`` boxes on the straight line from the robot's start to the object (the "obstacles placed
    in the planned path" of the paper's second set of trials).

    Each box goes at a random point along the middle of the line (jittered sideways by up to 15 cm),
    clear of other bodies by 0.35 m, at least 0.8 m from the start and 1.0 m from the object, so the
    robot can still get past and stand near the object. Boxes that find no such spot are left out.
    """
    rx, ry, _ = scene.robot_start
    ox, oy = float(place[0]), float(place[1])
    length = math.hypot(ox - rx, oy - ry)
    room = supports(scene)[0].polygon
    out_bodies, poses = list(scene.bodies), []
    ux, uy = ((ox - rx) / length, (oy - ry) / length) if length > 1e-9 else (1.0, 0.0)
    for k in range(n):
        for _ in range(200):
            s = rng.uniform(0.8, max(0.8, length - 1.0))
            lat = rng.uniform(-0.15, 0.15)
            x, y = rx + s * ux - lat * uy, ry + s * uy + lat * ux
            yaw = float(rng.uniform(0, 90))
            body = BodySpec(
                f"obstacle_{k + 1}", "box", tuple(size), (x, y, 0.0, yaw), "obstacle", (0.45, 0.4, 0.35)
            )
            fp = footprint(body)
            if not polygon_inside(footprint(body, 0.35), room):
                continue
            if any(polygons_overlap(fp, footprint(b, 0.35)) for b in out_bodies if b.role != "decor"):
                continue
            near_start = polygons_overlap(fp, circle_polygon(rx, ry, 0.6))
            if near_start or polygons_overlap(fp, circle_polygon(ox, oy, 1.0)):
                continue
            out_bodies.append(body)
            poses.append((x, y, 0.0, yaw))
            break
    return replace(scene, bodies=tuple(out_bodies)), poses
