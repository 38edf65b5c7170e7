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
most ``max_rotation_std_deg``; ours besides: the pose in the world rests on one of the box's faces
within ``max_rest_tilt_deg`` and explains the frame (:mod:`lab.search.pose_check`). Otherwise the next
view is tried.

The object's world pose is the odometry pose composed with the camera on the head and the estimate,

.. math:: G_{WO} = G_{WR}(\text{odometry})\; G_{RC}(\text{pan}, \text{tilt})\; G_{CO},

**The second look** (ours, not the paper's: issue 22). Before the cell is declared empty, the search
looks again where the colour says the object is (:class:`SecondLookConfig`): the object's colour model is
back-projected over the 9 views (the ratio histogram of the global search against these views' own
colours, :func:`lab.search.global_search.object_likelihood_ratio`), the strongest window means whose
stereo point lies near the searched cell are aimed at, one at a time, and each new frame's region around
the peak is enlarged ``upsample`` times (:func:`lab.vision.stereo.upsampled_pair`) before SIFT. The
start, refinement and "found" are the same as above, the refinement on enlarged regions too. It is for
small objects far below the camera (an object on the floor seen from the 1.1 m mast spans a few tens of
pixels at 320 x 240, too few SIFT matches for a start), which the enlarged region gives enough
matches. How this was measured: docs/tuning/search-second-look-upsample.md.
``second_look=None`` is the paper's local search.

The result is a detection of the searched cell (:class:`~lab.search.probability_map.LocalSearchDetection`,
with the config's constant ``alpha`` and ``beta`` and its neighbourhood) that the caller applies to its
map: when no view finds the object, a negative one.
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
from lab.geometry import se3, se3_inv, transform_points, wrap_angle
from lab.robot import Robot, StereoFrame
from lab.search.global_search import (
    GlobalSearchConfig,
    object_likelihood_ratio,
    peak_disparity,
    strongest_clusters,
    window_mean,
)
from lab.search.pose_check import PoseCheckConfig
from lab.search.probability_map import DetectionModel, LocalSearchDetection
from lab.search.tracking import Track, aim_at, refine_track, region_features
from lab.vision.colour import back_project, colour_histogram
from lab.vision.database import FeatureDatabase
from lab.vision.dense import checked_disparity
from lab.vision.matching import Matcher
from lab.vision.roi import object_roi
from lab.vision.stereo import sift, stereo_features, triangulate

__all__ = [
    "LocalSearchConfig",
    "LocalSearchResult",
    "SecondLookConfig",
    "ViewRecord",
    "aim_at",
    "local_search",
    "local_views",
    "look_at_points",
    "make_matcher",
    "object_roi",
]


@dataclass(frozen=True)
class SecondLookConfig:
    """The second look of the local search, at colour peaks near the searched cell (module docstring).

    Attributes
    ----------
    upsample : int
        Enlargement of the region around a colour peak before SIFT (bicubic;
        :func:`lab.vision.stereo.upsampled_pair`): 2x gave the floor misses' best views enough right
        matches for a RANSAC start, and 3x did worse than 2x. How it was chosen:
        docs/tuning/search-second-look-upsample.md.
    n_looks : int
        At most this many peaks are looked at, strongest first.
    max_offset_m : float [m]
        A peak counts when its stereo point lies within this horizontal distance of the searched
        cell's centre: the reach of the failed search's negative update
        (``LocalSearchConfig.detection.neighbour_radius_m``), the cells this search answers for.
    min_separation_m : float [m]
        Peaks closer than this to a stronger one are the same object seen in two views.
    margin_px : int [px]
        Margin around the peak's region (an object-sized square at the peak's depth) in the original
        image's pixels.
    colour : GlobalSearchConfig
        The colour peaks' settings: ``window_px``, ``n_hist`` (per view), ``min_strength``,
        ``suppression_px``, ``ratio_eps``, ``num_disparities`` and the heights an object can stand at
        (``min_height_m``, ``max_height_m``), as the global search finds its peaks.
    """

    upsample: int = 2
    n_looks: int = 2
    max_offset_m: float = 0.45
    min_separation_m: float = 0.15
    margin_px: int = 12
    colour: GlobalSearchConfig = field(default_factory=GlobalSearchConfig)

    def __post_init__(self):
        if not (isinstance(self.upsample, int) and self.upsample >= 1):
            raise ConfigError(f"upsample must be an integer >= 1, got {self.upsample!r}")
        if self.n_looks < 1 or not self.max_offset_m > 0:
            raise ConfigError("n_looks must be >= 1 and max_offset_m > 0")


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
    refine_frames, max_refine_frames : int
        Frames of refinement after centring the object; a track confirmed and healthy whose pose is
        still above the bounds then is refined on, up to ``max_refine_frames`` in all (more evidence
        rather than a refusal; ``refine_frames``: never, the paper's). docs/tuning/search-refine-on.md.
    confirm_updates, confirm_matches : int
        "Found" needs at least ``confirm_updates`` refinement updates that each used at least
        ``confirm_matches`` gated matches.
    dither_deg : float [deg]
        Head offset between refinement frames (see :func:`lab.search.tracking.refine_track`).
    max_position_std_m : float [m]
    max_rotation_std_deg : float [deg]
        "Small covariance": bounds on the largest position and rotation standard deviations.
    roi_margin_px : int [px]
        Margin around the projected object's bounding box for the ROI.
    detection : DetectionModel
        The search's detector, for the map update of its result's ``detection``: ``alpha``, ``beta``
        the constant detection errors of Eq. (2) (false alarm and missed detection at close range);
        ``neighbour_radius_m``: a search is a detection of the searched cell *and* of every cell whose
        centre lies within this distance of it (one Bayes update per cell), since the 9 views look at
        the searched cell's neighbours as closely as at the cell. The default radius is the reach of
        the strongest colour peak's growing beta (``lambda ln((1 - alpha) / beta_min)`` = 0.45 m, see
        the probability map). 0 is the paper's update of the one cell, which sends the robot on to
        each of the neighbours that the global search's growing beta raised with the peak (the
        paper's Fig. 6 shows such a revisit).
    process : ProcessNoise
        The EKF's static-object process noise (Eq. (4): ``X_k = X_{k-1} + eta``).
    pose_check : PoseCheckConfig or None
        The last check before "found": the pose must explain enough of the database features it
        predicts in view (:mod:`lab.search.pose_check`); None skips it.
    second_look : SecondLookConfig or None
        Before the cell is declared empty, look again at the colour peaks near it, on enlarged
        regions (module docstring; ours). None: the paper's local search, the 9 views alone.
    refine_upsample : int
        The refinement's region of interest is enlarged at least this many times before SIFT
        (:func:`lab.vision.stereo.upsampled_pair`; a second look's own ``upsample`` when larger). 1: as
        captured, the paper's. An object that drives away while the robot looks leaves the
        local-search range: at 1.4-2 m a box spans 25-50 px at 320 x 240 and its refinement frames
        matched too few features for an update, where the enlarged region matched three times as many
        (:func:`lab.runs.moving.agent_config` sets 2; docs/tuning/search-moving-object.md).
    max_rest_tilt_deg : float or None [deg]
        "Found" needs the pose in the world to rest on one of the object's faces within this angle
        (:func:`lab.search.pose_check.rest_tilt_deg`): the success criterion's 10 degrees, which no
        pose that counts as correct exceeds. None skips it (an object that leans or hangs).
    """

    pans_deg: tuple[float, ...] = (0.0, 60.0, -60.0)
    tilts_deg: tuple[float, ...] = (0.0, -35.0, 31.0)
    min_distance_m: float = 0.6
    max_distance_m: float = 0.9
    min_matches: int = 6
    min_inliers: int = 5
    refine_frames: int = 4
    max_refine_frames: int = 8
    confirm_updates: int = 2
    confirm_matches: int = 5
    dither_deg: float = 2.0
    max_position_std_m: float = 0.01
    max_rotation_std_deg: float = 3.0
    roi_margin_px: int = 20
    detection: DetectionModel = field(
        default_factory=lambda: DetectionModel(alpha=0.05, beta=0.1, neighbour_radius_m=0.45)
    )
    process: ProcessNoise = field(
        default_factory=lambda: ProcessNoise(sigma_v=0.0, sigma_w=0.0, eta_m=2e-3, eta_rad=5e-3)
    )
    pose_check: PoseCheckConfig | None = field(default_factory=PoseCheckConfig)
    second_look: SecondLookConfig | None = field(default_factory=SecondLookConfig)
    refine_upsample: int = 1
    max_rest_tilt_deg: float | None = 10.0

    def __post_init__(self):
        if self.max_rest_tilt_deg is not None and not 0 < self.max_rest_tilt_deg <= 90:
            raise ConfigError(
                "max_rest_tilt_deg must be in (0, 90] degrees or None (no check), "
                f"got {self.max_rest_tilt_deg}"
            )
        if len(self.pans_deg) * len(self.tilts_deg) < 1:
            raise ConfigError("the local search needs at least one view")
        if not 0 < self.min_distance_m <= self.max_distance_m:
            raise ConfigError(
                f"need 0 < min_distance_m <= max_distance_m, got {self.min_distance_m}, {self.max_distance_m}"
            )
        if self.min_matches < 4 or self.min_inliers < 4:
            raise ConfigError("min_matches and min_inliers must be >= 4 (a RANSAC start needs 4)")
        if not 1 <= self.refine_frames <= self.max_refine_frames:
            raise ConfigError(
                f"need 1 <= refine_frames <= max_refine_frames, got {self.refine_frames}, "
                f"{self.max_refine_frames}"
            )
        if not (isinstance(self.refine_upsample, int) and self.refine_upsample >= 1):
            raise ConfigError(f"refine_upsample must be an integer >= 1, got {self.refine_upsample!r}")


@dataclass(frozen=True)
class ViewRecord:
    """What one view of the local search saw (a second look: ``upsample`` > 1, or its outcome says so)."""

    pan: float
    tilt: float
    t: float
    n_features: int
    n_matched: int
    n_inliers: int
    outcome: str
    upsample: int = 1  # > 1: a second look, SIFT on the region enlarged this many times


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
    colour_peaks : tuple of ndarray, shape (3,) [m]
        The world points of the object's colour near the searched cell that the second look aimed at
        (odometry frame): on a miss, the object's colours were there but no pose came of them.
    detection : LocalSearchDetection or None
        The search as a detection of its map cell (``y = 1`` found, ``y = 0`` not) with the config's
        :class:`~lab.search.probability_map.DetectionModel`, for the caller's
        :meth:`~lab.search.probability_map.ProbabilityMap.observe`; None when no cell was given.
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
    colour_peaks: tuple[np.ndarray, ...] = field(default=(), repr=False)
    detection: LocalSearchDetection | None = field(default=None, repr=False)


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


#: Database features closer than this [m] in the object frame are one physical point for the ratio
#: test (:class:`lab.vision.Matcher`'s ``alias_radius``): the search's several training rings see a
#: point from directions far apart, with descriptors too different to merge.
ALIAS_RADIUS_M = 0.015


def make_matcher(db: FeatureDatabase) -> Matcher:
    """The database's matcher: FLANN, or exact search for a tiny database (OpenCV's KD-tree asserts
    when asked for about as many neighbours as the database holds: the glossy cup has 11 features);
    with spatial aliases (:data:`ALIAS_RADIUS_M`)."""
    return Matcher(db, method="flann" if len(db) >= 64 else "brute", alias_radius=ALIAS_RADIUS_M)


def local_search(
    robot: Robot,
    db: FeatureDatabase,
    target_xy,
    rng: np.random.Generator,
    config: LocalSearchConfig | None = None,
    matcher: Matcher | None = None,
    *,
    cell: tuple[int, int] | None = None,
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
    cell : (i, j), optional
        The searched map cell: the result's ``detection`` is of it.

    Returns
    -------
    LocalSearchResult
    """
    cfg = config or LocalSearchConfig()
    return _LocalSearch(robot, db, rng, cfg, matcher or make_matcher(db)).run(target_xy, cell)


def look_at_points(
    robot: Robot,
    db: FeatureDatabase,
    points_W,
    rng: np.random.Generator,
    config: LocalSearchConfig | None = None,
    matcher: Matcher | None = None,
) -> LocalSearchResult:
    """The second look alone: aim the head at each world point of ``points_W`` [m] in turn (the colour
    peaks an earlier local search found near its cell) and start and track on the enlarged region around
    it, as :class:`SecondLookConfig` says, until one finds the object. The search agent's side look
    calls it after stepping round the peak (``SearchAgentConfig.side_look_deg``).

    Parameters
    ----------
    robot : Robot
        Enabled and standing still; only the head moves.
    db : FeatureDatabase
    points_W : sequence of array-like, shape (3,) [m]
        World (odometry-frame) points, looked at in the order given.
    rng : numpy.random.Generator
    config : LocalSearchConfig, optional
        Its ``second_look`` (the default :class:`SecondLookConfig` when None), refinement and "found".
    matcher : Matcher, optional

    Returns
    -------
    LocalSearchResult
        On a miss, ``colour_peaks`` holds the points looked at.
    """
    cfg = config or LocalSearchConfig()
    points = [np.asarray(p, float).reshape(3) for p in points_W]
    if not points:
        raise ConfigError("look_at_points needs at least one point to look at")
    return _LocalSearch(robot, db, rng, cfg, matcher or make_matcher(db)).look(points)


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
        self.frames: list[StereoFrame] = []  # the views' frames, for the second look's colour peaks
        self.best_reason, self.best_rank = "no view had enough matches", (-1, -1)

    def run(self, target_xy, cell=None) -> LocalSearchResult:
        """Search the views centred on the bearing of ``target_xy`` [m] (world) from the robot, then,
        before giving up, take the second look at the colour peaks near it; a detection of ``cell``
        when it is given."""
        robot = self.robot
        t_start = robot.now()
        odom = robot.odometry()
        bearing = wrap_angle(math.atan2(target_xy[1] - odom.y, target_xy[0] - odom.x) - odom.theta)
        for pan, tilt in local_views(self.cfg, bearing, robot.pan_tilt_limits):
            track = self._search_view(pan, tilt)
            if track is not None and track.found:
                return self._found(track, t_start, self._detection(cell, 1))
        peaks = []
        if self.cfg.second_look is not None:
            peaks = self._colour_peaks(target_xy, self.cfg.second_look)
            for p_W in peaks:
                track = self._second_look(p_W, self.cfg.second_look)
                if track is not None and track.found:
                    return self._found(track, t_start, self._detection(cell, 1))
        return LocalSearchResult(
            False,
            f"not found in {len(self.records)} views: {self.best_reason}",
            views=tuple(self.records),
            t_start=t_start,
            t_end=robot.now(),
            colour_peaks=tuple(peaks),
            detection=self._detection(cell, 0),
        )

    def _detection(self, cell, y: int) -> LocalSearchDetection | None:
        return None if cell is None else LocalSearchDetection(tuple(cell), y, self.cfg.detection)

    def look(self, points_W: list[np.ndarray]) -> LocalSearchResult:
        """The second look at each of ``points_W`` [m] (world) in turn (:func:`look_at_points`)."""
        t_start = self.robot.now()
        sl = self.cfg.second_look or SecondLookConfig()
        for p_W in points_W:
            track = self._second_look(p_W, sl)
            if track is not None and track.found:
                return self._found(track, t_start)
        return LocalSearchResult(
            False,
            f"not found in {len(self.records)} looks at colour peaks: {self.best_reason}",
            views=tuple(self.records),
            t_start=t_start,
            t_end=self.robot.now(),
            colour_peaks=tuple(points_W),
        )

    def _search_view(self, pan: float, tilt: float) -> Track | None:
        """Look at ``(pan, tilt)`` [rad], match, start the EKF by RANSAC and track; record the view.
        None when the view has too few matches or too weak a start."""
        robot = self.robot
        robot.command_pan_tilt(pan, tilt)
        robot.wait_pan_tilt()
        frame = robot.capture_stereo()
        self.frames.append(frame)
        f = stereo_features(frame.left, frame.right, frame.camera, t=frame.t, detector=self.detector)
        return self._start_and_track(frame, f, self.matcher.match(f), pan, tilt, upsample=1)

    def _start_and_track(self, frame, f, corr, pan: float, tilt: float, upsample: int) -> Track | None:
        """The RANSAC start from one frame's matches and, when it is strong enough, the track; records
        the view (``upsample`` > 1: the features are of the region enlarged that many times)."""
        cfg = self.cfg
        rec = {"pan": pan, "tilt": tilt, "t": frame.t, "n_features": len(f), "n_matched": corr.n_matched}
        look = "" if upsample == 1 else f"second look ({upsample}x region): "
        if corr.n_matched < cfg.min_matches:
            outcome = f"{look}{corr.n_matched} matches < {cfg.min_matches}"
            self.records.append(ViewRecord(**rec, n_inliers=0, outcome=outcome, upsample=upsample))
            return None
        ekf = PoseEKF(self.ekf_cfg, rng=self.rng)
        res = ekf.update(*corr.pairs(f, self.db))  # RANSAC start
        n_start = res.n_used if ekf.initialized else 0
        if n_start < cfg.min_inliers:
            outcome = f"{look}RANSAC start with {n_start} inliers: {res.reason}"
            self.records.append(ViewRecord(**rec, n_inliers=n_start, outcome=outcome, upsample=upsample))
            self._came_closer((0, n_start), f"{look}best start had {n_start} inliers < {cfg.min_inliers}")
            return None
        track = refine_track(self.robot, self.db, self.matcher, self.detector, ekf, frame, cfg, upsample)
        self.records.append(
            ViewRecord(**rec, n_inliers=n_start, outcome=look + track.reason, upsample=upsample)
        )
        if not track.found:
            self._came_closer(
                (1, n_start), f"{look}best track ({n_start} inliers at the start): {track.reason}"
            )
        return track

    def _colour_peaks(self, target_xy, sl: SecondLookConfig) -> list[np.ndarray]:
        """The points ``p_W`` (3,) [m] of the strongest colour peaks of the views near ``target_xy``,
        strongest first, at most ``sl.n_looks`` and ``sl.min_separation_m`` apart.

        As the global search finds its peaks (:func:`lab.search.global_search.process_view`), with the
        ratio histogram's background the colours of these views: back-projection, window mean, the
        ``n_hist`` strongest clusters of each view, the median full-width checked disparity of the
        window's most object-like pixels, and ``p_W = G_WR(odometry) G_RC(pan, tilt) p_C``."""
        c = sl.colour
        space = self.db.meta.get("colour_space", "rg")
        bins = self.db.histogram.shape[0]
        background = sum(colour_histogram(fr.left, space=space, bins=bins) for fr in self.frames)
        model = object_likelihood_ratio(self.db.histogram, background, c.ratio_eps)
        peaks: list[tuple[float, np.ndarray]] = []
        for fr in self.frames:
            bp = back_project(fr.left, model, space)
            clusters = strongest_clusters(
                window_mean(bp, c.window_px), c.n_hist, c.min_strength, c.suppression_px
            )
            disp = checked_disparity(fr.left, fr.right, c.num_disparities) if clusters else None
            for u, v, strength in clusters:
                d = peak_disparity(disp, bp, u, v, c.window_px)
                if d is None or not d > 0:
                    continue
                uv = np.array([[float(u), float(v)]])
                p_C = triangulate(uv, uv - [[d, 0.0]], fr.camera)[0]  # Z = f_x B / d
                p_W = transform_points(fr.odom.G() @ fr.G_RC, p_C)
                near = math.hypot(p_W[0] - target_xy[0], p_W[1] - target_xy[1]) <= sl.max_offset_m
                if near and c.min_height_m <= p_W[2] <= c.max_height_m:
                    peaks.append((strength, p_W))
        chosen: list[np.ndarray] = []
        for _, p_W in sorted(peaks, key=lambda sp: -sp[0]):
            if all(np.linalg.norm(p_W - q) >= sl.min_separation_m for q in chosen):
                chosen.append(p_W)
            if len(chosen) == sl.n_looks:
                break
        return chosen

    def _second_look(self, p_W: np.ndarray, sl: SecondLookConfig) -> Track | None:
        """Aim the head at the colour peak's point ``p_W`` [m], and start and track on the region around
        it (an object-sized square at its depth) enlarged ``sl.upsample`` times."""
        robot = self.robot
        p_R = transform_points(se3_inv(robot.odometry().G()), p_W)
        pan, tilt = aim_at(p_R, robot.camera, robot.pan_tilt_limits)
        robot.command_pan_tilt(pan, tilt)
        robot.wait_pan_tilt()
        frame = robot.capture_stereo()
        p_C = transform_points(se3_inv(frame.odom.G() @ frame.G_RC), p_W)
        side = float(np.linalg.norm(self.db.extent))  # the object's diagonal, whichever way it stands
        roi = object_roi(se3(np.eye(3), p_C), (side, side, side), frame.camera, sl.margin_px)
        if roi is None:
            return None
        f, _, _ = region_features(frame, roi, sl.upsample, self.detector)
        return self._start_and_track(frame, f, self.matcher.match(f), pan, tilt, sl.upsample)

    def _came_closer(self, rank: tuple[int, int], reason: str) -> None:
        if rank > self.best_rank:
            self.best_reason, self.best_rank = reason, rank

    def _found(self, track: Track, t_start: float, detection=None) -> LocalSearchResult:
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
            detection=detection,
        )
