r"""The fine local search of the search paper (Sec. III-C): 9 pan-tilt views, SIFT + EKF, 6D pose.

The robot stands facing a probability-map cell at local-search range. The head visits 9 predefined
pan-tilt configurations that cover the viewing hemisphere in front of it (:func:`local_views`). In each:

1. stereo 3D SIFT features ``D_k`` (:func:`lab.vision.stereo_features`) are matched against the object's
   database ``B`` by Best-Bin-First (:class:`lab.vision.Matcher`);
2. with at least ``min_matches`` matches, a fresh pose EKF (:class:`lab.estimation.PoseEKF`, the
   rotation-vector chart) is initialised from them by RANSAC;
3. a start with at least ``min_inliers`` inliers is a *candidate*: the head turns to put the estimated
   object centre in the middle of the image and the track is refined over ``refine_frames`` frames.
   Each frame's SIFT is restricted to a region of interest around the object projected at the
   predicted pose (the paper: "limited to a region of interest ... once the object track has been
   initialized"), the EKF predicts the head's motion (Eqs. (1)-(2) with the static object of the
   search paper's Eq. (4)) and updates with the matches that pass its geometric feasibility gate
   (each matched feature must lie near where the predicted pose puts its database feature).

**Found** (our criterion; the paper's "minimum number of observed SIFT matches and the covariance of
object pose"): a RANSAC start with at least ``min_inliers`` inliers, then over the refinement at least
``confirm_updates`` EKF updates that each kept ``confirm_matches`` matches through the gate, a healthy
(not diverged) filter, and a small pose covariance: the largest position standard deviation at most
``max_position_std_m`` and the largest rotation standard deviation (over a small rotation vector) at
most ``max_rotation_std_deg``. Otherwise the next view is tried.

The object's world pose is the odometry pose composed with the camera on the head and the estimate,

.. math:: G_{WO} = G_{WR}(\text{odometry})\; G_{RC}(\text{pan}, \text{tilt})\; G_{CO},

and when no view finds it, the caller updates the searched cell as a negative detection with the
local search's constant ``alpha`` and ``beta`` (:class:`LocalSearchConfig`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from lab.errors import ConfigError
from lab.estimation import (
    CalibrationUncertainty,
    EKFConfig,
    ModelUncertainty,
    OrientationChart,
    PoseEKF,
    PoseEstimate,
    ProcessNoise,
)
from lab.geometry import transform_points, wrap_angle
from lab.robot import Robot, StereoCamera, StereoFrame, frame_motion
from lab.search.pose_check import PoseCheckConfig, check_pose
from lab.vision.database import FeatureDatabase
from lab.vision.matching import Matcher
from lab.vision.roi import object_roi
from lab.vision.stereo import sift, stereo_features

__all__ = [
    "LocalSearchConfig",
    "LocalSearchResult",
    "ViewRecord",
    "aim_at",
    "local_search",
    "local_views",
    "make_matcher",
    "object_roi",
]


@dataclass(frozen=True)
class LocalSearchConfig:
    """Settings of the local search.

    Attributes
    ----------
    pans_deg : tuple of float
        Pans relative to the bearing of the searched cell. With the 75 degree horizontal field of
        view, -60, 0 and +60 cover 195 degrees: the hemisphere in front.
    tilts_deg : tuple of float
        With the 60 degree vertical field of view, -35, 0 and +31 (the unit's limit) cover -65 to +61
        degrees of elevation: from 0.6 to 0.9 m away and a camera 1.1 m high (the lab room's mast),
        the floor (50-60 degrees down), a table top (0.75 m, 10-30 degrees down) and a shelf top
        (1.2 m, about level); with a 0.7 m mast, the shelf from 30-40 degrees below.
    min_distance_m, max_distance_m : float [m]
        The local-search range: the band around the cell's centre the robot is sent to. Close, because
        the objects are small (8-20 cm faces) at 320 x 240: at 0.6-0.9 m a face spans 40-100 px; from
        1.1 m on, the matches on floor and shelf objects fell below what a start needs.
    min_matches : int
        Matches a view needs before a RANSAC start is tried.
    min_inliers : int
        RANSAC inliers a start needs to become a candidate.
    refine_frames : int
        Frames of refinement after centring the object.
    confirm_updates, confirm_matches : int
        "Found" needs at least ``confirm_updates`` refinement updates that each used at least
        ``confirm_matches`` gated matches.
    dither_deg : float [deg]
        Head offset between refinement frames (see :func:`_refine`).
    max_position_std_m : float [m]
    max_rotation_std_deg : float [deg]
        "Small covariance": bounds on the largest position and rotation standard deviations.
    roi_margin_px : int [px]
        Margin around the projected object's bounding box for the ROI.
    alpha, beta : float
        The constant detection errors of Eq. (2) for the negative update after a failed search
        (false alarm and missed detection at close range).
    neighbour_radius_m : float [m]
        A failed search is a negative detection of the searched cell *and* of every cell whose centre
        lies within this distance of it (one Bayes update per cell): the 9 views look at the searched
        cell's neighbours as closely as at the cell. The default is the reach of the strongest colour
        peak's growing beta (``lambda ln((1 - alpha) / beta_min)`` = 0.45 m, see the probability map).
        0 is the paper's update of the one cell, which sends the robot on to each of the neighbours
        that the global search's growing beta raised with the peak (the paper's Fig. 6 shows such a
        revisit).
    process : ProcessNoise
        The EKF's static-object process noise (Eq. (4): ``X_k = X_{k-1} + eta``).
    pose_check : PoseCheckConfig or None
        The last check before "found": the pose must explain enough of the database features it
        predicts in view (:mod:`lab.search.pose_check`); None skips it.
    """

    pans_deg: tuple[float, ...] = (0.0, 60.0, -60.0)
    tilts_deg: tuple[float, ...] = (0.0, -35.0, 31.0)
    min_distance_m: float = 0.6
    max_distance_m: float = 0.9
    min_matches: int = 6
    min_inliers: int = 5
    refine_frames: int = 4
    confirm_updates: int = 2
    confirm_matches: int = 5
    dither_deg: float = 2.0
    max_position_std_m: float = 0.01
    max_rotation_std_deg: float = 3.0
    roi_margin_px: int = 20
    alpha: float = 0.05
    beta: float = 0.1
    neighbour_radius_m: float = 0.45
    process: ProcessNoise = field(
        default_factory=lambda: ProcessNoise(sigma_v=0.0, sigma_w=0.0, eta_m=2e-3, eta_rad=5e-3)
    )
    pose_check: PoseCheckConfig | None = field(default_factory=PoseCheckConfig)

    def __post_init__(self):
        if len(self.pans_deg) * len(self.tilts_deg) < 1:
            raise ConfigError("the local search needs at least one view")
        if not 0 < self.min_distance_m <= self.max_distance_m:
            raise ConfigError(
                f"need 0 < min_distance_m <= max_distance_m, got {self.min_distance_m}, {self.max_distance_m}"
            )
        if self.min_matches < 4 or self.min_inliers < 4:
            raise ConfigError("min_matches and min_inliers must be >= 4 (a RANSAC start needs 4)")
        if self.refine_frames < 1:
            raise ConfigError(f"refine_frames must be >= 1, got {self.refine_frames}")


@dataclass(frozen=True)
class ViewRecord:
    """What one view of the local search saw."""

    pan: float
    tilt: float
    t: float
    n_features: int
    n_matched: int
    n_inliers: int
    outcome: str


@dataclass(frozen=True)
class LocalSearchResult:
    """The outcome of one local search.

    Attributes
    ----------
    found : bool
    reason : str
        Why it was (not) found, in words.
    G_WO : ndarray, shape (4, 4) or None
        The object's estimated pose in the world (odometry) frame.
    estimate : PoseEstimate or None
        The EKF's last estimate of ``G_CO`` (in the last frame's camera frame).
    frame : StereoFrame or None
        The last frame of the track (for the figure of the pose drawn on the image).
    n_inliers : int
        Matches used by the last update of the track.
    position_std_m, rotation_std_deg : float or None
    views : tuple of ViewRecord
    t_start, t_end : float [s]
    """

    found: bool
    reason: str
    G_WO: np.ndarray | None = field(default=None, repr=False)
    estimate: PoseEstimate | None = field(default=None, repr=False)
    frame: StereoFrame | None = field(default=None, repr=False)
    n_inliers: int = 0
    position_std_m: float | None = None
    rotation_std_deg: float | None = None
    views: tuple[ViewRecord, ...] = field(default=(), repr=False)
    t_start: float = 0.0
    t_end: float = 0.0


def local_views(config: LocalSearchConfig, bearing: float = 0.0, limits=None) -> list[tuple[float, float]]:
    """The predefined ``(pan, tilt)`` [rad] views, pans relative to ``bearing`` [rad] (the direction of
    the searched cell in the robot frame), clamped to the ``limits``.

    Column by column in a serpentine: the first pan (straight at the cell) at every tilt first, since
    the object is most likely there, then the next pan with the tilts in reverse, and so on.
    """
    out = []
    for k, pan in enumerate(config.pans_deg):
        tilts = config.tilts_deg if k % 2 == 0 else tuple(reversed(config.tilts_deg))
        for tilt in tilts:
            p, t = wrap_angle(bearing + math.radians(pan)), math.radians(tilt)
            if limits is not None:
                p = min(max(p, limits.pan_min), limits.pan_max)
                t = min(max(t, limits.tilt_min), limits.tilt_max)
            out.append((p, t))
    return out


def aim_at(p_R: np.ndarray, camera: StereoCamera, limits=None) -> tuple[float, float]:
    """Pan and tilt [rad] that point the head at the point ``p_R`` (robot frame), clamped to ``limits``."""
    m = camera.mount_R
    dx, dy, dz = p_R[0] - m[0], p_R[1] - m[1], p_R[2] - m[2]
    pan, tilt = math.atan2(dy, dx), math.atan2(dz, math.hypot(dx, dy))
    if limits is not None:
        pan = min(max(pan, limits.pan_min), limits.pan_max)
        tilt = min(max(tilt, limits.tilt_min), limits.tilt_max)
    return pan, tilt


#: Database features closer than this [m] in the object frame are one physical point for the ratio
#: test (:class:`lab.vision.Matcher`'s ``alias_radius``): the search's several training rings see a
#: point from directions far apart, with descriptors too different to merge.
ALIAS_RADIUS_M = 0.015


def make_matcher(db: FeatureDatabase) -> Matcher:
    """The database's matcher: FLANN, or exact search for a tiny database (OpenCV's KD-tree asserts
    when asked for about as many neighbours as the database holds: the glossy cup has 7 features);
    with spatial aliases (:data:`ALIAS_RADIUS_M`)."""
    return Matcher(db, method="flann" if len(db) >= 64 else "brute", alias_radius=ALIAS_RADIUS_M)


def _stds(ekf: PoseEKF) -> tuple[float, float]:
    S = ekf.object_estimate.Sigma_rv  # with the database's own error: where the object is
    pos = math.sqrt(max(0.0, float(np.linalg.eigvalsh(S[:3, :3])[-1])))
    rot = math.degrees(math.sqrt(max(0.0, float(np.linalg.eigvalsh(S[3:, 3:])[-1]))))
    return pos, rot


def local_search(
    robot: Robot,
    db: FeatureDatabase,
    target_xy,
    rng: np.random.Generator,
    config: LocalSearchConfig | None = None,
    matcher: Matcher | None = None,
) -> LocalSearchResult:
    """Look for the object from where the robot stands, facing (roughly) ``target_xy`` [m] (world).

    Parameters
    ----------
    robot : Robot
        Enabled and standing still; only the head moves.
    db : FeatureDatabase
        The object's database.
    target_xy : (x, y) [m]
        The searched cell's centre, in the world (odometry) frame: the views are centred on its bearing.
    rng : numpy.random.Generator
        Seeds the RANSAC starts.
    config : LocalSearchConfig, optional
    matcher : Matcher, optional
        Reuse a matcher (its index is built once per database).

    Returns
    -------
    LocalSearchResult
    """
    cfg = config or LocalSearchConfig()
    return _LocalSearch(robot, db, rng, cfg, matcher or make_matcher(db)).run(target_xy)


class _LocalSearch:
    """One :func:`local_search`: the views in turn, each matched, started by RANSAC and tracked, until
    one finds the object; it keeps a record of every view and the reason of the one that came closest
    (the most RANSAC inliers; a refined track beats a start)."""

    def __init__(self, robot: Robot, db: FeatureDatabase, rng, cfg: LocalSearchConfig, matcher: Matcher):
        self.robot, self.db, self.rng, self.cfg, self.matcher = robot, db, rng, cfg, matcher
        self.detector = sift()
        self.ekf_cfg = EKFConfig(
            chart=OrientationChart.ROTATION_VECTOR,
            process=cfg.process,
            calibration=CalibrationUncertainty.of_camera(robot.camera),  # shared by a frame's features
            model=ModelUncertainty(db.point_std_m),  # the database's own error, shared by all frames
        )
        self.records: list[ViewRecord] = []
        self.best_reason, self.best_rank = "no view had enough matches", (-1, -1)

    def run(self, target_xy) -> LocalSearchResult:
        """Search the views centred on the bearing of ``target_xy`` [m] (world) from the robot."""
        robot = self.robot
        t_start = robot.now()
        odom = robot.odometry()
        bearing = wrap_angle(math.atan2(target_xy[1] - odom.y, target_xy[0] - odom.x) - odom.theta)
        for pan, tilt in local_views(self.cfg, bearing, robot.pan_tilt_limits):
            track = self._search_view(pan, tilt)
            if track is not None and track.found:
                return self._found(track, t_start)
        return LocalSearchResult(
            False,
            f"not found in {len(self.records)} views: {self.best_reason}",
            views=tuple(self.records),
            t_start=t_start,
            t_end=robot.now(),
        )

    def _search_view(self, pan: float, tilt: float) -> _Track | None:
        """Look at ``(pan, tilt)`` [rad], match, start the EKF by RANSAC and track; record the view.
        None when the view has too few matches or too weak a start."""
        cfg = self.cfg
        frame, f, corr = self._look(pan, tilt)
        rec = {"pan": pan, "tilt": tilt, "t": frame.t, "n_features": len(f), "n_matched": corr.n_matched}
        if corr.n_matched < cfg.min_matches:
            outcome = f"{corr.n_matched} matches < {cfg.min_matches}"
            self.records.append(ViewRecord(**rec, n_inliers=0, outcome=outcome))
            return None
        ekf = PoseEKF(self.ekf_cfg, rng=self.rng)
        res = ekf.update(*corr.pairs(f, self.db))  # RANSAC start
        n_start = res.n_used if ekf.initialized else 0
        if n_start < cfg.min_inliers:
            outcome = f"RANSAC start with {n_start} inliers: {res.reason}"
            self.records.append(ViewRecord(**rec, n_inliers=n_start, outcome=outcome))
            self._came_closer((0, n_start), f"best start had {n_start} inliers < {cfg.min_inliers}")
            return None
        track = _refine(self.robot, self.db, self.matcher, self.detector, ekf, frame, cfg)
        self.records.append(ViewRecord(**rec, n_inliers=n_start, outcome=track.reason))
        if not track.found:
            self._came_closer((1, n_start), f"best track ({n_start} inliers at the start): {track.reason}")
        return track

    def _look(self, pan: float, tilt: float):
        """Turn the head to ``(pan, tilt)``, capture, and match the frame's stereo features."""
        robot = self.robot
        robot.command_pan_tilt(pan, tilt)
        robot.wait_pan_tilt()
        frame = robot.capture_stereo()
        f = stereo_features(frame.left, frame.right, frame.camera, t=frame.t, detector=self.detector)
        return frame, f, self.matcher.match(f)

    def _came_closer(self, rank: tuple[int, int], reason: str) -> None:
        if rank > self.best_rank:
            self.best_reason, self.best_rank = reason, rank

    def _found(self, track: _Track, t_start: float) -> LocalSearchResult:
        return LocalSearchResult(
            True,
            track.reason,
            track.G_WO,
            track.estimate,
            track.frame,
            track.n_inliers,
            track.position_std_m,
            track.rotation_std_deg,
            tuple(self.records),
            t_start,
            self.robot.now(),
        )


