"""The search's navigation: the stereo-costmap :class:`~lab.navigation.Navigator` behind the agent's
``navigate(target_xy, min_distance, max_distance)`` callable (see :mod:`lab.search.agent`)."""

from __future__ import annotations

from lab.navigation.navigator import Navigator
from lab.navigation.navigator import NavOutcome as _Outcome
from lab.search.agent import NavOutcome

__all__ = ["navigator_factory"]


def navigator_factory(robot, spec, timeout_s: float = 120.0):
    """``navigate`` for :func:`lab.search.trial.run_search`: scan once, then ``go_near`` each target.

    The returned callable carries its :class:`~lab.navigation.Navigator` as ``navigate.navigator``, so
    that a caller can show the costmap it built (e.g. :func:`lab.search.figures.fig5_trial`).
    """
    nav = Navigator(robot)
    state = {"scanned": False}

    def navigate(target_xy, min_distance: float, max_distance: float) -> NavOutcome:
        if not state["scanned"]:
            nav.scan()
            state["scanned"] = True
        r = nav.go_near(target_xy, min_distance, max_distance, timeout=timeout_s)
        arrived = r.outcome is _Outcome.ARRIVED
        return NavOutcome(arrived, r.reason or r.outcome.name, r.pose)

    navigate.navigator = nav
    return navigate
