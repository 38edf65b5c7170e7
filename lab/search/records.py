"""What the search loop (:class:`lab.search.agent.SearchAgent`) records and what its navigation returns.

**Navigation** is any callable ``navigate(target_xy, min_distance, max_distance)`` (:class:`Navigate`)
that drives the robot to a pose whose distance to ``target_xy`` [m] is within the band, facing it, and
returns an object with ``arrived`` (bool), ``reason`` (str) and ``pose`` (:class:`~lab.geometry.Pose2D`),
like :class:`NavigationResult` (an optional ``path_xy`` is kept for the figures). It must bound its own
run time. (Not :class:`lab.navigation.NavOutcome`, the navigator's enum of how a request ended.)
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Protocol

import numpy as np

from lab.geometry import Pose2D

if TYPE_CHECKING:
    from lab.search.global_search import GlobalSearchResult
    from lab.search.local_search import LocalSearchResult
    from lab.search.world_pose import WorldPoseStd

__all__ = ["AgentResult", "MapSnapshot", "NavigationResult", "Navigate", "SearchEvent"]


@dataclass(frozen=True)
class NavigationResult:
    """What the agent's ``navigate`` call reports (any object with these attributes will do).

    Attributes
    ----------
    arrived : bool
        The robot stands within the distance band of the target, facing it.
    reason : str
        Why not, or how it went.
    pose : Pose2D
        The odometry pose at the end.
    path_xy : ndarray, shape (k, 2) [m] or None
        The (first) planned path, for the figures.
    """

    arrived: bool
    reason: str
    pose: Pose2D
    path_xy: np.ndarray | None = field(default=None, repr=False)


class Navigate(Protocol):
    """``navigate(target_xy, min_distance, max_distance)``: drive to within the distance band [m] of
    ``target_xy`` [m], facing it; returns a :class:`NavigationResult`-like object (module docstring)."""

    def __call__(self, target_xy: tuple[float, float], min_distance: float, max_distance: float): ...


@dataclass(frozen=True)
class MapSnapshot:
    """The probability map at time ``t`` [s], after ``label`` (e.g. a failed local search of ``cell``)."""

    t: float
    P: np.ndarray = field(repr=False)
    label: str = ""
    cell: tuple[int, int] | None = None
    pose: Pose2D | None = None


@dataclass(frozen=True)
class SearchEvent:
    """One step of the run, for the record: ``kind`` is global / navigate / skip / local / track / end
    (track: a colour track followed and given up, :mod:`lab.search.follow`)."""

    t: float
    kind: str
    cell: tuple[int, int] | None = None
    detail: str = ""

    def as_dict(self) -> dict:
        return {
            "t": round(self.t, 3),
            "kind": self.kind,
            "cell": None if self.cell is None else list(self.cell),
            "detail": self.detail,
        }


@dataclass(frozen=True)
class AgentResult:
    """How a run of :class:`SearchAgent` ended, and its record.

    Attributes
    ----------
    found : bool
    reason : str
        Why the run ended.
    G_WO : ndarray, shape (4, 4) or None
        The found object's pose in the world (odometry) frame.
    local : LocalSearchResult or None
        The successful local search.
    global_searches, local_searches : int
    events : tuple of SearchEvent
    snapshots : tuple of MapSnapshot
        After each global search and each failed local search.
    globals_ : tuple of GlobalSearchResult
    nav_paths : tuple of (target_xy, path_xy or None)
    P_final : ndarray
    t_start, t_end : float [s] (robot clock)
    pose_std : WorldPoseStd or None
        How well the robot says it knows ``G_WO`` in the world (:mod:`lab.search.world_pose`): the
        object in the camera, the camera on the robot and the robot's pose; set when the find is
        reported (:meth:`lab.search.report_policy.ReportPolicy.report`).
    """

    found: bool
    reason: str
    G_WO: np.ndarray | None = field(default=None, repr=False)
    local: LocalSearchResult | None = field(default=None, repr=False)
    global_searches: int = 0
    local_searches: int = 0
    events: tuple[SearchEvent, ...] = field(default=(), repr=False)
    snapshots: tuple[MapSnapshot, ...] = field(default=(), repr=False)
    globals_: tuple[GlobalSearchResult, ...] = field(default=(), repr=False)
    nav_paths: tuple = field(default=(), repr=False)
    P_final: np.ndarray | None = field(default=None, repr=False)
    t_start: float = 0.0
    t_end: float = 0.0
    pose_std: WorldPoseStd | None = field(default=None, repr=False)
