r"""The camera levelled against the floor: its mounts' roll and pitch from the ground plane it sees.

A pan-tilt unit 0.5 deg off square on its mast, or a camera 0.5 deg off square on its bracket, tilts
every point the camera places by as much: a found object 1.2 m away sits 1-2 cm too high or too low,
and its horizontal position moves with the view's tilt. A calibration against posters
(:mod:`lab.localization.mount_calibration`) is limited by the posters' survey (a poster 5 cm off along
its normal moves its centre's elevation by 0.3 deg at 3 m, docs/tuning/mount-calibration.md). The floor
is a reference the room gives exactly: the robot stands on it, and dense stereo sees thousands of its
points in every view looking down.

**The model.** The robot stands still and turns its head through ``pans`` x ``tilts`` looking down. In
each view ``k`` the floor's unit normal ``n_C,k`` is fitted in the camera frame (dense stereo, the
navigator's RANSAC ground plane, :func:`~lab.navigation.ground.fit_ground_plane`). Seen through the
head's kinematics with the mounts ``theta`` (:func:`lab.mounts.mounted_G_RC`) it must be the robot's
vertical:

.. math::

    R_{RC}(pan_k, tilt_k;\ \theta)\; n_{C,k} = e_z

with ``theta = (rho_h, pi_h, tau, rho_c, psi_c)``: the head's roll and pitch on the mast, the tilt's
zero (with the camera's pitch on the bracket: one rotation about the tilt axis), the camera's roll and
yaw on the bracket. The residual of a view is the horizontal part of ``R_RC n_C`` (two small angles
[rad]) over ``sigma_view``; each angle has a prior (0, ``prior_deg``), the mounts' stated accuracy.

**What the floor can and cannot tell.**

* The head's roll and pitch tilt the pan axis: the same tilt in R at every pan. The camera's roll and
  the tilt's zero tilt the view in the head's frame: a tilt in R that turns with the pan. Pans all round
  tell them apart.
* The camera's yaw on the bracket is a rotation about the bracket's vertical, which a downward tilt
  leans forward: it shows as a roll of ``sin(tilt)`` times itself, so two tilts tell it from the roll
  (weakly: the prior still counts).
* A yaw about the vertical leaves the floor's normal vertical: the head's yaw on the mast and the pan's
  zero are not estimated (the localizer's heading takes them, as in the poster calibration).
* The camera's own calibration error (its principal point, its focal length) turns the rays it measures
  as a small rotation of the camera would; the levelled mounts absorb it, which is what every later
  view wants.

:func:`level_camera` runs the views on a robot and returns the :class:`~lab.mounts.HeadMounts` it
solved (a search stacks a :class:`~lab.mounts.CalibratedRobot` with them beneath its localizer:
``lab.runs.search``); :func:`solve_level` is the solver alone, for tests and notebooks.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from lab.errors import LabError
from lab.mounts import HeadMounts, mounted_G_RC
from lab.navigation.ground import NoGroundPlane, fit_ground_plane
from lab.vision.dense import dense_points

__all__ = ["FloorView", "Level", "LevelConfig", "floor_normal", "level_camera", "solve_level"]

#: The angles the floor can tell (the names :class:`~lab.mounts.HeadMounts` lists as ``estimated``).
ANGLES = ("head_roll", "head_pitch", "tilt_zero", "camera_roll", "camera_yaw")


@dataclass(frozen=True)
class LevelConfig:
    """The levelling views and the solver's weights.

    Attributes
    ----------
    pans_deg, tilts_deg : tuples of float [deg]
        The head's pattern: every pan at every tilt. Pans all round separate the head's tilt from the
        camera's; two tilts separate the camera's yaw from its roll. The tilts look down far enough that
        the floor fills most of the view and near enough that it is sharp (1-3 m).
    max_depth_m : float [m]
        Stereo points farther than this along the optical axis are left out (their depth error grows
        with the square of the distance).
    pixel_step : int
        Dense points every ``pixel_step`` pixels.
    sigma_view_deg : float [deg]
        One view's normal, as the solver weights it: the fit over thousands of points is good to a few
        hundredths of a degree, but the floor's texture and the disparity's quantisation leave more.
    prior_deg : float [deg]
        The prior standard deviation of every angle: a bracket's 0.5 deg (the mounts' stated accuracy,
        ``[room] camera_mount_deg``), widened so that the floor, not the prior, decides.
    gate_deg : float [deg]
        A view whose floor stays tilted by more than this after a robust first solve is left out (a
        strip of floor between the robot and a wall a metre away, in the corner of a view: 1-2 deg off;
        the others are within 0.15 deg).
    min_views : int
        Fewer views with a floor than this: no levelling (:class:`NotLevelled`).
    settle_s : float [s]
        How long after the head stops each view is taken. A camera's image is older than its frame's
        stamp (a USB camera's 30-100 ms, ``[sensing.room] latency_s``), so a frame taken as the head
        arrives may show it still turning, paired with the arrived angles. The head moves at 60 deg/s,
        so 0.1 s is several degrees of pan or tilt, and the floor's normal tilts with it. The wait covers
        three times the longest such latency and costs a few seconds over the pattern.
    """

    pans_deg: tuple[float, ...] = (-150.0, -100.0, -50.0, 0.0, 50.0, 100.0, 150.0)
    tilts_deg: tuple[float, ...] = (-20.0, -40.0)
    max_depth_m: float = 3.0
    pixel_step: int = 2
    sigma_view_deg: float = 0.1
    prior_deg: float = 1.0
    gate_deg: float = 0.4
    min_views: int = 6
    settle_s: float = 0.3


class NotLevelled(LabError, RuntimeError):
    """Too few views showed the floor to level the camera (the robot stands among walls or furniture)."""


@dataclass(frozen=True)
class FloorView:
    """One view's floor: the head's reported angles and the floor's unit normal in the camera frame C.

    Attributes
    ----------
    pan, tilt : float [rad]
    normal_C : tuple of 3 floats
        Pointing from the floor towards the camera.
    n_inliers : int
    """

    pan: float
    tilt: float
    normal_C: tuple[float, float, float]
    n_inliers: int


@dataclass(frozen=True)
class Level:
    """What :func:`solve_level` found.

    Attributes
    ----------
    mounts : HeadMounts
        The estimated angles (the head's yaw and the pan zero 0), with ``std`` and ``estimated``.
    views : int
        Views used (within the gate).
    rms_deg : float [deg]
        The views' residual root-mean-square after the fit (how level the floor looks now).
    rms_before_deg : float [deg]
        The same with the nominal kinematics (how tilted it looked), over the same views.
    dropped : int
        Views left out: their floor disagreed with the others' by more than ``gate_deg``.
    """

    mounts: HeadMounts
    views: int
    rms_deg: float
    rms_before_deg: float
    dropped: int = 0


def floor_normal(frame, config: LevelConfig | None = None, rng=None) -> FloorView | None:
    """The floor's normal in the camera frame of ``frame`` (a :class:`~lab.robot.StereoFrame`), or None
    when the view shows no floor. The plane is fitted in the robot's frame as the nominal kinematics place
    the points (near-horizontal, near the floor: a table or a wall never wins) and turned back to C,
    where it is what the camera measured whatever the kinematics."""
    cfg = config or LevelConfig()
    P_C = dense_points(
        frame.left, frame.right, frame.camera, step=cfg.pixel_step, max_depth=cfg.max_depth_m, checked=True
    )
    G_RC = frame.G_RC
    P_R = P_C @ G_RC[:3, :3].T + G_RC[:3, 3]
    try:
        plane = fit_ground_plane(P_R, rng if rng is not None else 0)
    except NoGroundPlane:
        return None
    n_C = G_RC[:3, :3].T @ np.asarray(plane.normal)
    p = frame.pan_tilt
    return FloorView(float(p.pan), float(p.tilt), tuple(float(v) for v in n_C), plane.n_inliers)


def _mounts(theta) -> HeadMounts:
    rho_h, pi_h, tau, rho_c, psi_c = (float(v) for v in theta)
    return HeadMounts(head_rpy=(rho_h, pi_h, 0.0), camera_rpy=(rho_c, 0.0, psi_c), tilt_zero=tau)


def _residuals(theta, views: Sequence[FloorView], camera) -> np.ndarray:
    m = _mounts(theta)
    out = []
    for v in views:
        G = mounted_G_RC(
            v.pan, v.tilt, camera.mount_R, camera.camera_offset_P, m.head_rpy, m.camera_rpy, 0.0, m.tilt_zero
        )
        n_R = G[:3, :3] @ np.asarray(v.normal_C)
        out += [n_R[0], n_R[1]]  # the floor's tilt in R: 0 when the kinematics are right
    return np.asarray(out)


def solve_level(views: Sequence[FloorView], camera, config: LevelConfig | None = None) -> Level:
    """The mounts that make every view's floor level (the module's model), by least squares with a
    prior on each angle; the covariance ``(J^T J)^{-1}`` at the solution, scaled by the reduced
    chi-square when it exceeds 1.

    Raises
    ------
    NotLevelled
        Fewer than ``config.min_views`` views.
    """
    cfg = config or LevelConfig()
    if len(views) < cfg.min_views:
        raise NotLevelled(
            f"only {len(views)} views showed the floor, need at least {cfg.min_views} to level the camera"
        )
    s_view, s_prior = math.radians(cfg.sigma_view_deg), math.radians(cfg.prior_deg)

    def f(theta, used):
        return np.concatenate([_residuals(theta, used, camera) / s_view, theta / s_prior])

    # a robust first solve, then the views within the gate solved again by least squares: a view that
    # looks at a wall a metre away sees a strip of floor in its corner, tilted by a degree or two
    x0 = np.zeros(len(ANGLES))
    first = least_squares(f, x0, args=(views,), loss="soft_l1", f_scale=2.0, x_scale=s_prior)
    tilt = np.hypot(*_residuals(first.x, views, camera).reshape(-1, 2).T)
    used = [v for v, e in zip(views, tilt, strict=True) if e <= math.radians(cfg.gate_deg)]
    if len(used) < cfg.min_views:
        raise NotLevelled(
            f"only {len(used)} of {len(views)} views showed a floor that agrees with the others within "
            f"{cfg.gate_deg:g} deg, need at least {cfg.min_views} to level the camera"
        )
    sol = least_squares(f, first.x, args=(used,), method="lm", x_scale=s_prior)
    J = sol.jac
    dof = max(2 * len(used) - len(ANGLES), 1)
    chi2 = float(np.sum(sol.fun[: 2 * len(used)] ** 2)) / dof
    cov = np.linalg.inv(J.T @ J) * max(chi2, 1.0)
    std = np.sqrt(np.diag(cov))
    rms = lambda th: math.degrees(float(np.sqrt(np.mean(_residuals(th, used, camera) ** 2))))  # noqa: E731
    m = _mounts(sol.x)
    sd = {
        "head_rpy": (float(std[0]), float(std[1]), 0.0),
        "camera_rpy": (float(std[3]), 0.0, float(std[4])),
        "tilt_zero": float(std[2]),
        "pan_zero": 0.0,
    }
    mounts = HeadMounts(m.head_rpy, m.camera_rpy, 0.0, m.tilt_zero, sd, ANGLES, "levelled on the floor")
    return Level(mounts, len(used), rms(sol.x), rms(np.zeros(len(ANGLES))), len(views) - len(used))


def level_camera(robot, config: LevelConfig | None = None) -> Level:
    """Turn the standing robot's head through the pattern, fit the floor in every view (taken
    ``config.settle_s`` after the head stopped) and solve (:func:`solve_level`); the head is put back
    where it was. The robot must be enabled; it does not drive.

    Raises
    ------
    NotLevelled
        Too few views showed the floor.
    """
    cfg = config or LevelConfig()
    start = robot.pan_tilt()
    lim = robot.pan_tilt_limits
    timeout = 2.0 * (lim.pan_max - lim.pan_min) / lim.min_speed
    views = []
    robot.stop()
    for i, tilt in enumerate(cfg.tilts_deg):
        for pan in cfg.pans_deg[:: -1 if i % 2 else 1]:  # back and forth: the head's shortest way
            p, t = math.radians(pan), math.radians(tilt)
            if not (lim.pan_min <= p <= lim.pan_max and lim.tilt_min <= t <= lim.tilt_max):
                continue
            robot.command_pan_tilt(p, t)
            robot.wait_pan_tilt(timeout=timeout)
            v = floor_normal(robot.capture_stereo(after=robot.now() + cfg.settle_s), cfg)
            if v is not None:
                views.append(v)
    robot.command_pan_tilt(start.pan, start.tilt)
    robot.wait_pan_tilt(timeout=timeout)
    return solve_level(views, robot.camera, cfg)
