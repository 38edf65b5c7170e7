"""Test-only helpers for the search tests: a stand-in navigator that plans on the scene's GROUND TRUTH,
and set-ups that place the robot in front of an object from the truth.

The real ``Navigator`` (stereo costmap + A*, ``lab.navigation.navigator``) replaces
:class:`TruthNavigator` in ``lab search``; the agent takes either through the same call,
``navigate(target_xy, min_distance, max_distance) -> NavigationResult``. This one knows the obstacles from the
scene file (every body's footprint, tables whole, the walls), so it isolates the search from
costmap errors; it plans with ``lab.navigation``'s A* to the ring around the target and drives with
its pure-pursuit follower on odometry, like the real one will.
"""

from __future__ import annotations

import math

import numpy as np

from lab.geometry import Pose2D
from lab.navigation import Costmap, GridSpec, astar_to_region, drive_to, heading_towards, simplify_path
from lab.navigation.follower import DriveOutcome
from lab.runs.placement import footprint
from lab.search.records import NavigationResult


def _inside_convex(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Which points (n, 2) lie inside a convex polygon (k, 2) of either orientation."""
    edges = np.roll(poly, -1, axis=0) - poly
    rel = points[:, None, :] - poly[None, :, :]
    cross = edges[None, :, 0] * rel[:, :, 1] - edges[None, :, 1] * rel[:, :, 0]
    return np.all(cross >= 0, axis=1) | np.all(cross <= 0, axis=1)


def truth_occupancy(scene, spec: GridSpec) -> np.ndarray:
    """Cells covered by a body's footprint (all roles but decor) or lying on the room's border."""
    X, Y = spec.cell_centers()
    pts = np.stack([X.ravel(), Y.ravel()], axis=1)
    occ = np.zeros(len(pts), bool)
    half = 0.5 * spec.resolution
    for b in scene.bodies:
        if b.role == "decor":
            continue
        occ |= _inside_convex(pts, footprint(b, grow=half))  # a cell touched by the footprint
    occ = occ.reshape(spec.shape)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = True  # the walls
    return occ


class TruthNavigator:
    """``navigate(target_xy, min_distance, max_distance)`` by A* on the true occupancy and pure pursuit.

    Parameters
    ----------
    robot : Robot
        What to drive (the search's budgeted robot); its ``base`` (a SimRobot) gives the world.
    resolution : float [m]
        Costmap cells (the paper's 10 cm).
    margin : float [m]
        Obstacles are grown by the robot's radius plus this.
    timeout_s : float [s]
        Bound on one drive.
    """

    def __init__(self, robot, resolution: float = 0.1, margin: float = 0.12, timeout_s: float = 90.0):
        self.robot = robot
        sim = getattr(robot, "base", robot)
        scene = sim.world.scene
        sx, sy = scene.room.size
        self.spec = GridSpec.from_bounds(-sx / 2, -sy / 2, sx / 2, sy / 2, resolution)
        self.occupancy = truth_occupancy(scene, self.spec)
        cm = Costmap.from_occupancy(self.spec, self.occupancy)
        r = robot.base_limits.radius
        self.grids = [cm.inflated(r + margin), cm.inflated(r + 0.02)]  # the second when the start is blocked
        self.timeout_s = timeout_s
        self.calls: list[tuple] = []

    def __call__(self, target_xy, min_distance: float, max_distance: float) -> NavigationResult:
        pose = self.robot.odometry()
        for grid in self.grids:
            path = astar_to_region(grid, pose, target_xy, max_distance, min_distance)
            if path.found or path.reason != "START_IN_OBSTACLE":
                break
        self.calls.append((tuple(target_xy), path.reason))
        if not path.found:
            return NavigationResult(False, f"no path: {path.reason}", pose)
        waypoints = simplify_path(path, grid)
        if len(waypoints) == 1:
            waypoints = np.array([[pose.x, pose.y]])
        else:
            waypoints[0] = (pose.x, pose.y)
        heading = heading_towards(waypoints[-1], target_xy)
        res = drive_to(self.robot, waypoints, heading, timeout=self.timeout_s)
        ok = res.outcome is DriveOutcome.ARRIVED
        return NavigationResult(ok, res.outcome.value, res.pose, path.points_xy)


def truth_navigator(robot, spec) -> TruthNavigator:
    """The factory ``run_search(navigate=...)`` takes."""
    return TruthNavigator(robot)


def stand_in_front(scene, xy, normal_deg: float, distance: float) -> Pose2D:
    """A robot pose ``distance`` [m] from ``xy`` along ``normal_deg``, facing ``xy`` (test set-up)."""
    a = math.radians(normal_deg)
    p = (xy[0] + distance * math.cos(a), xy[1] + distance * math.sin(a))
    return Pose2D(p[0], p[1], math.atan2(xy[1] - p[1], xy[0] - p[0]))
