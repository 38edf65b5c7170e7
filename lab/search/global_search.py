r"""The coarse global search of the search paper (Sec. III-B): colour peaks, sparse stereo, map update.

From where the robot stands, the pan-tilt head scans a set of views that covers the viewing
hemisphere (:func:`scan_configurations`). In each view:

1. **Back-projection.** Every pixel gets how much its red-green chromaticity looks like the object
   (:func:`lab.vision.back_project`). The histogram back-projected is the likelihood ratio of the
   object's model histogram against the whole scan's own histogram, scaled so the most object-like
   colour is 1 (:func:`object_likelihood_ratio`, after Swain and Ballard's ratio histogram): colours
   that are everywhere (grey walls, the floor) score near 0, colours that are rare in the room and
   common on the object near 1. (With the plain model histogram every grey wall lights up: the
   objects' printed faces hold a lot of white and grey.)
2. **Fixed window.** A box filter of ``window_px`` x ``window_px`` pixels averages the back-projection:
   a cluster's score is the fraction of a window that looks like the object.
3. **N_hist strongest clusters** by non-maximum suppression (:func:`strongest_clusters`): the
   window-mean maximum, then the next maximum at least ``suppression_px`` away, and so on, keeping
   those of strength at least ``min_strength``. The paper normalises each image to a distribution
   over its pixels; we keep the window means in [0, 1] instead, so that a view holding nothing like
   the object gives no confident peak (a normalised image always has one).
4. **Sparse stereo.** The peak's disparity is the median dense disparity of the pixels in its window
   that look most like the object (back-projection at least half the window's best), from
   :func:`lab.vision.dense.checked_disparity` (SGBM over the full image width, left-right checked); the
   pixel and disparity triangulate to ``p_C`` (:func:`lab.vision.triangulate`'s formulas), and
   ``p_W = G_WR(odometry) G_RC(pan, tilt) p_C``.
5. **Detections.** A peak whose point is on the map, at a height where an object can stand
   (``[min_height_m, max_height_m]``), within ``max_range_m`` of the camera and not on the robot's own
   base, and the strongest of its view in its cell, is a positive detection of that cell with
   ``P(y_uv = 1 | h_uv = 1) = P'_n`` (its strength) and the growing beta of
   :func:`lab.search.probability_map.update_global`: a
   :class:`~lab.search.probability_map.ColourPeakDetection`, which the caller applies to its map with
   :meth:`~lab.search.probability_map.ProbabilityMap.observe`, in the order given.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from lab.errors import ConfigError
from lab.geometry import transform_points
from lab.robot import Robot, StereoCamera, StereoFrame
from lab.search.probability_map import ColourPeakDetection, DetectionModel, ProbabilityMap, observe
from lab.vision.colour import back_project, colour_histogram
from lab.vision.database import FeatureDatabase
from lab.vision.dense import checked_disparity

__all__ = [
    "ColourPeak",
    "GlobalSearchConfig",
    "GlobalSearchResult",
    "ScanView",
    "global_search",
    "object_likelihood_ratio",
    "peak_disparity",
    "process_view",
    "scan_configurations",
    "strongest_clusters",
    "window_mean",
]


@dataclass(frozen=True)
class GlobalSearchConfig:
    """Settings of the global search (defaults measured in the lab room; see the tests).

    Attributes
    ----------
    pans_deg, tilts_deg : tuple of float
        The scan: every pan at every tilt. Six pans 60 degrees apart with the 75 degree horizontal field
        of view cover the full circle but for the 40 degrees behind the robot the PTU cannot reach;
        the two tilts with the 60 degree vertical field of view cover -60 to +40 degrees of elevation:
        from the lab room's 1.1 m mast, the floor from 0.65 m out, and the far floor, tables and shelf
        near the horizon inside both views rather than at an edge (docs/tuning/global-search-scan-tilts.md).
    window_px : int [px]
        Side of the fixed scanning window (box filter).
    n_hist : int
        ``N_hist``: clusters kept per view.
    min_strength : float
        Smallest window mean kept as a peak.
    suppression_px : int [px]
        Non-maximum suppression radius around a kept cluster.
    detection : DetectionModel
        The colour peak's detector (Eq. (2)): ``alpha`` its false-alarm probability (a peak of strength
        ``P'_n`` multiplies its cell's odds against the rest of the map by about ``P'_n / alpha``: 18
        for the strongest); ``beta`` the smallest missed-detection probability at a peak's cell
        (``P'_n`` above ``1 - beta`` counts as ``1 - beta``); ``growth_m`` the growth length of the
        variable beta.
    min_height_m, max_height_m : float [m]
        Heights at which an object can stand (floor to the top of a shelf object); peaks elsewhere
        (a poster on a wall, the ceiling) are not used.
    max_range_m : float [m]
        Peaks farther from the camera are not used (stereo depth error grows as the range squared).
    min_range_m : float [m]
        Peaks closer than this to the robot's centre (on the floor) are the robot's own base.
    num_disparities : int
        SGBM disparity range (48 px: down to 0.52 m at f = 208 px, b = 0.12 m). Plain SGBM gives no
        disparity in the left ``num_disparities`` columns, and the neighbouring pan's view (15 degrees
        of overlap, about 42 px) does not make up for it, so the peaks take the full-width disparity
        (:func:`lab.vision.dense.checked_disparity`; docs/tuning/global-search-full-width-disparity.md).
    ratio_eps : float
        ``epsilon`` of :func:`object_likelihood_ratio`.
    """

    pans_deg: tuple[float, ...] = (-150.0, -90.0, -30.0, 30.0, 90.0, 150.0)
    tilts_deg: tuple[float, ...] = (-30.0, 10.0)
    window_px: int = 7
    n_hist: int = 3
    min_strength: float = 0.15
    suppression_px: int = 20
    detection: DetectionModel = field(
        default_factory=lambda: DetectionModel(alpha=0.05, beta=0.1, growth_m=0.2)
    )
    min_height_m: float = -0.1
    max_height_m: float = 1.5
    max_range_m: float = 7.0
    min_range_m: float = 0.4
    num_disparities: int = 48
    ratio_eps: float = 3e-3

    def __post_init__(self):
        if not self.pans_deg or not self.tilts_deg:
            raise ConfigError("the scan needs at least one pan and one tilt")
        if self.window_px < 1 or self.window_px % 2 == 0:
            raise ConfigError(f"window_px must be an odd number >= 1, got {self.window_px}")
        if self.n_hist < 1:
            raise ConfigError(f"n_hist must be >= 1, got {self.n_hist}")
        if not 0.0 <= self.min_strength < 1.0:
            raise ConfigError(f"min_strength must be within [0, 1), got {self.min_strength}")
        if self.num_disparities % 16:
            raise ConfigError(f"num_disparities must be a multiple of 16, got {self.num_disparities}")


@dataclass(frozen=True)
class ColourPeak:
    """One colour cluster of one view and what became of it.

    Attributes
    ----------
    view : int
        Index of the view in the scan.
    uv : tuple of 2 floats [px]
        Cluster centre in the left image.
    strength : float
        ``P'_n``: the window mean of the back-projection at the centre, in [0, 1].
    disparity : float or None [px]
    p_W : ndarray, shape (3,) or None [m]
        The cluster's 3D position in the world (odometry) frame.
    cell : tuple of 2 ints or None
        The map cell it projects into.
    used : bool
        Whether it updated the map.
    reason : str
        Why not, when it did not ("used" otherwise).
    """

    view: int
    uv: tuple[float, float]
    strength: float
    disparity: float | None = None
    p_W: np.ndarray | None = field(default=None, repr=False)
    cell: tuple[int, int] | None = None
    used: bool = False
    reason: str = "used"


@dataclass(frozen=True)
class ScanView:
    """One view of the scan: the frame, its back-projection and window means, and its peaks."""

    frame: StereoFrame = field(repr=False)
    backprojection: np.ndarray = field(repr=False)
    window_mean: np.ndarray = field(repr=False)
    peaks: tuple[ColourPeak, ...] = ()


@dataclass(frozen=True)
class GlobalSearchResult:
    """What one global search saw and did.

    Attributes
    ----------
    views : tuple of ScanView
        In scan order.
    peaks : tuple of ColourPeak
        All clusters of all views.
    P_before, P_after : ndarray, shape (nx, ny)
        The map before the search, and after its ``detections`` (what the caller's
        :meth:`~lab.search.probability_map.ProbabilityMap.observe` of them gives).
    background_hist : ndarray
        The scan's own colour histogram (the ratio histogram's denominator).
    colour_model : ndarray
        The histogram that was back-projected (:func:`object_likelihood_ratio`).
    t_start, t_end : float [s]
        Robot time at the start and the end of the scan.
    detections : tuple of ColourPeakDetection
        One per used peak, in scan order: for the caller's map.
    """

    views: tuple[ScanView, ...] = field(repr=False)
    peaks: tuple[ColourPeak, ...] = field(repr=False)
    P_before: np.ndarray = field(repr=False)
    P_after: np.ndarray = field(repr=False)
    background_hist: np.ndarray = field(repr=False)
    colour_model: np.ndarray = field(repr=False)
    t_start: float = 0.0
    t_end: float = 0.0
    detections: tuple[ColourPeakDetection, ...] = field(default=(), repr=False)

    @property
    def used_peaks(self) -> tuple[ColourPeak, ...]:
        return tuple(p for p in self.peaks if p.used)


def scan_configurations(config: GlobalSearchConfig, limits=None) -> list[tuple[float, float]]:
    """``(pan, tilt)`` [rad] of the scan, row by row in a serpentine (the head never swings back).

    Angles outside the pan-tilt ``limits`` (a :class:`~lab.robot.PanTiltLimits`) are clamped to them.
    """
    out = []
    for k, tilt in enumerate(config.tilts_deg):
        pans = config.pans_deg if k % 2 == 0 else tuple(reversed(config.pans_deg))
        for pan in pans:
            p, t = math.radians(pan), math.radians(tilt)
            if limits is not None:
                p = min(max(p, limits.pan_min), limits.pan_max)
                t = min(max(t, limits.tilt_min), limits.tilt_max)
            out.append((p, t))
    return out


def object_likelihood_ratio(model_hist: np.ndarray, background_hist: np.ndarray, eps: float) -> np.ndarray:
    r"""The colour model the scan back-projects: the likelihood ratio of the object's colours against
    the scan's, scaled so the most object-like colour is 1.

    .. math:: R(c) = \frac{M(c) / (I(c) + \epsilon)}{\max_{c'} M(c') / (I(c') + \epsilon)}

    ``M`` and ``I`` are the model's and the scan's histograms, each normalised to sum to 1. ``R`` is
    Swain and Ballard's ratio histogram ``M / I`` without their clip at 1 (which gives every colour
    rarer in the room than on the object the same score, so a small blue spray bottle scores like the
    red cereal box whose logo has a little blue) and normalised by its maximum. ``eps`` (about the
    share of the scan one object covers) keeps a colour the scan barely holds from dominating; and
    when the object's main colours are not in the scan at all, their ratio is ``M / eps`` and every
    colour that *is* in the scan scores low: no confident peak.
    """
    M = model_hist / max(float(model_hist.sum()), 1e-12)
    I = background_hist / max(float(background_hist.sum()), 1e-12)
    R = M / (I + eps)
    return (R / max(float(R.max()), 1e-12)).astype(np.float32)


def window_mean(backprojection: np.ndarray, window_px: int) -> np.ndarray:
    """Mean of the back-projection over a ``window_px`` square around every pixel (box filter)."""
    return cv2.blur(backprojection.astype(np.float32), (window_px, window_px), borderType=cv2.BORDER_CONSTANT)


def strongest_clusters(
    score: np.ndarray, n: int, min_strength: float, suppression_px: int
) -> list[tuple[int, int, float]]:
    """The ``n`` strongest clusters by non-maximum suppression: ``[(u, v, score), ...]``, strongest first.

    Take the maximum, blank a disc of radius ``suppression_px`` around it, repeat; stop early when
    the maximum is below ``min_strength``.
    """
    s = score.astype(np.float32, copy=True)
    H, W = s.shape
    vv, uu = np.mgrid[0:H, 0:W]
    out = []
    for _ in range(n):
        k = int(np.argmax(s))
        v, u = divmod(k, W)
        val = float(s[v, u])
        if val < min_strength or val <= 0.0:
            break
        out.append((u, v, val))
        s[(uu - u) ** 2 + (vv - v) ** 2 <= suppression_px**2] = -1.0
    return out


def peak_disparity(
    disparity: np.ndarray, backprojection: np.ndarray, u: int, v: int, window_px: int
) -> float | None:
    """Median disparity [px] of the pixels of the window at ``(u, v)`` that look most like the object.

    Pixels whose back-projection is at least half the window's largest and whose disparity is valid
    (finite) count; None when there is none (untextured or occluded in the right image). The window
    is widened once (to three times its side) before giving up.
    """
    H, W = disparity.shape
    for half in (window_px // 2, 3 * (window_px // 2) + 1):
        v0, v1, u0, u1 = max(0, v - half), min(H, v + half + 1), max(0, u - half), min(W, u + half + 1)
        bp = backprojection[v0:v1, u0:u1]
        d = disparity[v0:v1, u0:u1]
        good = (bp >= 0.5 * float(bp.max())) & np.isfinite(d) & (bp > 0)
        if np.count_nonzero(good) >= 3:
            return float(np.median(d[good]))
    return None


def _point_C(u: float, v: float, d: float, camera: StereoCamera) -> np.ndarray:
    """Triangulation of a rectified pixel and its disparity: ``Z = f_x b / d``, ``X``, ``Y`` by similar
    triangles (as :func:`lab.vision.triangulate`)."""
    Z = camera.fx * camera.baseline / d
    return np.array([(u - camera.cx) * Z / camera.fx, (v - camera.cy) * Z / camera.fy, Z])


def process_view(
    frame: StereoFrame,
    colour_model: np.ndarray,
    space: str,
    pmap: ProbabilityMap,
    config: GlobalSearchConfig,
    view_index: int = 0,
) -> ScanView:
    """Steps 1-4 of the module docstring for one view (the map is not changed here).

    ``colour_model`` is the histogram to back-project (:func:`object_likelihood_ratio`). Of several
    peaks of one view that fall into the same cell only the strongest is used (a near object spans
    several windows).
    """
    bp = back_project(frame.left, colour_model, space)
    wm = window_mean(bp, config.window_px)
    clusters = strongest_clusters(wm, config.n_hist, config.min_strength, config.suppression_px)
    peaks = []
    disp = None
    G_WC = frame.odom.G() @ frame.G_RC
    odom = frame.odom
    cells_used: set[tuple[int, int]] = set()
    for u, v, val in clusters:
        base = {"view": view_index, "uv": (float(u), float(v)), "strength": val}
        if disp is None:
            disp = checked_disparity(frame.left, frame.right, num_disparities=config.num_disparities)
        d = peak_disparity(disp, bp, u, v, config.window_px)
        if d is None or not d > 0:
            peaks.append(ColourPeak(**base, reason="no stereo disparity at the peak"))
            continue
        p_C = _point_C(u, v, d, frame.camera)
        p_W = transform_points(G_WC, p_C)
        kw = {**base, "disparity": d, "p_W": p_W}
        if p_C[2] > config.max_range_m:
            peaks.append(ColourPeak(**kw, reason=f"farther than {config.max_range_m} m"))
            continue
        if math.hypot(p_W[0] - odom.x, p_W[1] - odom.y) < config.min_range_m:
            peaks.append(ColourPeak(**kw, reason="on the robot itself"))
            continue
        if not config.min_height_m <= p_W[2] <= config.max_height_m:
            peaks.append(ColourPeak(**kw, reason=f"height {p_W[2]:.2f} m where no object can stand"))
            continue
        ij, inside = pmap.spec.cells_of(p_W[None, :2])
        if not inside[0]:
            peaks.append(ColourPeak(**kw, reason="outside the map"))
            continue
        cell = (int(ij[0, 0]), int(ij[0, 1]))
        if cell in cells_used:
            peaks.append(ColourPeak(**kw, cell=cell, reason="a stronger peak of this view is in the cell"))
            continue
        cells_used.add(cell)
        peaks.append(ColourPeak(**kw, cell=cell, used=True))
    return ScanView(frame, bp, wm, tuple(peaks))


def global_search(
    robot: Robot, db: FeatureDatabase, pmap: ProbabilityMap, config: GlobalSearchConfig | None = None
) -> GlobalSearchResult:
    """Scan and find the colour peaks (see the module docstring); ``pmap`` is read, not changed.

    The robot must be enabled and standing still; it stays where it is, only the head moves. The views
    are captured first, so that the ratio histogram's background is the whole scan's colour histogram.
    The result's ``detections`` are for the caller's ``pmap.observe``, in order.
    """
    config = config or GlobalSearchConfig()
    t_start = robot.now()
    frames = []
    for pan, tilt in scan_configurations(config, robot.pan_tilt_limits):
        robot.command_pan_tilt(pan, tilt)
        robot.wait_pan_tilt()
        frames.append(robot.capture_stereo())
    space = db.meta.get("colour_space", "rg")
    bins = db.histogram.shape[0]
    background = sum(colour_histogram(f.left, space=space, bins=bins) for f in frames)
    colour_model = object_likelihood_ratio(db.histogram, background, config.ratio_eps)
    P_before = pmap.P.copy()
    views = []
    detections = []
    P_after = P_before.copy()
    for k, f in enumerate(frames):
        view = process_view(f, colour_model, space, pmap, config, k)
        for p in view.peaks:
            if p.used:
                detections.append(ColourPeakDetection(p.cell, p.strength, config.detection))
                P_after = observe(P_after, pmap.spec, detections[-1])
        views.append(view)
    peaks = tuple(p for v in views for p in v.peaks)
    return GlobalSearchResult(
        tuple(views),
        peaks,
        P_before,
        P_after.copy(),
        background,
        colour_model,
        t_start,
        robot.now(),
        tuple(detections),
    )
