"""When the search re-localizes its robot: before every drive, and before it reports a found object.

A search on a localized robot (:class:`~lab.localization.LocalizedRobot`) looks for
landmarks at two moments, and :class:`ReportPolicy` decides both:

* **before every drive** (:meth:`ReportPolicy.relocalize_before_drive`): when the pose is uncertain the
  robot looks for a landmark first, so the drive starts from a pose it can trust. The agent gets this as
  its ``navigate`` (:meth:`ReportPolicy.relocalizing`, a :class:`RelocalizingNavigate` round the search's
  own navigate), which also stops a drive whose pose has drifted too far to map on (the navigator's
  pose guard, :meth:`LocalizedRobot.drive_guard`), re-localizes and drives on;
* **before a find is reported** (:meth:`ReportPolicy.report`): the object's world pose is only as good
  as the robot's pose when it was found, so the robot re-localizes to the report's tighter thresholds
  at the object's point, and when no landmark is seen well from there it makes a detour to one
  (:meth:`ReportPolicy.detour`) while the filter keeps the pose the object was found from.

The policy works on the robot through the localized robot's interface (``relocalize``,
``relocalize_to_report``, ``pose_estimate``, ``localizer``, ``mode``, ``config``,
``landmark_vantage_points``, ``log``, ``stop``, ``now``): a wrapper that passes those on (the run's
tracked robot) will do. The time budget is a callable ``check()`` that raises
:class:`~lab.search.budget.SearchBudgetExceeded` once it is used up (:meth:`BudgetedRobot.check
<lab.search.budget.BudgetedRobot.check>`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from lab.errors import SafetyStop
from lab.geometry import Pose2D, se3_inv
from lab.localization import LocalizationMode, PlanarPoseEstimate
from lab.navigation.drive_loop import NavOutcome
from lab.search.budget import SearchBudgetExceeded
from lab.search.records import AgentResult, NavigationResult
from lab.search.world_pose import rest_on_face, world_pose_covariance, world_pose_std_of

__all__ = ["POSE_UNCERTAIN", "RelocalizingNavigate", "ReportPolicy", "stated_pose_std", "unlimited"]

#: The start of a drive's reason when the navigator's pose guard stopped it (its NavOutcome's name).
POSE_UNCERTAIN = NavOutcome.POSE_UNCERTAIN.name


def unlimited() -> None:
    """A budget check that never stops the run (no time budget)."""


class RelocalizingNavigate:
    """The search's ``navigate`` with an active re-localization before every drive
    (:meth:`ReportPolicy.relocalize_before_drive`): the same call, ``navigate(target_xy, min_distance,
    max_distance) -> NavigationResult``.

    During the drive the navigator's pose guard (:attr:`Navigator.pose_guard
    <lab.navigation.navigator.Navigator.pose_guard>`) is the robot's :meth:`LocalizedRobot.drive_guard`:
    when the pose's deviation passes ``LocalizerConfig.drive_sigma_*`` the drive stops before mapping
    another frame, the robot re-localizes where it stands and drives on to the same target, at most
    ``max_drive_stops`` times. A stop the re-localization cannot help (no landmark in view brought the
    pose back within those thresholds) drives on unguarded: standing still would not find one either.
    The agent sees one drive and its result.

    Attributes
    ----------
    navigate : callable
        The navigate it drives with.
    policy : ReportPolicy
    max_drive_stops : int
        Re-localizations within one drive at most (then the drive goes on unguarded).
    """

    def __init__(
        self, navigate: Callable[..., NavigationResult], policy: ReportPolicy, max_drive_stops: int = 3
    ):
        self.navigate = navigate
        self.policy = policy
        self.max_drive_stops = int(max_drive_stops)

    @property
    def navigator(self):
        """The policy's :class:`~lab.navigation.navigator.Navigator` (None without one): whose costmap
        the figures and the live view draw."""
        return self.policy.navigator

    def __call__(self, *args, **kwargs) -> NavigationResult:
        policy, nav = self.policy, self.policy.navigator  # a guard implies a navigator
        stops = 0
        while True:
            policy.relocalize_before_drive()
            guard = policy.drive_guard() if stops < self.max_drive_stops else None
            if guard is None:
                return self.navigate(*args, **kwargs)
            nav.pose_guard = guard
            try:
                r = self.navigate(*args, **kwargs)
            finally:
                nav.pose_guard = None
            if not r.reason.startswith(POSE_UNCERTAIN):
                return r
            stops += 1
            policy.robot.log(f"localization: drive stopped to re-localize ({r.reason})")


class ReportPolicy:
    """When the search re-localizes (see the module docstring): before every drive, and before a find is
    reported, with a detour to a landmark when none is seen well from where the object was found.

    Parameters
    ----------
    robot : LocalizedRobot or a wrapper that passes its interface on
        The localized robot beneath the time budget (its views step it directly).
    navigate : callable, optional
        The search's ``navigate(target_xy, min_distance, max_distance) -> NavigationResult`` (on the
        budgeted robot): what :meth:`relocalizing` wraps and what the detour drives with. None: no
        detour.
    navigator : Navigator, optional
        The navigator behind ``navigate`` (:attr:`NavigatorAdapter.navigator
        <lab.search.navigate.NavigatorAdapter.navigator>`): the detour plans on its planning grid.
        None: no detour.
    check : callable () -> None
        The time budget's check (:meth:`BudgetedRobot.check <lab.search.budget.BudgetedRobot.check>`);
        default: :func:`unlimited`.
    rests_on_face : bool
        The searched object is a box resting on a face of a level surface (the floor, a table, a shelf):
        the reported pose is conditioned on it (:func:`lab.search.world_pose.rest_on_face`). False: the
        pose as the local search estimated it.
    """

    def __init__(
        self,
        robot,
        navigate: Callable[..., NavigationResult] | None = None,
        navigator=None,
        check: Callable[[], None] = unlimited,
        rests_on_face: bool = True,
    ):
        self.robot = robot
        self.navigate = navigate
        self.navigator = navigator
        self.check = check
        self.rests_on_face = bool(rests_on_face)

    def relocalizing(self) -> RelocalizingNavigate:
        """The agent's ``navigate``: this policy's ``navigate`` with a re-localization before every drive."""
        return RelocalizingNavigate(self.navigate, self)

    def drive_guard(self) -> Callable[[], str | None] | None:
        """The navigator's pose guard for the next drive (:meth:`LocalizedRobot.drive_guard`), or None:
        no navigator, not localized against landmarks, or the pose already past the drive's thresholds
        (no landmark in view made it better, so stopping again would not either)."""
        robot = self.robot
        if self.navigator is None or getattr(robot, "mode", None) is not LocalizationMode.LANDMARKS:
            return None  # (a scripted robot in a test has no mode)
        if robot.drive_guard() is not None:
            return None
        return robot.drive_guard

    def relocalize_before_drive(self) -> None:
        """Active re-localization before a drive: when the pose is uncertain, look for a landmark first.

        Its views step the robot beneath the budget wrapper, which cannot stop them, so the budget is
        checked before and after: a run whose drives all failed at once (an unreachable cell each)
        looked round for 20 s before each and ran on to 768 s of a 300 s budget."""
        self.check()
        self.robot.relocalize()
        self.check()

    def report(self, out: AgentResult) -> tuple[AgentResult, dict | None]:
        """Active re-localization before reporting a found object, to the report's tighter thresholds at
        the object (:meth:`LocalizedRobot.relocalize_to_report`): the object's pose relative to the robot
        stays; its world pose follows the corrected robot pose ``G_WO' = G_WR' G_WR^-1 G_WO``.

        When no landmark from where the robot stands gets the object's point within ``report_sigma_m``
        (and ``report_detour_above_m``) and there is a ``navigate`` to drive with, a detour
        (:meth:`detour`): the pose the object was found from is kept in the filter while the robot drives
        to a landmark, and ``G_WR'`` is that kept pose as the landmark corrected it.

        Returns the result to report and what was done, for the JSON's ``report_relocalization`` (None
        when nothing was reported: not found, or not localized against landmarks): the landmark updates
        it made, the object point's position standard deviation before and after, how far the reported
        object moved, and the detour (None: none was needed or possible).

        The result carries the reported pose's stated deviation in the world (:func:`stated_pose_std`)
        with the robot's covariance as reported (on odometry alone: dead reckoning's), and with
        ``rests_on_face`` the pose and its deviation conditioned on the box resting on a face."""
        robot = self.robot
        if not out.found or out.G_WO is None:
            return out, None
        if robot.mode is not LocalizationMode.LANDMARKS:
            return stated_pose_std(out, robot.pose_estimate().Sigma, robot.camera, self.rests_on_face), None
        p_W = out.G_WO[:2, 3].copy()
        est0 = robot.camera_pose_estimate()  # the camera's: the object was placed from it
        robot.relocalize_to_report(at_W=p_W)
        est1 = robot.camera_pose_estimate()
        G_WR, sigma, detour, Sigma_R = est1.pose.G(), est1.point_sigma_m(p_W), None, est1.Sigma
        cfg = robot.config
        wanted = sigma > max(cfg.report_sigma_m, cfg.report_detour_above_m)
        if wanted and self.navigate is not None and cfg.report_detour_m > 0:
            kept, detour = self.detour()
            if kept is not None:
                G_WR, sigma, Sigma_R = kept.pose.G(), kept.point_sigma_m(p_W), kept.Sigma
        G_WO = G_WR @ se3_inv(est0.pose.G()) @ out.G_WO
        info = {
            "updates": int(robot.pose_estimate().n_updates - est0.n_updates),
            "point_sigma_before_m": round(est0.point_sigma_m(p_W), 4),
            "point_sigma_after_m": round(sigma, 4),
            "within_report_sigma": bool(sigma <= cfg.report_sigma_m),
            "shift_m": round(float(np.linalg.norm(G_WO[:3, 3] - out.G_WO[:3, 3])), 4),
            "detour": detour,
        }
        yaw_in_pose = robot.localizer.camera_yaw is not None  # Sigma_R is the camera's pose (est1, kept)
        out = stated_pose_std(replace(out, G_WO=G_WO), Sigma_R, robot.camera, self.rests_on_face, yaw_in_pose)
        return out, info

    def detour(self) -> tuple[PlanarPoseEstimate | None, dict | None]:
        """Keep the robot's pose in the filter (:meth:`Localizer.start_clone`), drive to the nearest place
        from which a landmark is seen well (:meth:`LocalizedRobot.landmark_vantage_points`, on the
        navigator's planning grid; the next one if a drive fails, two tries), re-localize there to the
        report's thresholds, and return the kept pose as corrected (None when it could not be kept) and
        what was done, for the JSON: the place, its landmark, whether the robot got there and the updates
        there (None: no navigator to plan on, or the filter has not placed the robot yet).

        The time budget holds: a drive that runs it out ends the detour with what the filter has then."""
        robot, navigate = self.robot, self.navigate
        loc = robot.localizer
        nav = self.navigator
        if nav is None or loc.first_sighting_pending:
            return None, None
        grid = nav.planning_grid()
        spec = grid.spec

        def free(x, y):
            if not spec.contains_xy(x, y):
                return False
            i, j = spec.world_to_cell(x, y)
            return not grid.blocked[i, j]

        spots = robot.landmark_vantage_points(free)
        info = {"to": None, "landmark": None, "arrived": False, "updates": 0, "stopped": None}
        if not spots:
            return None, {**info, "stopped": "no place within reach sees a landmark well"}
        est = robot.pose_estimate()
        n0 = est.n_updates
        loc.start_clone()
        try:
            for x, y, name in spots[:2]:
                info.update(to=[round(float(x), 3), round(float(y), 3)], landmark=name)
                robot.log(
                    f"localization: no landmark seen well where the object was found; a detour of "
                    f"{math.hypot(x - est.pose.x, y - est.pose.y):.1f} m to see {name}"
                )
                if navigate((x, y), 0.0, 0.2).arrived:
                    info["arrived"] = True
                    robot.relocalize_to_report()
                    break
        except (SearchBudgetExceeded, SafetyStop) as e:
            robot.stop()
            info["stopped"] = str(e)
        finally:
            x_c, S_c = loc.end_clone(camera=True)  # the camera's pose then: the object was placed from it
        info["updates"] = int(robot.pose_estimate().n_updates - n0)
        kept = PlanarPoseEstimate(
            Pose2D(*(float(v) for v in x_c)), S_c, robot.now(), LocalizationMode.LANDMARKS
        )
        return kept, info


def stated_pose_std(
    out: AgentResult, Sigma_R, camera, rests_on_face: bool = False, yaw_in_pose: bool = False
) -> AgentResult:
    """``out`` with its ``pose_std``: how well the robot knows the found ``G_WO`` in the world
    (:func:`lab.search.world_pose.world_pose_covariance`) from the local search's estimate in the camera,
    the camera's stated pointing accuracy on the robot (``camera.pointing_std_deg``: the pan-tilt's zero
    and the mounts) and the robot's pose covariance ``Sigma_R`` (3, 3); unchanged without a found track.

    With ``rests_on_face`` the pose and the covariance are conditioned on the box resting on one of its
    faces (:func:`lab.search.world_pose.rest_on_face`): ``G_WO`` is the upright pose, ``pose_std`` the
    conditioned deviation. ``yaw_in_pose``: ``Sigma_R`` is the camera's pose, its heading carrying the
    camera's yaw on the robot (:meth:`LocalizedRobot.camera_pose_estimate`), so the stated pointing's
    part about the vertical is not added again."""
    loc = out.local
    if out.G_WO is None or loc is None or loc.estimate is None or loc.frame is None:
        return out
    G_RC, G_CO, Sigma_o = loc.frame.G_RC, loc.estimate.G_CO, loc.estimate.Sigma_rv
    G_WR = out.G_WO @ se3_inv(G_RC @ G_CO)  # the robot pose the reported G_WO rests on
    pointing = math.radians(camera.pointing_std_deg)
    S = world_pose_covariance(G_WR, Sigma_R, G_RC, pointing, G_CO, Sigma_o, yaw_in_pose)
    G_WO = out.G_WO
    if rests_on_face:
        G_WO, S = rest_on_face(G_WO, S)
    return replace(out, G_WO=G_WO, pose_std=world_pose_std_of(S, Sigma_o))