def _refine(robot, db, matcher, detector, ekf: PoseEKF, frame: StereoFrame, cfg: LocalSearchConfig):
    """Centre the object and track it over ``cfg.refine_frames`` frames with ROI-restricted SIFT.

    The head aims at the estimated object centre before each frame, offset by a small dither
    (``cfg.dither_deg``, alternating directions): a simulated camera that has not moved renders the very
    same image again, which would add no information while the filter counted it as new (on the robot,
    sensor noise makes successive frames differ).
    """
    prev = frame
    confirmed, last_used = 0, 0
    dither = math.radians(cfg.dither_deg)
    offsets = [(0.0, 0.0), (dither, 0.0), (-dither, dither), (0.0, -dither), (dither, dither)]
    for k in range(cfg.refine_frames):
        p_R = transform_points(prev.G_RC, ekf.estimate.mu[:3])  # estimated object centre in R
        pan, tilt = aim_at(p_R, robot.camera)
        dp, dt = offsets[k % len(offsets)]
        lim = robot.pan_tilt_limits
        robot.command_pan_tilt(
            min(max(pan + dp, lim.pan_min), lim.pan_max), min(max(tilt + dt, lim.tilt_min), lim.tilt_max)
        )
        robot.wait_pan_tilt()
        cur = robot.capture_stereo()
        ekf.predict(prev.G_RC, cur.G_RC, frame_motion(prev, cur), max(0.0, cur.t - prev.t))
        roi = object_roi(ekf.estimate.G_CO, db.extent, cur.camera, cfg.roi_margin_px)
        f = stereo_features(cur.left, cur.right, cur.camera, roi=roi, t=cur.t, detector=detector)
        corr = matcher.match(f)
        res = ekf.update(*corr.pairs(f, db))  # gated by the geometric feasibility check
        last_used = res.n_used if res.applied else 0
        if res.applied and res.n_used >= cfg.confirm_matches:
            confirmed += 1
        prev = cur
    pos_std, rot_std = _stds(ekf)
    G_WO = prev.odom.G() @ prev.G_RC @ ekf.estimate.G_CO
    base = {
        "estimate": ekf.object_estimate,
        "frame": prev,
        "n_inliers": last_used,
        "position_std_m": pos_std,
        "rotation_std_deg": rot_std,
        "G_WO": G_WO,
    }
    if ekf.divergence is not None:
        return _Track(False, f"track diverged: {ekf.divergence}", **base)
    if confirmed < cfg.confirm_updates:
        return _Track(
            False,
            f"not confirmed: {confirmed} of {cfg.refine_frames} refinement updates had >= "
            f"{cfg.confirm_matches} matches (need {cfg.confirm_updates})",
            **base,
        )
    if pos_std > cfg.max_position_std_m or rot_std > cfg.max_rotation_std_deg:
        return _Track(False, f"pose too uncertain: std {pos_std * 100:.1f} cm, {rot_std:.1f} deg", **base)
    check = ""
    if cfg.pose_check is not None:  # does the pose explain the last frame? (lab.search.pose_check)
        pc = check_pose(f, corr, db, ekf.estimate.G_CO, prev.camera, cfg.pose_check, roi)
        if not pc.confirmed:
            return _Track(False, f"pose not confirmed: {pc.reason}", **base)
        check = f"; {pc.reason}"
    return _Track(
        True,
        f"found: {confirmed} confirming updates, std {pos_std * 100:.2f} cm, {rot_std:.2f} deg{check}",
        **base,
    )


@dataclass(frozen=True)
class _Track:
    found: bool
    reason: str
    estimate: PoseEstimate
    frame: StereoFrame
    n_inliers: int
    position_std_m: float
    rotation_std_deg: float
    G_WO: np.ndarray
