"""The search's navigation: the stereo-costmap :class:`~lab.navigation.Navigator` behind the agent's
``navigate(target_xy, min_distance, max_distance)`` callable (see :mod:`lab.search.agent`)."""

from __future__ import annotations

from lab.navigation.astar import astar_to_region
from lab.navigation.drive_loop import NavOutcome
from lab.navigation.grid import room_bounds
from lab.navigation.navigator import Navigator
from lab.scene import load_scene
from lab.search.agent import NavigationResult

__all__ = ["navigator_factory"]


def navigator_factory(robot, spec, timeout_s: float = 120.0):
    """``navigate`` for :func:`lab.search.trial.run_search`: scan once, then ``go_near`` each target.

    The returned callable keeps its :class:`~lab.navigation.Navigator` as ``navigate.navigator`` (its
    costmap is what ``lab search --out`` draws under the trajectory). Each outcome carries the path A*
    plans first on the current costmap (``path_xy``, for the figures; the navigator replans on the way).
    """
    nav = Navigator(robot, bounds=room_bounds(load_scene("lab_room")))
    state = {"scanned": False}

    def navigate(target_xy, min_distance: float, max_distance: float) -> NavigationResult:
        if not state["scanned"]:
            nav.scan()
            state["scanned"] = True
        first = astar_to_region(nav.planning_grid(), robot.odometry(), target_xy, max_distance, min_distance)
        r = nav.go_near(target_xy, min_distance, max_distance, timeout=timeout_s)
        arrived = r.outcome is NavOutcome.ARRIVED
        path = first.points_xy if first.found else None
        return NavigationResult(arrived, r.reason or r.outcome.name, r.pose, path)

    navigate.navigator = nav
    return navigate
