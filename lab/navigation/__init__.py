"""Navigation: the stereo costmap, A* with replanning, and a differential-drive path follower.

The object-search paper's Sec. III-D (the costmap ``M_c`` and A*), as a data flow::

    points_W --fit_ground_plane--> GroundPlane --Costmap.integrate--> free / unknown / obstacle cells
      --Costmap.inflated(radius)--> CostGrid --astar / astar_to_region--> PathResult
      --simplify_path--> waypoints --PathFollower / drive_to--> robot.drive(v, omega)
    and after every costmap update: Replanner.update(grid, pose) -> replan if the path ahead is blocked

:class:`~lab.navigation.navigator.Navigator` runs the whole loop on a :class:`lab.robot.Robot` (stereo
frames in, velocity and pan-tilt commands out): ``scan()``, ``go_to(goal)``, ``go_near(target)``; each
request is a :class:`~lab.navigation.drive_loop.DriveLoop` (plan, look, drive and replan, face, report).
Its workspace comes from the world's scene: ``Navigator(robot, bounds=room_bounds(load_scene(name)))``.

Grid geometry and frames follow ``docs/conventions.md`` (world frame W, metres, radians); cell
``(i, j)`` counts along W's x and y axes (:mod:`lab.navigation.grid`).
"""

from lab.navigation.astar import (
    PathResult,
    PathStatus,
    astar,
    astar_cells,
    astar_to_region,
    heading_towards,
)
from lab.navigation.costmap import CellState, CostGrid, Costmap, CostmapConfig, CostmapUpdate
from lab.navigation.drive_loop import NavOutcome, NavResult
from lab.navigation.follower import (
    Command,
    DriveOutcome,
    DriveResult,
    FollowStatus,
    PathFollower,
    StepUpdate,
    drive_to,
)
from lab.navigation.grid import GridSpec, OutsideMap, room_bounds
from lab.navigation.ground import GroundPlane, NoGroundPlane, fit_ground_plane
from lab.navigation.navigator import Navigator, NavigatorConfig, Observation, ScanResult
from lab.navigation.paths import (
    ReplanDecision,
    Replanner,
    first_blocked_index,
    segment_is_clear,
    simplify_path,
)

__all__ = [
    "NavOutcome",
    "NavResult",
    "Navigator",
    "NavigatorConfig",
    "Observation",
    "ScanResult",
    "CellState",
    "Command",
    "CostGrid",
    "Costmap",
    "CostmapConfig",
    "CostmapUpdate",
    "DriveOutcome",
    "DriveResult",
    "FollowStatus",
    "GridSpec",
    "GroundPlane",
    "NoGroundPlane",
    "OutsideMap",
    "PathFollower",
    "PathResult",
    "PathStatus",
    "ReplanDecision",
    "Replanner",
    "StepUpdate",
    "astar",
    "astar_cells",
    "astar_to_region",
    "drive_to",
    "first_blocked_index",
    "fit_ground_plane",
    "heading_towards",
    "room_bounds",
    "segment_is_clear",
    "simplify_path",
]
