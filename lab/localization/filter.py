r"""The localizer: an EKF over the robot's planar pose, corrected by stereo landmark observations.

An extended Kalman filter over the planar pose :math:`x = [x, y, \theta]^T` in the world W fuses the
odometry's increments (prediction, :func:`~lab.localization.models.motion_model`; its noise grows with
the distance driven and the angle turned, :meth:`LocalizerConfig.motion_noise`) with landmark
observations (update, :func:`~lab.localization.models.measurement_model`; each observation's covariance
is the fit's own plus a floor, :meth:`LocalizerConfig.observation_floor`).

The filter never sees ground truth. Its equations, written as the code does::

    predict:  x_bar = f(x, u)                           F = df/dx,  V = df/du
              Sigma_bar = F Sigma F^T + V M(u) V^T
    update:   nu = z - h(x_bar)   (angle wrapped)       H = dh/dx
              S = H Sigma_bar H^T + Q
              gate: nu^T S^-1 nu <= chi2_3(gate_prob), else the observation is rejected (an outlier)
              K = Sigma_bar H^T S^-1
              x = x_bar + K nu
              iterated: x_i+1 = x_bar + K_i (z - h(x_i) - H_i (x_bar - x_i)),  H_i, K_i at x_i
                        (from x_0 = x_bar, until it stops moving: Gauss-Newton to the posterior's mode)
              Sigma = (I - K H) Sigma_bar (I - K H)^T + K Q K^T      (Joseph form: stays symmetric PSD)

**The odometry's calibration** (``LocalizerConfig.odometry_calibration``, on by default): the largest
odometry errors of a real base are systematic, the same on every turn (spin slip, the effective track
width) and every metre (unequal wheels), so they add up linearly where the noise ``M(u)`` grows like a
random walk. The state is then ``s = [x, y, theta, k, c]``: the pose, the turn scale ``k`` and the
curvature bias ``c`` [rad/m], with ``theta' = theta + k dtheta + c dx``
(:func:`~lab.localization.models.calibrated_motion_model`) and the same equations on the longer state
(``H = [dh/dx, 0]``: a landmark sees the pose; a turn correlates the heading with ``k``, and the next
update corrects both). ``x`` and ``Sigma`` stay the pose's mean and covariance. With
``spin_slip_sigma`` above 0 the state also carries the spin's slip ``sigma``, the extra over-count of a
turn in place (``theta' = theta + (k - sigma phi) dtheta + c dx``, ``phi`` the increment's spin
fraction), so that a spin's slip is not taken for the turn scale of a drive.

**A surveyed map** (:attr:`Landmark.survey_sigma_m` above 0): each such poster's planar pose joins the
state, seeded by the survey, and the updates refine it (landmark SLAM, :mod:`lab.localization.posters`).

The update is iterated (``LocalizerConfig.update_iterations``) because one EKF step is linearised at the
prior: after a long drive on realistic odometry the heading can be 15 deg off, and one step then left
the estimate 15 cm from where a precise poster sighting put the robot, with a covariance claiming 2 cm
(measured in search trials); relinearising at the new mean converges to the posterior's mode instead.

This module holds one idea, the filter: its configuration (noise models, gate and thresholds), the
estimate and update records it reports, the pose clone it can keep, and :class:`Localizer` itself.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from lab.errors import ConfigError
from lab.estimation.fit import RansacConfig, chi2_quantile
from lab.geometry import Pose2D, wrap_angle
from lab.localization.landmarks import Landmark
from lab.localization.models import (
    calibrated_motion_jacobians,
    calibrated_motion_model,
    motion_jacobians,
    motion_model,
)
from lab.localization.modes import LocalizationMode
from lab.localization.posters import PosterStates, observe, sighting_pose
from lab.localization.refind import Refinder, RejectedSighting

__all__ = ["Localizer", "LocalizerConfig", "PlanarPoseEstimate", "UpdateRecord"]


@dataclass(frozen=True)
class LocalizerConfig:
    """Noise models and thresholds of the localizer.

    How each was chosen (the split, the evidence, the command): ``docs/tuning/localizer-*.md``, one file
    per tuned quantity, named below.

    Attributes
    ----------
    sigma_along_m_per_sqrt_m : float [m / sqrt(m)]
        Odometry's distance error grows like a random walk in the distance driven ``d``:
        ``var = sigma**2 * d`` along the motion ...
    sigma_cross_m_per_sqrt_m : float [m / sqrt(m)]
        ... and across it;
    sigma_heading_rad_per_sqrt_m : float [rad / sqrt(m)]
        heading error per distance (unequal wheels curve a straight drive);
    sigma_heading_rad_per_sqrt_rad : float [rad / sqrt(rad)]
        heading error per angle turned (track width error, wheel scrub). How they were chosen:
        docs/tuning/localizer-motion-noise.md.
    obs_sigma_m, obs_sigma_rel, obs_sigma_per_m, obs_sigma_rel_across, obs_sigma_rad : float
        A floor under each landmark observation's covariance, added to the fit's own for the errors a
        fit cannot see because they move every feature of a frame together (see
        :meth:`observation_floor`): along the line of sight a constant [m], a share of the range [-]
        (the baseline's and focal lengths' scale error) and a share of its square [1/m] (a disparity
        bias: depth error ``Z^2 delta_d / (f B)``); across it the constant and a share of the range [-]
        (the pan-tilt's pointing error); and the heading [rad]. The heading's floor is wide because a
        poster's yaw comes from the depth differences across its face, and errors its features share
        turn it further than the fit's covariance says (not traced; depth errors along the line of
        sight, where a stereo point's own covariance is long, are the likely cause). How they were
        chosen: docs/tuning/localizer-observation-floor.md and docs/tuning/localizer-heading-floor.md.
    shared_floor : bool
        Sightings of one landmark from one place (the robot has not driven ``recount_m`` or turned
        ``recount_rad`` since the first of them) share the floor's error: a second look brings fresh
        image noise (the fit's own covariance) but the same calibration. The ``n``-th such sighting's
        covariance is then the one that leaves the filter's information what ``n`` sightings really
        hold (:meth:`shared_floor_covariance`), not ``n`` times one sighting's. False: every sighting
        counted as independent, as before (under issue 52's survey a robot standing at its find looked
        8 times at one poster and ended 2.5 cm off while stating 1.1 cm). The gate sees the same
        covariance, so a repeated look's wrong fit passes more easily, and moves the estimate little.
        Why and what it changed: docs/tuning/localizer-shared-floor.md.
    gate_prob : float
        Observations whose innovation's Mahalanobis distance exceeds the chi-square(3) quantile are
        rejected as outliers.
    max_rejected_in_a_row, reject_inflation : int, float
        Gate lock-out recovery: after this many rejected observations in a row the estimate, not the
        landmarks, is the likelier culprit (an odometry bias the noise model does not cover, such as
        wheel scrub in long turns), so the covariance is multiplied by ``reject_inflation`` and the
        next observation can correct it.
    recount_m, recount_rad : float [m], [rad]
        A rejection counts towards that lock-out once per landmark until the robot has driven
        ``recount_m`` or turned ``recount_rad`` since: a robot standing still that sees the same wrong
        fit frame after frame (a local search's dozen views, a poster in the background of each) holds
        one piece of evidence against its estimate, not a dozen, and counted frame by frame it could
        trip the recovery (the covariance x 9) on its own. Rejections of different landmarks from one
        place still count each (and after an inflation every landmark counts again: several landmarks
        that all disagree with the estimate do move it). How it was chosen:
        docs/tuning/localizer-recount-rule.md.
    min_inliers : int
        Fewest RANSAC inliers for a landmark observation.
    min_face_in_image : float
        Smallest share of the printed face that must project into the image, at the fitted pose, for a
        fit to be used (:func:`face_share_in_image`). A fit from a patch of the face at the image's edge
        rests on features from a small part of it, and its covariance can understate its error. How it
        was chosen: docs/tuning/localizer-min-face-in-image.md.
    max_range_m, min_facing : float
        A landmark is looked for in a frame only within this range and when seen at most
        ``acos(min_facing)`` off its face normal.
    relocalize_sigma_m, relocalize_sigma_rad : float [m], [rad]
        Active re-localization: the robot looks for a landmark when the position standard deviation
        (the larger axis of the covariance ellipse) or the heading's exceeds these.
    drive_sigma_m, drive_sigma_rad : float [m], [rad]
        A drive stops to re-localize when the position's or the heading's standard deviation passes
        these (:meth:`LocalizedRobot.drive_guard`, the search's
        :class:`~lab.search.report_policy.RelocalizingNavigate`): every frame the navigator maps is
        placed with the pose, and frames from a pose this uncertain leave slanted copies of walls in its
        costmap. Looser than ``relocalize_sigma_*`` (which every drive starts within when a landmark is
        in view): an ordinary drive of a few metres ends at 5-20 cm / 3-7 deg without stopping. How
        they were chosen: docs/tuning/room-errors.md.
    report_sigma_m, report_sigma_rad : float [m], [rad]
        The same thresholds before a run reports a pose in the room (a found object's): tighter, since
        the object's world pose inherits the robot's error whole. How they were chosen:
        docs/tuning/localizer-report-sigma.md.
    report_max_views, report_passes : int
        At most this many head views for the reporting re-localization, going round the landmarks in
        view up to ``report_passes`` times (a second look at a poster brings fresh image noise, not a
        fresh calibration: more passes would make the filter trust the shared error more than it should;
        a later pass looks again only where the one before saw a landmark the filter accepted).
    report_detour_m : float [m]
        When the re-localization before a report cannot get the found object's point within
        ``report_sigma_m`` (no landmark seen well from where the robot found it), the robot keeps that
        pose in the filter (:meth:`Localizer.start_clone`), drives at most this far (straight-line) to a
        place where a landmark is in view (:meth:`LocalizedRobot.landmark_vantage_points`), re-localizes
        there, and reports the object from the corrected kept pose. 0: no detour.
    report_detour_above_m : float [m]
        The detour is made only when the point's standard deviation is above this after the
        re-localization where the robot stands: the odometry of a detour itself leaves about 3 cm at
        1.5 m, so a point known better than this gains nothing from one. How it was chosen:
        docs/tuning/localizer-report-detour.md.
    first_sighting_max_offset_m, first_sighting_max_offset_rad : float [m], [rad]
        A start pose measured by hand (:class:`Localizer` with ``first_sighting=True``): the first
        landmark sighting that disagrees with it beyond the gate replaces it when the pose it implies is
        within these of the start (farther: an outlier, rejected).
    refind : bool
        Re-find a lost robot: two rejected sightings that are independent evidence (two posters, or one
        poster from two places) and agree with each other, within the gate, reset the pose from the newer
        (:mod:`lab.localization.refind`). False (the default): only the lock-out recovery above. Off
        because the reset drops what the estimate knew: it re-finds robots lost by 10-45 deg or metres,
        but it also fires on a filter that is only slightly overconfident, and there it leaves the pose
        worse. Why, and what it gained and cost: docs/tuning/localizer-refind.md.
    update_iterations : int
        The landmark update's iterations (the iterated EKF: relinearise at the new mean until it stops
        moving, at most this many); 1 is the plain EKF. How it was chosen:
        docs/tuning/localizer-update-iterations.md.
    camera_yaw_sigma_rad : float [rad]
        Estimate the camera's yaw on the base (the pan zero and the mounts' yaw) in the state, from this
        prior (:mod:`lab.localization.posters`); 0: assumed exact (not in the state).
    range_scale_sigma : float [-]
        Estimate the stereo's range scale (the calibration's focal length and baseline errors, which
        stretch every sighting's range by the same factor) in the state, from this prior
        (:mod:`lab.localization.posters`); 0: assumed exact (not in the state).
    odometry_calibration : bool
        Estimate the odometry's turn scale ``k`` and curvature bias ``c`` in the state
        (:func:`calibrated_motion_model`); False: the pose alone, with the systematic errors left to the
        motion noise's random walk.
    turn_scale_sigma, curvature_sigma_rad_per_m : float [-], [rad/m]
        The calibration's prior: ``k ~ N(1, turn_scale_sigma^2)``, ``c ~ N(0, curvature_sigma^2)``
        (a Create 2's spin over-count and track error are a few per cent; unequal wheels of 0.5 % curve
        it by 0.02 rad/m).
    turn_scale_walk_per_sqrt_rad : float [1 / sqrt(rad)]
        ``k`` is not quite a constant (the slip depends on how much of a motion is a spin): its variance
        grows by this squared per radian turned.
    spin_slip_sigma : float [-]
        Estimate the spin's slip ``sigma`` in the state (:func:`calibrated_motion_model`), from the prior
        ``N(0, spin_slip_sigma^2)``; 0: not in the state, ``k`` takes a spin's slip and a drive's turn
        alike. Needs ``odometry_calibration``.
    track_m : float [m]
        The base's nominal track (the odometry's wheel base), which sets an increment's spin fraction
        (:func:`lab.localization.models.spin_fraction`): the Create 2's 0.235 m.
    calibrated_heading_rad_per_sqrt_m, calibrated_heading_rad_per_sqrt_rad : float
        With the calibration on, the heading noise per distance and per angle turned that is left once
        the systematic part is in the state: these replace ``sigma_heading_rad_per_sqrt_m`` and
        ``sigma_heading_rad_per_sqrt_rad`` in :meth:`motion_noise`. How they and the calibration's
        prior were chosen: docs/tuning/localizer-motion-noise.md.
    """

    sigma_along_m_per_sqrt_m: float = 0.02
    sigma_cross_m_per_sqrt_m: float = 0.01
    sigma_heading_rad_per_sqrt_m: float = 0.03
    sigma_heading_rad_per_sqrt_rad: float = 0.1
    obs_sigma_m: float = 0.002
    obs_sigma_rel: float = 0.002
    obs_sigma_per_m: float = 0.001
    obs_sigma_rel_across: float = 0.001
    obs_sigma_rad: float = math.radians(0.75)
    shared_floor: bool = True
    gate_prob: float = 0.999
    max_rejected_in_a_row: int = 3
    reject_inflation: float = 9.0
    recount_m: float = 0.05
    recount_rad: float = math.radians(2.0)
    min_inliers: int = 10
    min_face_in_image: float = 1.0 / 3.0
    max_range_m: float = 6.5
    min_facing: float = 0.35
    relocalize_sigma_m: float = 0.05
    relocalize_sigma_rad: float = math.radians(0.5)
    drive_sigma_m: float = 0.30
    drive_sigma_rad: float = math.radians(10.0)
    report_sigma_m: float = 0.015
    report_sigma_rad: float = math.radians(0.5)
    report_max_views: int = 12
    report_passes: int = 3
    report_detour_m: float = 1.5
    report_detour_above_m: float = 0.04
    first_sighting_max_offset_m: float = 1.0
    first_sighting_max_offset_rad: float = math.radians(30.0)
    refind: bool = False
    update_iterations: int = 10
    odometry_calibration: bool = True
    turn_scale_sigma: float = 0.04
    curvature_sigma_rad_per_m: float = 0.03
    turn_scale_walk_per_sqrt_rad: float = 0.002
    spin_slip_sigma: float = 0.0
    track_m: float = 0.235
    calibrated_heading_rad_per_sqrt_m: float = 0.02
    calibrated_heading_rad_per_sqrt_rad: float = 0.03
    camera_yaw_sigma_rad: float = 0.0
    range_scale_sigma: float = 0.0
    ransac: RansacConfig = field(default_factory=lambda: RansacConfig(min_matches=6, dist_max_m=0.25))

    def __post_init__(self):
        for k in (
            "sigma_along_m_per_sqrt_m",
            "sigma_cross_m_per_sqrt_m",
            "sigma_heading_rad_per_sqrt_m",
            "sigma_heading_rad_per_sqrt_rad",
            "obs_sigma_m",
            "obs_sigma_rel",
            "obs_sigma_per_m",
            "obs_sigma_rel_across",
            "obs_sigma_rad",
            "recount_m",
            "recount_rad",
            "report_detour_m",
            "report_detour_above_m",
            "turn_scale_sigma",
            "curvature_sigma_rad_per_m",
            "turn_scale_walk_per_sqrt_rad",
            "spin_slip_sigma",
            "calibrated_heading_rad_per_sqrt_m",
            "calibrated_heading_rad_per_sqrt_rad",
            "camera_yaw_sigma_rad",
            "range_scale_sigma",
        ):
            v = getattr(self, k)
            if not (math.isfinite(v) and v >= 0):
                raise ConfigError(f"LocalizerConfig.{k} must be a finite number >= 0, got {v!r}")
        if not 0.0 <= self.min_face_in_image <= 1.0:
            raise ConfigError(
                f"LocalizerConfig.min_face_in_image must be a share in [0, 1], got {self.min_face_in_image!r}"
            )
        if not 0.0 < self.gate_prob < 1.0:
            raise ConfigError(f"LocalizerConfig.gate_prob must be in (0, 1), got {self.gate_prob}")
        it = self.update_iterations
        if isinstance(it, bool) or not (isinstance(it, int) and it >= 1):
            raise ConfigError(
                f"LocalizerConfig.update_iterations must be an integer >= 1 (1: the plain EKF), "
                f"got {self.update_iterations!r}"
            )
        if not isinstance(self.refind, bool):
            raise ConfigError(f"LocalizerConfig.refind must be True or False, got {self.refind!r}")
        if not isinstance(self.shared_floor, bool):
            raise ConfigError(
                f"LocalizerConfig.shared_floor must be True or False, got {self.shared_floor!r}"
            )
        if not isinstance(self.odometry_calibration, bool):
            raise ConfigError(
                "LocalizerConfig.odometry_calibration must be True or False, "
                f"got {self.odometry_calibration!r}"
            )
        if self.spin_slip_sigma > 0 and not self.odometry_calibration:
            raise ConfigError(
                "LocalizerConfig.spin_slip_sigma > 0 needs odometry_calibration (the slip is part of it)"
            )
        for k in ("relocalize_sigma_m", "report_sigma_m", "drive_sigma_m", "drive_sigma_rad", "track_m"):
            if not getattr(self, k) > 0:
                unit = "rad" if k.endswith("_rad") else "m"
                raise ConfigError(f"LocalizerConfig.{k} must be > 0 {unit}, got {getattr(self, k)}")

    def motion_noise(self, u) -> np.ndarray:
        r"""``M(u)``: covariance (3, 3) of an odometry increment ``u``, in its own frame.

        .. math:: M = \mathrm{diag}(\sigma_a^2 d,\; \sigma_c^2 d,\;
                  \sigma_{\theta d}^2 d + \sigma_{\theta\theta}^2 |\Delta\theta|),
                  \quad d = \|[\Delta x, \Delta y]\|

        With ``odometry_calibration`` the heading's two terms are the ``calibrated_heading_*`` ones.
        """
        d = math.hypot(float(u[0]), float(u[1]))
        turn = abs(float(u[2]))
        if self.odometry_calibration:
            s_hd, s_ht = self.calibrated_heading_rad_per_sqrt_m, self.calibrated_heading_rad_per_sqrt_rad
        else:
            s_hd, s_ht = self.sigma_heading_rad_per_sqrt_m, self.sigma_heading_rad_per_sqrt_rad
        return np.diag(
            [
                self.sigma_along_m_per_sqrt_m**2 * d,
                self.sigma_cross_m_per_sqrt_m**2 * d,
                s_hd**2 * d + s_ht**2 * turn,
            ]
        )

    def observation_floor(self, z) -> np.ndarray:
        r"""Covariance (3, 3) added to every landmark observation ``z`` (see the attributes).

        Stereo measures range worse than bearing: the landmark's position error is an ellipse with its
        long axis along the line of sight ``u = [z_1, z_2] / r``, ``r = \|[z_1, z_2]\|``:

        .. math:: Q_{floor} = \begin{bmatrix} R_u\, \mathrm{diag}(s_\parallel^2, s_\perp^2)\, R_u^T & 0 \\
                              0 & \sigma_{obs,\theta}^2 \end{bmatrix}, \quad
                  s_\parallel = \sigma_{obs} + \sigma_{rel}\, r + \sigma_{r^2}\, r^2, \quad
                  s_\perp = \sigma_{obs} + \sigma_{rel,\perp}\, r

        with :math:`R_u = [u, u^\perp]` the rotation onto the line of sight.
        """
        r = math.hypot(float(z[0]), float(z[1]))
        s_along = self.obs_sigma_m + self.obs_sigma_rel * r + self.obs_sigma_per_m * r * r
        s_across = self.obs_sigma_m + self.obs_sigma_rel_across * r
        u = np.array([z[0], z[1]], float) / r if r > 0 else np.array([1.0, 0.0])  # along the line of sight
        v = np.array([-u[1], u[0]])  # across it
        Q = np.zeros((3, 3))
        Q[:2, :2] = s_along**2 * np.outer(u, u) + s_across**2 * np.outer(v, v)  # R_u diag(.) R_u^T
        Q[2, 2] = self.obs_sigma_rad**2
        return Q

    @staticmethod
    def shared_floor_covariance(R, F, n: int) -> np.ndarray:
        r"""The covariance (3, 3) to give the ``n``-th sighting of a landmark from one place, whose
        fit's own covariance ``R`` is fresh each time while the floor's error ``F`` is the same one.

        ``n`` such sightings measure the landmark to :math:`R/n + F` (the image noise averages down, the
        calibration does not), so the information they add up to must be :math:`(R/n + F)^{-1}`. Each
        update adds :math:`Q_n^{-1}`; the ``n``-th must add the difference:

        .. math:: Q_1 = R + F, \qquad
                  Q_n = \left[(R/n + F)^{-1} - (R/(n-1) + F)^{-1}\right]^{-1}

        (for scalars :math:`Q_n = (R + nF)(R + (n-1)F) / R`: a sighting whose error is mostly the floor's
        adds little the second time). The information is exact when the pose does not move between the
        sightings (the filter's linearisation the same); the mean is not the batch's (the sequential
        updates weight the first look most), unbiased but spread a little more than stated (NEES 3.0-3.7
        for chi-square 3 in tests/test_localization_shared_floor.py). A direction the difference leaves
        without information gets a variance of 1e6.
        """
        R, F = np.asarray(R, float), np.asarray(F, float)
        if n < 1:
            raise ValueError(f"the sighting's count n must be >= 1, got {n}")
        if n == 1:
            return R + F
        A = np.linalg.inv(R / n + F) - np.linalg.inv(R / (n - 1) + F)  # the n-th sighting's information
        w, V = np.linalg.eigh(0.5 * (A + A.T))
        return (V * (1.0 / np.maximum(w, 1e-6))) @ V.T


@dataclass(frozen=True)
class PlanarPoseEstimate:
    """The robot's pose estimate and its covariance.

    Attributes
    ----------
    pose : Pose2D
    Sigma : ndarray, shape (3, 3) [m^2, m rad, rad^2]
    t : float [s]
    mode : LocalizationMode
    n_updates : int
        Landmark observations the filter used so far (0: the pose is odometry alone).
    """

    pose: Pose2D
    Sigma: np.ndarray = field(repr=False)
    t: float = 0.0
    mode: LocalizationMode = LocalizationMode.LANDMARKS
    n_updates: int = 0

    @property
    def sigma_xy_m(self) -> float:
        """Standard deviation along the position ellipse's larger axis [m]."""
        return float(math.sqrt(max(np.linalg.eigvalsh(self.Sigma[:2, :2])[-1], 0.0)))

    @property
    def sigma_theta_rad(self) -> float:
        return float(math.sqrt(max(self.Sigma[2, 2], 0.0)))

    def point_sigma_m(self, p_W) -> float:
        r"""Standard deviation [m] (the larger axis) of a point ``p_W`` (x, y in W) that the robot placed
        from where it stands (an object it found): ``p_W = t + R(theta) p_R`` moves with the robot's
        position and, through the lever arm, its heading,

        .. math:: \Sigma_p = J \Sigma J^T, \quad
                  J = \begin{bmatrix} 1 & 0 & -(p_y - y) \\ 0 & 1 & p_x - x \end{bmatrix}

        Errors of position and heading can cancel or add up there: the point's, not the robot's,
        is the error a found object inherits.
        """
        dx, dy = float(p_W[0]) - self.pose.x, float(p_W[1]) - self.pose.y
        J = np.array([[1.0, 0.0, -dy], [0.0, 1.0, dx]])
        S = J @ self.Sigma @ J.T
        return float(math.sqrt(max(np.linalg.eigvalsh(S)[-1], 0.0)))


@dataclass(frozen=True)
class UpdateRecord:
    """One landmark observation the filter considered: what it saw and whether the gate let it in.

    ``x_bar``/``Sigma_bar`` before, ``x``/``Sigma`` after (equal to before when rejected); ``nis`` the
    innovation's squared Mahalanobis distance. ``kind`` is ``"update"`` (the EKF update), or for the
    first sighting of a start measured by hand (:meth:`Localizer.first_sighting`) ``"fused"`` (it agreed
    with the start: both fused), ``"reset"`` (it did not: the start replaced by the sighting's pose) or
    ``"outlier"`` (too far from the start: rejected); ``"refound"`` when a rejected sighting agreed
    with an earlier rejected one and the pose was reset from it (:mod:`lab.localization.refind`).
    """

    t: float
    landmark: str
    z: np.ndarray = field(repr=False)
    Q: np.ndarray = field(repr=False)
    x_bar: np.ndarray = field(repr=False)
    Sigma_bar: np.ndarray = field(repr=False)
    x: np.ndarray = field(repr=False)
    Sigma: np.ndarray = field(repr=False)
    nis: float = 0.0
    accepted: bool = True
    n_inliers: int = 0
    kind: str = "update"


@dataclass
class _Clone:
    """A past pose kept in the localizer's state: its mean ``x``, covariance ``Sigma`` and its
    cross-covariance ``cross`` = Cov(s_now, x_clone) (n, 3) with the moving state (the pose, and the
    odometry's calibration when it is estimated)."""

    x: np.ndarray
    Sigma: np.ndarray
    cross: np.ndarray

    def update(self, P_bar, H, S, Q, v) -> None:
        """The clone's part of an accepted update (:meth:`Localizer.start_clone`): the joint state
        ``[s, x_c]`` with prior covariance ``P = [[P_bar, cross], [cross^T, Sigma]]`` and
        ``H_joint = [H, 0]`` (``H`` is (3, n)); ``K_joint = P H_joint^T S^-1``, ``x_c += K_c v``,
        Joseph form."""
        n = P_bar.shape[0]
        P = np.block([[P_bar, self.cross], [self.cross.T, self.Sigma]])
        Hj = np.hstack([H, np.zeros((3, 3))])
        Kj = np.linalg.solve(S, Hj @ P).T  # (n + 3, 3)
        self.x = self.x + Kj[n:] @ v
        self.x[2] = wrap_angle(self.x[2])
        IKH = np.eye(n + 3) - Kj @ Hj
        P = IKH @ P @ IKH.T + Kj @ Q @ Kj.T
        P = 0.5 * (P + P.T)
        self.Sigma, self.cross = P[n:, n:], P[:n, n:]


class Localizer:
    """The EKF over ``x = [x, y, theta]`` (see the module docstring for its equations), and with
    ``config.odometry_calibration`` over ``s = [x, y, theta, k, c]``: the pose and the odometry's turn
    scale and curvature bias (:func:`calibrated_motion_model`), which the landmark updates estimate
    through their correlation with the heading (a landmark sees the pose only: ``H = [H_x, 0]``); with
    ``config.spin_slip_sigma`` above 0, ``[x, y, theta, k, c, sigma]``, the spin's slip too
    (:attr:`spin_slip`).

    ``x`` and ``Sigma`` are the pose's mean and covariance (the first three of ``s`` and ``P``);
    :attr:`calibration` the odometry's; :meth:`landmark_estimates` a surveyed map's posters, which join
    ``s`` after these at their first sighting (:mod:`lab.localization.posters`).

    Parameters
    ----------
    x0 : array_like, shape (3,)
        The start pose [m, m, rad] (the odometry's origin: the run starts aligned with the world).
    Sigma0 : array_like, shape (3, 3), optional
        Its covariance (default: 1 cm, 0.5 deg).
    config : LocalizerConfig, optional
    first_sighting : bool
        The start was measured by hand (a real robot stood at a taped mark): the first landmark
        observation goes through :meth:`first_sighting` instead of the EKF update, so that a start that
        is off by more than ``Sigma0`` says is corrected, not locked out by the gate.

    A past pose can be kept in the state (stochastic cloning, :meth:`start_clone`): the robot found an
    object where no landmark was in view, drives to one, and the landmark corrects the pose it found
    the object from too (:meth:`cloned_estimate`).
    """

    def __init__(self, x0, Sigma0=None, config: LocalizerConfig | None = None, first_sighting: bool = False):
        self.config = c = config or LocalizerConfig()
        self.first_sighting_pending = bool(first_sighting)
        # the robot's part of the state (the pose, the odometry's calibration); posters follow
        self._m = n = (6 if c.spin_slip_sigma > 0 else 5) if c.odometry_calibration else 3
        self.posters = PosterStates(n)  # the surveyed posters in the state (lab.localization.posters)
        self.s = np.zeros(n)
        self.P = np.zeros((n, n))
        self.x = x0
        self.Sigma = (
            np.diag([0.01**2, 0.01**2, math.radians(0.5) ** 2]) if Sigma0 is None else np.array(Sigma0, float)
        )
        if n >= 5:  # the calibration's prior: nominal odometry, give or take its sigmas
            self.s[3:5] = (1.0, 0.0)
            self.P[3, 3], self.P[4, 4] = c.turn_scale_sigma**2, c.curvature_sigma_rad_per_m**2
        if n == 6:
            self.P[5, 5] = c.spin_slip_sigma**2
        self.camera_yaw = None  # its index in the state, when estimated (camera_yaw_sigma_rad)
        if c.camera_yaw_sigma_rad > 0:
            self.s, self.P, self.camera_yaw = self.posters.augment_camera(
                self.s, self.P, c.camera_yaw_sigma_rad, "camera's yaw"
            )
        self.range_scale = None  # its index in the state, when estimated (range_scale_sigma)
        if c.range_scale_sigma > 0:
            self.s, self.P, self.range_scale = self.posters.augment_camera(
                self.s, self.P, c.range_scale_sigma, "range scale"
            )
        self.history: list[UpdateRecord] = []
        self.rejected_in_a_row = 0
        self.n_inflations = 0
        self.n_refinds = 0  # poses reset from rejected sightings that agree (config.refind)
        self.refinder = (
            Refinder(chi2_quantile(c.gate_prob, 3), c.drive_sigma_m, c.drive_sigma_rad) if c.refind else None
        )
        self._rejected_here: set[str] = set()  # landmarks whose rejection counted since the last move
        self._moved = np.zeros(2)  # driven [m] and turned [rad] since then
        self._seen_here: dict[str, int] = {}  # accepted sightings per landmark since then (shared_floor)
        self._clone: _Clone | None = None  # a past pose kept in the state (start_clone)

    # the pose: the first three of the state
    @property
    def x(self) -> np.ndarray:
        """The pose's mean ``[x, y, theta]`` (a copy; assign to set it)."""
        return self.s[:3].copy()

    @x.setter
    def x(self, value) -> None:
        self.s[:3] = np.asarray(value, float).reshape(3)

    @property
    def Sigma(self) -> np.ndarray:
        """The pose's covariance (3, 3) (a copy; assigning it sets the pose's block and forgets its
        correlation with the rest of the state: the calibration, the posters)."""
        return self.P[:3, :3].copy()

    @Sigma.setter
    def Sigma(self, value) -> None:
        self.P[:3, :3] = np.asarray(value, float).reshape(3, 3)
        self.P[:3, 3:] = 0.0
        self.P[3:, :3] = 0.0

    @property
    def calibration(self) -> tuple[float, float, float, float] | None:
        """The odometry's turn scale ``k``, curvature bias ``c`` [rad/m] and their standard deviations,
        or None without ``odometry_calibration``."""
        if self._m == 3:
            return None
        return (float(self.s[3]), float(self.s[4]), math.sqrt(self.P[3, 3]), math.sqrt(self.P[4, 4]))

    @property
    def spin_slip(self) -> tuple[float, float] | None:
        """The spin's slip ``sigma`` (a turn in place over-counts by about this more than a drive's turn)
        and its standard deviation, or None when it is not in the state (``spin_slip_sigma`` 0)."""
        if self._m != 6:
            return None
        return float(self.s[5]), math.sqrt(self.P[5, 5])

    @property
    def camera_yaw_estimate(self) -> tuple[float, float] | None:
        """The camera's yaw on the base [rad] and its standard deviation, or None when it is not in the
        state (``camera_yaw_sigma_rad`` 0)."""
        if self.camera_yaw is None:
            return None
        b = self.camera_yaw
        return float(self.s[b]), math.sqrt(self.P[b, b])

    @property
    def range_scale_estimate(self) -> tuple[float, float] | None:
        """The stereo's range scale error (a sighting's range is ``1 +`` this times the true one) and its
        standard deviation, or None when it is not in the state (``range_scale_sigma`` 0)."""
        if self.range_scale is None:
            return None
        g = self.range_scale
        return float(self.s[g]), math.sqrt(self.P[g, g])

    def camera_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """The camera's planar pose ``[x, y, theta + beta]`` and its covariance (3, 3): the base's
        position with its heading turned by the camera's yaw on the base ``beta`` (when it is in the
        state), ``J P J^T`` with ``J`` summing the two headings. What a frame places in the world hangs on
        this heading (the yaw turns the camera about the pan axis, over the base's origin), so a found
        point's deviation and the re-localization's thresholds are this pose's. The base's pose and
        covariance (:attr:`x`, :attr:`Sigma`) when the yaw is not in the state."""
        if self.camera_yaw is None:
            return self.x, self.Sigma
        b = self.camera_yaw
        J = np.zeros((3, self.s.size))
        J[0, 0] = J[1, 1] = J[2, 2] = J[2, b] = 1.0
        x = self.x
        x[2] = wrap_angle(x[2] + self.s[b])
        return x, J @ self.P @ J.T

    @property
    def n_updates(self) -> int:
        return sum(1 for r in self.history if r.accepted)

    def predict(self, u) -> None:
        """Prediction from an odometry increment ``u`` (3,).

        ``s_bar = f(s, u)``, ``P_bar = F P F^T + V M V^T`` (+ the turn scale's walk when calibrating)."""
        c, m = self.config, self._m
        if m == 3:
            F, V = motion_jacobians(self.s[:3], u)
            s_bar = motion_model(self.s[:3], u)
        else:
            F, V = calibrated_motion_jacobians(self.s[:m], u, 0.5 * c.track_m)
            s_bar = calibrated_motion_model(self.s[:m], u, 0.5 * c.track_m)
        # P_bar = F P F^T + V M V^T with F = blockdiag(F, I): the posters stay where they are
        P = self.P.copy()
        P[:m] = F @ P[:m]
        P[:, :m] = P[:, :m] @ F.T
        P[:m, :m] += V @ c.motion_noise(u) @ V.T
        if m >= 5:
            P[3, 3] += c.turn_scale_walk_per_sqrt_rad**2 * abs(float(u[2]))
        self.s, self.P = np.concatenate([s_bar, self.s[m:]]), 0.5 * (P + P.T)
        if self._clone is not None:  # the clone stays where it was: Cov(s_bar, x_c) = F Cov(s, x_c)
            self._clone.cross[:m] = F @ self._clone.cross[:m]
        if self.refinder is not None:  # the rejected sightings' poses, carried along
            walk = c.turn_scale_walk_per_sqrt_rad if m >= 5 else 0.0
            self.refinder.predict(u, c.motion_noise(u), walk, 0.5 * c.track_m)
        self._moved += (math.hypot(u[0], u[1]), abs(u[2]))
        if self._moved[0] >= self.config.recount_m or self._moved[1] >= self.config.recount_rad:
            self._rejected_here.clear()  # a new place: every landmark's rejection counts again
            self._seen_here.clear()  # and its sightings bring a fresh view of the floor's error
            self._moved[:] = 0.0
            if self.refinder is not None:
                self.refinder.place += 1

    def update(self, z, Q, landmark: Landmark, t: float = 0.0, n_inliers: int = 0) -> UpdateRecord:
        """Update from one landmark observation ``z`` (3,) with covariance ``Q`` (3, 3); gated.

        While the first sighting of a hand-measured start is pending (``first_sighting=True`` and no
        observation accepted yet) this is :meth:`first_sighting`."""
        if self.first_sighting_pending:
            return self.first_sighting(z, Q, landmark, t, n_inliers)
        z = np.asarray(z, float)
        Q = self._sighting_covariance(z, Q, landmark)
        j = self._poster_block(landmark)  # H = [dh/dx, 0, (dh/dl_j)]: the pose, a surveyed poster
        x_bar, Sigma_bar = self.x, self.Sigma
        s_bar, P_bar = self.s.copy(), self.P.copy()
        n, angles = len(s_bar), self.posters.angles()
        h, H = observe(s_bar, landmark, j, self.camera_yaw, self.range_scale)
        nu = z - h  # innovation
        nu[2] = wrap_angle(nu[2])
        S = H @ P_bar @ H.T + Q  # innovation covariance
        nis = float(nu @ np.linalg.solve(S, nu))
        accepted = nis <= chi2_quantile(self.config.gate_prob, 3)
        if accepted:
            # the iterated EKF: from s_0 = s_bar (whose step is the plain EKF's, K nu, with the gate's H
            # and S), relinearise at each new mean until it stops moving
            s_i = s_bar.copy()
            for i in range(self.config.update_iterations):
                h, H_i = observe(s_i, landmark, j, self.camera_yaw, self.range_scale)
                if i > 0:
                    H = H_i
                    S = H @ P_bar @ H.T + Q
                K = np.linalg.solve(S, H @ P_bar).T  # K = P_bar H^T S^-1 (S, P_bar symmetric)
                r = z - h
                r[2] = wrap_angle(r[2])
                ds = s_bar - s_i
                ds[angles] = wrap_angle(ds[angles])
                v = r - H @ ds  # the iterated EKF's innovation at s_i
                s_next = s_bar + K @ v
                s_next[angles] = wrap_angle(s_next[angles])
                step = s_next - s_i
                step[angles] = wrap_angle(step[angles])
                s_i = s_next
                if np.max(np.abs(step)) < 1e-9:  # [m], [rad]: converged
                    break
            IKH = np.eye(n) - K @ H
            P = IKH @ P_bar @ IKH.T + K @ Q @ K.T  # Joseph form
            if self._clone is not None:
                self._clone.update(P_bar, H, S, Q, v)
            self.s, self.P = s_i, 0.5 * (P + P.T)
            self.rejected_in_a_row = 0
            self._seen_here[landmark.name] = self._seen_here.get(landmark.name, 0) + 1
            if self.refinder is not None:
                self.refinder.clear()  # the estimate is not lost
        elif self._refind(z, Q, landmark, j):
            return self._record(t, landmark, z, Q, x_bar, Sigma_bar, nis, True, n_inliers, "refound")
        elif landmark.name not in self._rejected_here:  # once per landmark per place (recount_m)
            self._rejected_here.add(landmark.name)
            self.rejected_in_a_row += 1
            if self.rejected_in_a_row >= self.config.max_rejected_in_a_row:  # gate lock-out recovery
                # the pose's variance times reject_inflation (D P D: its correlations scale along)
                d = np.ones(n)
                d[:3] = math.sqrt(self.config.reject_inflation)
                self.P = d[:, None] * self.P * d[None, :]
                self.rejected_in_a_row = 0
                self.n_inflations += 1
                self._rejected_here.clear()  # the doubted estimate is tried against them all again
        return self._record(t, landmark, z, Q, x_bar, Sigma_bar, nis, bool(accepted), n_inliers)

    def _refind(self, z, Q, landmark: Landmark, j: int | None) -> bool:
        r"""Keep a rejected sighting for re-finding a lost robot; when it agrees with a kept one as
        independent evidence, reset the pose from it and say True (:mod:`lab.localization.refind`).

        The reset is :meth:`first_sighting`'s: :math:`x = x_z(l)`,
        :math:`\mathrm{Cov}(x, y) = J_l \mathrm{Cov}(l, y)`, :math:`\mathrm{Cov}(x) = J_z Q J_z^T +
        J_l \mathrm{Cov}(l) J_l^T`; a kept pose clone's cross-covariance with it is :math:`J_l` times its
        cross-covariance with the state. The odometry's calibration keeps its estimate."""
        if self.refinder is None:
            return False
        x_z, Sigma_z, Jl = sighting_pose(self.s, z, Q, landmark, j, self.camera_yaw, self.range_scale)
        m = self._m
        r, C = np.concatenate([x_z, self.s[3:m]]), np.zeros((m, m))
        C[:3, :3], C[3:, 3:] = Sigma_z, self.P[3:m, 3:m]
        new = RejectedSighting(landmark.name, self.refinder.place, r, C, Jl)
        if self.refinder.add(new, self.P) is None:
            return False
        P_bar, row = self.P.copy(), Jl @ self.P
        if self._clone is not None:
            self._clone.cross[:3] = Jl @ self._clone.cross
        self.s[:3] = x_z
        self.P[:3, :], self.P[:, :3] = row, row.T
        self.P[:3, :3] = Sigma_z + Jl @ P_bar @ Jl.T
        self.P = 0.5 * (self.P + self.P.T)
        self.refinder.clear()
        self.rejected_in_a_row, self.n_refinds = 0, self.n_refinds + 1
        self._rejected_here.clear()
        return True

    def _sighting_covariance(self, z, Q, landmark: Landmark) -> np.ndarray:
        """An observation's covariance: the fit's own ``Q`` plus the floor, the floor shared with this
        landmark's earlier sightings from the same place (``LocalizerConfig.shared_floor``)."""
        F = self.config.observation_floor(z)
        n = self._seen_here.get(landmark.name, 0) + 1 if self.config.shared_floor else 1
        return LocalizerConfig.shared_floor_covariance(np.asarray(Q, float), F, n)

    def _poster_block(self, landmark: Landmark) -> int | None:
        """The index of a surveyed landmark's block in the state, added (seeded by its survey,
        :meth:`PosterStates.augment`) at its first observation; None for a landmark held fixed."""
        j = self.posters.index_of(landmark)
        if j is None and landmark.surveyed:
            self.s, self.P, j = self.posters.augment(self.s, self.P, landmark)
            if self._clone is not None:  # the new block is independent of the kept pose
                self._clone.cross = np.vstack([self._clone.cross, np.zeros((3, 3))])
        return j

    def seed_posters(self, landmarks) -> None:
        """Put every poster of a room surveyed once in the state now, seeded by the map's poses and its
        joint prior (``landmarks.joint_prior``, :mod:`lab.localization.stored_survey`), instead of each
        poster's own survey at its first sighting. Call it before any update."""
        names, L = landmarks.joint_prior
        if self.history or self._clone is not None:
            raise ValueError("the posters are seeded before the first update")
        self.s, self.P = self.posters.augment_all(self.s, self.P, [landmarks.get(k) for k in names], L)

    def landmark_estimates(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """The surveyed posters in the state, as refined so far: ``[x, y, yaw]`` and covariance (3, 3)
        by name (an exact map's landmarks, held fixed, are not in it)."""
        return self.posters.estimates(self.s, self.P)

    def _record(self, t, landmark, z, Q, x_bar, Sigma_bar, nis, accepted, n_inliers, kind="update"):
        """Keep what an observation did, with the filter's state after it, in :attr:`history`."""
        rec = UpdateRecord(
            t, landmark.name, z, Q, x_bar, Sigma_bar, self.x, self.Sigma, nis, accepted, int(n_inliers), kind
        )
        self.history.append(rec)
        return rec

    # stochastic cloning: a past pose kept in the state

    def start_clone(self) -> None:
        r"""Keep the pose now, :math:`x_c = x`, in the state beside the moving pose (stochastic cloning).

        The joint covariance starts as :math:`\begin{bmatrix} \Sigma & \Sigma \\ \Sigma & \Sigma
        \end{bmatrix}` (both are the same pose). A prediction moves :math:`x` only, so the
        cross-covariance becomes :math:`F\, \Sigma_{xc}`; an update corrects both through the joint
        Kalman gain, the measurement seeing :math:`x` alone (:math:`H_{joint} = [H, 0]`):

        .. math:: K_c = \Sigma_{xc}^T H^T S^{-1}, \qquad x_c \leftarrow x_c + K_c\, \nu

        with :math:`\nu` the update's innovation (the iterated EKF's, at its last iterate), and the
        joint covariance in Joseph form. A landmark seen after a short drive thus corrects the pose the
        drive began from, as far as the odometry between the two ties them.

        Raises
        ------
        ValueError
            While the first sighting of a hand-measured start is pending (it may replace the pose
            outright, which no cross-covariance describes).
        """
        if self.first_sighting_pending:
            raise ValueError("cannot clone the pose before the first landmark sighting of a measured start")
        self._clone = _Clone(self.x, self.Sigma, self.P[:, :3].copy())

    @property
    def cloning(self) -> bool:
        return self._clone is not None

    def cloned_estimate(self, camera: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """The kept pose ``x_c`` (3,) and its covariance (3, 3), as corrected since :meth:`start_clone`;
        with ``camera``, the camera's pose then (as :meth:`camera_pose`: its heading turned by the
        camera's yaw on the base as estimated now, with the yaw's covariance with the kept pose)."""
        if self._clone is None:
            raise ValueError("no pose is cloned (start_clone)")
        x, C = self._clone.x.copy(), self._clone.Sigma.copy()
        if camera and self.camera_yaw is not None:
            b = self.camera_yaw
            v = self._clone.cross[b]  # Cov(beta, x_c)
            x[2] = wrap_angle(x[2] + self.s[b])
            C[:, 2] += v
            C[2, :] += v
            C[2, 2] += self.P[b, b]
        return x, C

    def end_clone(self, camera: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Drop the kept pose; returns it and its covariance (:meth:`cloned_estimate`)."""
        out = self.cloned_estimate(camera)
        self._clone = None
        return out

    def first_sighting(self, z, Q, landmark: Landmark, t: float = 0.0, n_inliers: int = 0) -> UpdateRecord:
        r"""The first landmark observation of a start measured by hand: fuse it with the start, or let it
        replace the start.

        One observation of a (unique) landmark determines the whole planar pose,
        :math:`x_z = h^{-1}(z; l)` with covariance :math:`\Sigma_z = J Q J^T`
        (:func:`pose_from_observation`), so the prior can be compared with it in the pose's own space,
        where nothing is linearised about a start that may be wrong by 10 degrees:

        .. math:: d = x_z - \bar x, \quad S = \bar\Sigma + \Sigma_z, \quad
                  d^T S^{-1} d \le \chi^2_3(p_{gate})

        * within the gate, both are fused (the Kalman update with :math:`H = I`:
          :math:`K = \bar\Sigma S^{-1}`, :math:`x = \bar x + K d`, Joseph form): ``kind="fused"``;
        * beyond it the start, not the landmark, is the likelier culprit (a robot stood 30 cm off its mark
          by a start covariance that says 10 cm): the sighting's pose replaces it, :math:`x = x_z`,
          :math:`\Sigma = \Sigma_z` (``kind="reset"``), provided it is within
          ``first_sighting_max_offset_m`` and ``_rad`` of the start; farther, it is rejected as an outlier
          (a wrong fit) and the next sighting is tried the same way.

        Later observations go through the EKF :meth:`update`. A surveyed landmark (in the state) enters
        both through :math:`J_l = \partial x_z / \partial l` (:mod:`lab.localization.posters`): the
        fusion's ``H = [I, 0, -J_l]``; a reset's pose keeps its correlation with the landmark.
        """
        z = np.asarray(z, float)
        Q = self._sighting_covariance(z, Q, landmark)
        j = self._poster_block(landmark)
        x_bar, Sigma_bar = self.x, self.Sigma
        P_bar = self.P.copy()
        n = len(self.s)
        x_z, Sigma_z, Jl = sighting_pose(
            self.s, z, Q, landmark, j, self.camera_yaw, self.range_scale
        )  # Sigma_z = J_z Q J_z^T
        d = x_z - x_bar
        d[2] = wrap_angle(d[2])
        Hf = -Jl  # d = x - x_z(l): H = [I, 0, -J_l] (no poster: [I, 0])
        Hf[:, :3] = np.eye(3)
        S = Hf @ P_bar @ Hf.T + Sigma_z
        nis = float(d @ np.linalg.solve(S, d))
        cfg = self.config
        kind = "fused"
        accepted = True
        if nis <= chi2_quantile(cfg.gate_prob, 3):
            K = np.linalg.solve(S, Hf @ P_bar).T  # K = P_bar H^T S^-1 (n, 3)
            s_new = self.s + K @ d
            IKH = np.eye(n) - K @ Hf
            P = IKH @ P_bar @ IKH.T + K @ Sigma_z @ K.T  # Joseph form
            angles = self.posters.angles()
            s_new[angles] = wrap_angle(s_new[angles])
            self.s, self.P = s_new, 0.5 * (P + P.T)
        elif math.hypot(d[0], d[1]) <= cfg.first_sighting_max_offset_m and abs(d[2]) <= (
            cfg.first_sighting_max_offset_rad
        ):
            kind = "reset"  # the pose from the sighting; the calibration keeps its prior
            # x = x_z(l): Cov(x, y) = J_l Cov(l, y), Cov(x) = J_z Q J_z^T + J_l Cov(l) J_l^T
            row = Jl @ P_bar
            self.s[:3] = x_z
            self.P[:3, :], self.P[:, :3] = row, row.T
            self.P[:3, :3] = Sigma_z + Jl @ P_bar @ Jl.T
            self.P = 0.5 * (self.P + self.P.T)
        else:
            kind, accepted = "outlier", False  # rejected
        if accepted:
            self.first_sighting_pending = False
            self._seen_here[landmark.name] = self._seen_here.get(landmark.name, 0) + 1
        return self._record(t, landmark, z, Q, x_bar, Sigma_bar, nis, accepted, n_inliers, kind)
