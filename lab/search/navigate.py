"""The search's ``navigate`` on a real navigator: scan once, then drive near each target.

:class:`NavigatorAdapter` turns a :class:`~lab.navigation.navigator.Navigator` into the callable the
:class:`~lab.search.agent.SearchAgent` drives with, ``navigate(target_xy, min_distance, max_distance)
-> NavigationResult``. It keeps its navigator as a public attribute: its costmap is what the figures
draw under the trajectory, and its planning grid is where the report's detour
(:mod:`lab.search.report_policy`) looks for a place to see a landmark from.
"""

from __future__ import annotations

from lab.errors import SafetyStop
from lab.navigation.astar import astar_to_region
from lab.navigation.drive_loop import NavOutcome
from lab.navigation.grid import GridSpec
from lab.navigation.navigator import Navigator, NavigatorConfig
from lab.search.records import NavigationResult

__all__ = ["NavigatorAdapter"]


class NavigatorAdapter:
    """``navigate`` for the search agent: scan once before the first drive, then ``go_near`` each target.

    Parameters
    ----------
    robot : Robot
        The robot the navigator drives (in a search: the budgeted robot).
    spec : GridSpec
        The probability map's grid: the navigator's workspace is the floor it covers (the scene's room).
    timeout_s : float [s]
        Each drive's time limit.
    config : NavigatorConfig, optional
        The navigator's settings (default: the navigator's).

    Attributes
    ----------
    navigator : Navigator
        The navigator it drives with (its costmap is what ``lab search --out`` draws under the
        trajectory; its planning grid is where the report's detour plans).

    Each outcome carries the path A* plans first on the current costmap (``path_xy``, for the figures;
    the navigator replans on the way). A drive that ends in a safety stop (``SAFETY_STOP``: a cliff or a
    wheel drop; the robot is disarmed) raises :class:`~lab.errors.SafetyStop`, which ends the search with
    that fault.
    """

    def __init__(
        self, robot, spec: GridSpec, timeout_s: float = 120.0, config: NavigatorConfig | None = None
    ):
        x0, x1, y0, y1 = (round(v, 9) for v in spec.extent)  # 30 x 0.2 m is 6.000000000000001 m
        self.robot = robot
        self.timeout_s = timeout_s
        self.navigator = Navigator(robot, config=config, bounds=(x0, y0, x1, y1))
        self.scanned = False

    def __call__(self, target_xy, min_distance: float, max_distance: float) -> NavigationResult:
        """Drive to within ``[min_distance, max_distance]`` [m] of ``target_xy`` [m] and face it (after
        the one scan, on the first call)."""
        nav = self.navigator
        if not self.scanned:
            nav.scan()
            self.scanned = True
        first = astar_to_region(
            nav.planning_grid(), self.robot.odometry(), target_xy, max_distance, min_distance
        )
        r = nav.go_near(target_xy, min_distance, max_distance, timeout=self.timeout_s)
        if r.outcome is NavOutcome.SAFETY_STOP:
            # the robot stopped itself (cliff, wheel drop) and stays disarmed: the search cannot go on; the
            # agent ends the run with this fault (without this, each next target failed at once)
            raise SafetyStop(r.reason or r.outcome.value)
        arrived = r.outcome is NavOutcome.ARRIVED
        path = first.points_xy if first.found else None
        reason = r.outcome.name if r.reason is None else r.reason
        if r.outcome is NavOutcome.POSE_UNCERTAIN:
            reason = f"{r.outcome.name}: {r.reason}"  # what RelocalizingNavigate re-localizes on
        return NavigationResult(arrived, reason, r.pose, path)
