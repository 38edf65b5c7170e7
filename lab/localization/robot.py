"""The localized robot: the localizer behind the :class:`~lab.robot.Robot` interface.

:class:`LocalizedRobot`'s ``odometry()`` and every frame's ``odom`` are the filter's estimate, so the
navigator's costmap and path following, the search's map and the object poses it reports all use the
localized pose without a change; :meth:`LocalizedRobot.pose_estimate` adds the covariance. With
``mode=odometry`` it passes the wheel odometry through unchanged (and still reports the covariance of
dead reckoning). It also chooses where to look and where to stand to see a landmark: the head views of
an active re-localization (:meth:`LocalizedRobot.landmark_views`) and the vantage points of a detour
before a report (:meth:`LocalizedRobot.landmark_vantage_points`).
"""

from __future__ import annotations

import math
import sys
from dataclasses import replace

import numpy as np

from lab.errors import ConfigError
from lab.geometry import Pose2D, wrap_angle
from lab.localization.filter import Localizer, LocalizerConfig, PlanarPoseEstimate
from lab.localization.landmarks import LandmarkMap
from lab.localization.models import odometry_increment
from lab.localization.modes import LocalizationMode
from lab.localization.observer import LandmarkObserver
from lab.localization.stamps import OdometryHistory, PanTiltHistory
from lab.mounts import MAX_MOUNT_DEG, MountedCamera, with_head_yaw
from lab.robot import PanTiltState, Robot, RobotWrapper

__all__ = ["LocalizedRobot"]


class LocalizedRobot(RobotWrapper):
    """A :class:`~lab.robot.Robot` whose ``odometry()`` and frames' ``odom`` are the localizer's estimate.

    Its frames keep the base's wheel odometry in ``wheel_odom``: the object filters predict with the
    wheels' increment between two frames (:func:`lab.robot.frame_motion`), since a landmark update moves
    the estimate, not the robot.

    A frame is used at its image's stamp: ``frame.t - camera_latency_s``. When the head and odometry
    were read later than that (``frame.pan_tilt.t``: a camera's latency, stated to the robot, or a base
    that stamps its frames with the image's exposure but reads later), the odometry is taken back to the
    image's stamp from the readings the localizer keeps (:attr:`odometry_history`,
    :meth:`wheels_at_image`), and the frame's ``odom`` and ``wheel_odom`` (what the search places
    objects from, what the object filters predict with) are the pose at the image's stamp.

    Every call is passed on to ``base``. With ``mode=LANDMARKS`` each captured frame in which a landmark
    should be visible updates the filter; ``relocalize()`` points the head at landmarks until the pose
    is certain again (active re-localization). With ``mode=ODOMETRY`` the base's odometry is passed
    through unchanged and frames are not looked at (the filter only reports dead reckoning's covariance).

    Parameters
    ----------
    base : Robot
    mode : LocalizationMode or str
    landmarks : LandmarkMap, optional
        A trained map; needed for ``landmarks`` mode.
    config : LocalizerConfig, optional
    rng : numpy.random.Generator, optional
    log : callable(str), optional
        Where the localizer says what it does (default: stderr).
    Sigma0 : array_like, shape (3, 3), optional
        The covariance of the start, ``base.odometry()`` when this is made (default: the
        :class:`Localizer`'s, 1 cm and 0.5 deg: the simulator's odometry starts at the true pose).
    camera_latency_s : float [s]
        How much older an image is than its frame's stamp ``frame.t`` (a camera's measured mean latency:
        a USB camera's frame is 30-100 ms old on arrival); 0 for a base whose frames are stamped at the
        image's exposure (the hardware interpolates its readings to it, ``lab.hardware.frame_time``).
    start_measured_by_hand : bool
        The start is a pose an operator measured (a robot's): the first landmark sighting may correct it
        (:meth:`Localizer.first_sighting`).
    """

    def __init__(
        self,
        base: Robot,
        mode="landmarks",
        landmarks: LandmarkMap | None = None,
        config: LocalizerConfig | None = None,
        rng: np.random.Generator | None = None,
        log=None,
        *,
        Sigma0=None,
        start_measured_by_hand: bool = False,
        camera_latency_s: float = 0.0,
    ):
        super().__init__(base)
        self.mode = LocalizationMode.parse(mode)
        self.config = config or LocalizerConfig()
        self._odom = base.odometry()
        if not (math.isfinite(camera_latency_s) and 0.0 <= camera_latency_s <= 1.0):
            raise ConfigError(f"camera_latency_s must be within [0, 1] s, got {camera_latency_s!r}")
        self.camera_latency_s = float(camera_latency_s)
        self.odometry_history = OdometryHistory()  # the base's stamped readings: wheels_at_image
        self.pan_tilt_history = PanTiltHistory()  # the head's, with a camera latency: head_at_image
        self.odometry_history.add(base.now(), self._odom)
        self.localizer = Localizer(
            self._odom.as_array(), Sigma0, config=self.config, first_sighting=start_measured_by_hand
        )
        self.observer = None
        if self.mode is LocalizationMode.LANDMARKS:
            if landmarks is None or len(landmarks) == 0:
                raise ConfigError(
                    "localization 'landmarks' needs a trained landmark map with at least one landmark"
                )
            self.observer = LandmarkObserver(landmarks, self.config, rng or np.random.default_rng(0))
            if landmarks.joint_prior is not None:  # a room surveyed once: its posters, correlated
                self.localizer.seed_posters(landmarks)
        self.log = log or (lambda msg: print(f"lab: {msg}", file=sys.stderr))
        self.frames_seen = 0

    # the estimate
    def _sync(self, odom: Pose2D | None = None) -> None:
        """Predict the filter to the base's odometry now (kept in the history), or to ``odom`` (a
        frame's: possibly older than the last, then the increment runs backwards)."""
        if odom is None:
            odom = self.base.odometry()
            self.odometry_history.add(self.base.now(), odom)
        u = odometry_increment(self._odom, odom)
        if np.any(u != 0.0):
            self.localizer.predict(u)
        self._odom = odom

    def _pose(self) -> Pose2D:
        if self.mode is LocalizationMode.ODOMETRY:
            return self._odom
        return Pose2D(*(float(v) for v in self.localizer.x))

    def pose_estimate(self) -> PlanarPoseEstimate:
        """The robot's pose estimate and covariance now."""
        self._sync()
        return PlanarPoseEstimate(
            self._pose(), self.localizer.Sigma.copy(), self.base.now(), self.mode, self.localizer.n_updates
        )

    def camera_pose_estimate(self) -> PlanarPoseEstimate:
        """The pose a frame is placed from now: the base's position with the camera's heading (the base's
        turned by the camera's estimated yaw on the base, :meth:`Localizer.camera_pose`) and its
        covariance. The same as :meth:`pose_estimate` when the yaw is not in the filter's state. Whether
        the robot may map and report (:meth:`certain`) and how well it knows a found object are this
        pose's; driving (:meth:`drive_guard`) is the base's."""
        self._sync()
        if self.mode is LocalizationMode.ODOMETRY:
            return self.pose_estimate()
        x, S = self.localizer.camera_pose()
        return PlanarPoseEstimate(
            Pose2D(*(float(v) for v in x)), S, self.base.now(), self.mode, self.localizer.n_updates
        )

    def odometry(self) -> Pose2D:
        """The pose estimate (the localized pose, or the wheel odometry in ``odometry`` mode)."""
        self._sync()
        return self._pose()

    def odometry_calibration(self) -> dict | None:
        """What the filter learned of the base's odometry (:attr:`Localizer.calibration`), for a run's
        JSON and the operator: ``turn_scale`` (the true turn per turn the wheels report; 0.96 means
        they over-count turns by about 4 %), ``curvature_rad_per_m`` and their standard deviations;
        with the spin's slip in the state, ``spin_slip`` and ``spin_slip_sd`` too (a turn in place
        over-counts by about that much more than a drive's). None with ``mode=odometry`` or without
        ``odometry_calibration``."""
        cal = self.localizer.calibration
        if self.mode is LocalizationMode.ODOMETRY or cal is None:
            return None
        k, c, sk, sc = cal
        out = {
            "turn_scale": round(k, 5),
            "turn_scale_sd": round(sk, 5),
            "curvature_rad_per_m": round(c, 5),
            "curvature_sd_rad_per_m": round(sc, 5),
        }
        slip = self.localizer.spin_slip
        if slip is not None:
            out["spin_slip"], out["spin_slip_sd"] = round(slip[0], 5), round(slip[1], 5)
        return out

    def camera_estimate(self) -> dict | None:
        """What the filter learned of the camera's constants that every sighting shares, for a run's JSON
        and the operator: its yaw on the base (``yaw_deg``, ``yaw_sd_deg``: the pan zero and the mounts'
        yaw) and the stereo's range scale (``range_scale``, ``range_scale_sd``: 0.005 means every range
        came out 0.5 % long), each when it is in the state. None with ``mode=odometry`` or when neither
        is (:class:`LocalizerConfig`'s ``camera_yaw_sigma_rad`` and ``range_scale_sigma``)."""
        yaw, scale = self.localizer.camera_yaw_estimate, self.localizer.range_scale_estimate
        if self.mode is LocalizationMode.ODOMETRY or (yaw is None and scale is None):
            return None
        out = {}
        if yaw is not None:
            out.update(yaw_deg=round(math.degrees(yaw[0]), 4), yaw_sd_deg=round(math.degrees(yaw[1]), 4))
        if scale is not None:
            out.update(range_scale=round(scale[0], 6), range_scale_sd=round(scale[1], 6))
        return out

    def refined_landmarks(self) -> dict[str, dict]:
        """What the filter learned of a surveyed map (:meth:`Localizer.landmark_estimates`), for a run's
        JSON and the operator, by poster: its refined ``x_m``, ``y_m``, ``yaw_deg``, their standard
        deviations ``sd_m`` (the larger axis) and ``sd_deg``, and how far it moved from the map
        (``moved_m``, ``turned_deg``: a survey that far off). Empty for an exact map (held fixed) and
        with ``mode=odometry``."""
        if self.mode is LocalizationMode.ODOMETRY:
            return {}
        out = {}
        for name, (l, L) in self.localizer.landmark_estimates().items():
            mapped = self.observer.map.get(name).planar
            out[name] = {
                "x_m": round(float(l[0]), 5),
                "y_m": round(float(l[1]), 5),
                "yaw_deg": round(math.degrees(l[2]), 4),
                "sd_m": round(math.sqrt(max(np.linalg.eigvalsh(L[:2, :2])[-1], 0.0)), 5),
                "sd_deg": round(math.degrees(math.sqrt(L[2, 2])), 4),
                "moved_m": round(math.hypot(l[0] - mapped[0], l[1] - mapped[1]), 5),
                "turned_deg": round(math.degrees(wrap_angle(l[2] - mapped[2])), 4),
            }
        return out

    def wheel_odometry(self) -> Pose2D:
        """The base's wheel odometry, which the estimate starts from (in the base's frame)."""
        return self.base.odometry()

    def wheels_at_image(self, frame) -> Pose2D:
        """The base's wheel odometry at the image's stamp ``frame.t - camera_latency_s``.

        The frame's own odometry (``frame.wheels``) was read at ``frame.pan_tilt.t``; when that is later
        than the image, the history of readings is interpolated back to the image's stamp along the
        constant-velocity arc (:meth:`OdometryHistory.at`). A base that gives the odometry at the
        image's stamp (the hardware interpolates it, ``lab.hardware.frame_time``; no latency) has
        ``pan_tilt.t == t``, and its reading is used as it is."""
        t_read, t_image = frame.pan_tilt.t, frame.t - self.camera_latency_s
        self.odometry_history.add(t_read, frame.wheels)
        return frame.wheels if t_read <= t_image else self.odometry_history.at(t_image)

    def head_at_image(self, frame) -> PanTiltState:
        """The head's state when the frame's image was exposed, ``frame.t - camera_latency_s``: the
        frame's reading (``frame.pan_tilt``, at its ``t``) when it is not later, else the head's readings
        (kept at every :meth:`step` when there is a camera latency) interpolated back to the image's
        stamp: a head slewing at 60 deg/s is 3 deg past where a 50 ms old image shows it."""
        t_image = frame.t - self.camera_latency_s
        if frame.pan_tilt.t <= t_image:
            return frame.pan_tilt
        self.pan_tilt_history.add(frame.pan_tilt.t, frame.pan_tilt)
        return self.pan_tilt_history.at(t_image)

    def capture_stereo(self, after=None):
        frame = self.base.capture_stereo(after)
        wheels = self.wheels_at_image(frame)  # both read at frame.pan_tilt.t, taken to the image's stamp
        head = self.head_at_image(frame)
        if head is not frame.pan_tilt:  # G_RC at the image's stamp: for the landmarks and the search
            frame = replace(frame, pan_tilt=head)
        self._sync(wheels)
        if self.mode is LocalizationMode.ODOMETRY:  # the wheels at the image's stamp
            return frame if wheels is frame.wheels else replace(frame, odom=wheels)
        self.frames_seen += 1
        cands = self.observer.candidates(self.localizer.x, frame)
        for obs in self.observer.observe(frame, cands):
            rec = self.localizer.update(obs.z, obs.Q, obs.landmark, frame.t, obs.n_inliers)
            if not rec.accepted:
                self.log(f"localization: rejected {obs.landmark.name} (NIS {rec.nis:.1f}, an outlier)")
            elif rec.kind in ("reset", "refound"):
                dx, dy = rec.x[:2] - rec.x_bar[:2]
                dth = math.degrees(wrap_angle(rec.x[2] - rec.x_bar[2]))
                off = f"{100 * math.hypot(dx, dy):.0f} cm and {abs(dth):.1f} deg"
                if rec.kind == "reset":
                    self.log(
                        f"localization: the start pose was {off} off what {obs.landmark.name} says "
                        f"(NIS {rec.nis:.1f}): reset from it"
                    )
                else:
                    self.log(
                        f"localization: lost, the estimate was {off} off what {obs.landmark.name} says "
                        f"(NIS {rec.nis:.1f}), and an earlier rejected sighting agrees: re-found from it"
                    )
        frame = replace(frame, odom=self._pose(), wheel_odom=wheels)  # the wheels: frame_motion
        yaw = self.localizer.camera_yaw_estimate
        if yaw is not None:  # what the frame sees is placed through the camera's estimated yaw on the base
            frame = replace(
                frame, camera=with_head_yaw(frame.camera, _within_mount_limit(frame.camera, yaw[0]))
            )
        scale = self.localizer.range_scale_estimate
        if scale is not None:  # and at the ranges the estimated range scale corrects
            frame = replace(frame, camera=_rescaled(frame.camera, scale[0], self.config.range_scale_sigma))
        return frame

    def certain(self, sigma_m: float | None = None, sigma_rad: float | None = None, at_W=None) -> bool:
        """Whether the pose is within the thresholds ``sigma_m``, ``sigma_rad`` (position: the larger
        axis of its ellipse, or of the point ``at_W`` = (x, y) placed from the robot,
        :meth:`PlanarPoseEstimate.point_sigma_m`; heading), by default the re-localization's
        (:class:`LocalizerConfig`). The camera's pose (:meth:`camera_pose_estimate`): a standing robot's
        sightings fix the camera's heading, the base's only up to the camera's yaw on the base."""
        est = self.camera_pose_estimate()
        sm = self.config.relocalize_sigma_m if sigma_m is None else sigma_m
        sr = self.config.relocalize_sigma_rad if sigma_rad is None else sigma_rad
        s_pos = est.sigma_xy_m if at_W is None else est.point_sigma_m(at_W)
        return s_pos <= sm and est.sigma_theta_rad <= sr

    def drive_guard(self) -> str | None:
        """Why the pose is too uncertain to drive and map on (its position or heading standard deviation
        past ``config.drive_sigma_m`` / ``drive_sigma_rad``), or None: the navigator's
        :attr:`~lab.navigation.navigator.Navigator.pose_guard` during a search's drive. None on odometry
        alone (no landmark would make it better)."""
        if self.mode is LocalizationMode.ODOMETRY:
            return None
        est, c = self.pose_estimate(), self.config
        if est.sigma_xy_m > c.drive_sigma_m or est.sigma_theta_rad > c.drive_sigma_rad:
            return (
                f"pose deviation {100 * est.sigma_xy_m:.0f} cm / {math.degrees(est.sigma_theta_rad):.1f} deg "
                f"past the drive's {100 * c.drive_sigma_m:.0f} cm / {math.degrees(c.drive_sigma_rad):.1f} deg"
            )
        return None

    def landmark_views(self, tilt_max: float = math.radians(25.0)) -> list[tuple[float, float, str]]:
        """The head angles ``(pan, tilt, name)`` that point at each landmark the estimate says is in range,
        facing and within the pan range, best first (facing, wide, near: the most inliers)."""
        lim = self.base.pan_tilt_limits
        cam = self.base.camera
        x = self.localizer.x
        order = []
        for lm in self.observer.map:
            r, bearing = self.observer.map.bearing_in_robot(lm, x)
            if r > self.config.max_range_m or lm.facing(x[:2]) < self.config.min_facing:
                continue
            pan = wrap_angle(bearing)
            if not lim.pan_min <= pan <= lim.pan_max:
                continue
            dz = lm.centre_W[2] - cam.mount_R[2]
            tilt = float(
                np.clip(math.atan2(dz, r), max(lim.tilt_min, -tilt_max), min(lim.tilt_max, tilt_max))
            )
            order.append((-lm.facing(x[:2]) * lm.width_m / max(r, 0.5), pan, tilt, lm.name))
        order.sort()
        return [(pan, tilt, name) for _, pan, tilt, name in order]

    def landmark_vantage_points(
        self,
        free,
        radii_m=None,
        n_directions: int = 16,
        min_facing: float = 0.7,
        range_m: tuple[float, float] = (1.0, 3.5),
        tilt_max: float = math.radians(25.0),
    ) -> list[tuple[float, float, str]]:
        """Places near the robot from which a landmark would be seen well: for a detour before a report
        (``LocalizerConfig.report_detour_m``).

        The candidates lie on rings around the estimated position (radii ``radii_m``, default 0.5 m
        steps up to ``report_detour_m``; ``n_directions`` on each); ``free(x, y)`` says whether the robot
        may stand there (its costmap). A landmark is seen well from a place when it is ``range_m`` away,
        at most ``acos(min_facing)`` off its face's normal, and its centre within ``tilt_max`` of the
        camera's height: the whole face in a frame, head-on enough for a precise fit (the robot turns
        and pans to it there). Returns ``(x, y, landmark name)``, nearest first; of places equally near,
        the better view first (facing x width / range, as :meth:`landmark_views`).
        """
        if self.mode is LocalizationMode.ODOMETRY:
            return []
        reach = self.config.report_detour_m
        radii = radii_m if radii_m is not None else np.arange(0.5, reach + 1e-9, 0.5)
        x0, y0 = float(self.localizer.x[0]), float(self.localizer.x[1])
        h = self.base.camera.mount_R[2]
        out = []
        for r in radii:
            for a in np.arange(n_directions) * (2.0 * math.pi / n_directions):
                x, y = x0 + r * math.cos(a), y0 + r * math.sin(a)
                if not free(x, y):
                    continue
                best = None
                for lm in self.observer.map:
                    d = math.hypot(lm.centre_W[0] - x, lm.centre_W[1] - y)
                    facing = lm.facing((x, y))
                    if not (range_m[0] <= d <= range_m[1] and facing >= min_facing):
                        continue
                    if abs(math.atan2(lm.centre_W[2] - h, d)) > tilt_max:
                        continue
                    score = facing * lm.width_m / d
                    if best is None or score > best[0]:
                        best = (score, lm.name)
                if best is not None:
                    out.append((round(float(r), 6), -best[0], x, y, best[1]))
        out.sort()
        return [(x, y, name) for _, _, x, y, name in out]

    def relocalize(
        self,
        max_views: int = 6,
        tilt_max: float = math.radians(25.0),
        *,
        sigma_m: float | None = None,
        sigma_rad: float | None = None,
        passes: int = 1,
        at_W=None,
    ) -> bool:
        """Active re-localization: when the position is uncertain, stop and pan the head to the landmarks
        the estimate says are in view, best first (:meth:`landmark_views`), until it is certain again.

        ``sigma_m``, ``sigma_rad``, ``at_W``: the thresholds of :meth:`certain` and the point they hold
        at (default the re-localization's, at the robot; a report uses ``report_sigma_m`` at the object,
        :meth:`relocalize_to_report`); ``passes``: how many times round the landmarks in view, at most
        ``max_views`` views in all; a pass after the first looks only where the one before it saw a
        landmark the filter accepted.

        Returns True when the pose is (or became) within the thresholds; the head is put back where
        it was.
        """
        if self.mode is LocalizationMode.ODOMETRY:
            return False
        if self.certain(sigma_m, sigma_rad, at_W):
            return True
        self.base.stop()
        start = self.base.pan_tilt()
        views = self.landmark_views(tilt_max)
        done, n_views = False, 0
        for _ in range(max(int(passes), 1)):
            productive = []
            for view in views:
                if n_views >= max_views:
                    break
                pan, tilt, _name = view
                self._turn_head(pan, tilt)
                n0 = len(self.localizer.history)
                self.capture_stereo()
                n_views += 1
                if any(r.accepted for r in self.localizer.history[n0:]):
                    productive.append(view)
                if self.certain(sigma_m, sigma_rad, at_W):
                    done = True
                    break
            # the next pass looks again only where this one saw a landmark it accepted: the robot stands
            # still, so a view that showed none, or an outlier (a wrong fit), shows the same
            # again, and repeated rejections would trip the gate lock-out recovery for nothing
            views = productive
            if done or not views or n_views >= max_views:
                break
        self._turn_head(start.pan, start.tilt)
        return done

    def _turn_head(self, pan: float, tilt: float) -> None:
        """Point the head at ``(pan, tilt)`` and wait until it is there (a whole pan swing takes > 5 s).

        With a camera latency the wait steps through :meth:`step` (:meth:`wait_pan_tilt`), so the
        head's and the wheels' readings during the swing are kept and the next frame is taken back to
        its image's stamp along them (:meth:`head_at_image`, :meth:`wheels_at_image`). Waiting on the
        base alone left the whole swing out of the history: the head's angle at the image's stamp was
        then interpolated between a reading from before the swing and one after it, short of where the
        head stood by the swing times the latency over the gap (2.6-3 deg in the room's searches,
        docs/tuning/room-errors.md), and every sighting of a re-localization was turned by it. Without a
        latency nothing is taken back, and the base waits alone as before."""
        self.base.command_pan_tilt(pan, tilt)
        if self.camera_latency_s > 0:
            self.wait_pan_tilt(timeout=15.0)
        else:
            self.base.wait_pan_tilt(timeout=15.0)

    def relocalize_to_report(self, at_W=None) -> bool:
        """The re-localization before a pose is reported in the room (a found object's, at ``at_W`` =
        (x, y) [m] in W): the ordinary one first (:meth:`relocalize`), then on until the point's
        position standard deviation is within ``report_sigma_m`` (the robot's own without ``at_W``) and
        the heading's within ``report_sigma_rad``, with up to ``report_max_views`` views,
        ``report_passes`` times round the landmarks in view."""
        if self.mode is LocalizationMode.ODOMETRY:
            return False
        self.relocalize()
        c = self.config
        return self.relocalize(
            c.report_max_views,
            sigma_m=c.report_sigma_m,
            sigma_rad=c.report_sigma_rad,
            passes=c.report_passes,
            at_W=at_W,
        )

    def wait_pan_tilt(self, timeout: float = 10.0, dt: float = 0.05) -> PanTiltState:
        """Step until the head reaches its targets (:meth:`lab.robot.Robot.wait_pan_tilt`), then, with a
        camera latency, as long again as an image is old: the next frame's image is exposed with the head
        where it stopped (at 60 deg/s, an image 50 ms old shows a head that has just arrived 3 deg short
        of it, and the frame would pair it with the arrived angle)."""
        return self._settle(super().wait_pan_tilt(timeout, dt))

    def _settle(self, state: PanTiltState) -> PanTiltState:
        """After the head stopped: wait ``camera_latency_s`` (see :meth:`wait_pan_tilt`)."""
        if self.camera_latency_s > 0:
            self.step(self.camera_latency_s)
            state = self.base.pan_tilt()
        return state

    # the rest of the Robot interface is RobotWrapper's: passed on to the base
    def step(self, dt: float) -> None:
        self.base.step(dt)
        self._sync()
        if self.camera_latency_s > 0:  # the head's readings, for head_at_image (none without a latency)
            self.pan_tilt_history.add(self.base.now(), self.base.pan_tilt())


def _within_mount_limit(camera, yaw: float) -> float:
    """``yaw`` [rad] clipped so that the head's yaw it is added to stays within the mounts' limit
    (:data:`lab.mounts.MAX_MOUNT_DEG`): a diverged estimate places frames at the limit rather than stop
    the run with a ConfigError."""
    y0 = camera.mounts.head_rpy[2] if isinstance(camera, MountedCamera) else 0.0
    lim = math.radians(MAX_MOUNT_DEG) - 1e-9
    return float(np.clip(y0 + yaw, -lim, lim) - y0)


def _rescaled(camera, scale: float, sigma: float):
    """``camera`` with its focal lengths divided by ``1 + scale`` (the localizer's range scale,
    :mod:`lab.localization.posters`), which takes out a range scale whichever way a fit reads the
    range: from the apparent size of what it sees (the focal lengths' error) or from the disparity
    (``Z = f_x B / d``). The principal point and the baseline are kept. The scale is clipped to three of
    its prior deviations (``sigma``): a diverged estimate does not rescale the world."""
    s = float(np.clip(scale, -3.0 * sigma, 3.0 * sigma))
    return replace(camera, fx=camera.fx / (1.0 + s), fy=camera.fy / (1.0 + s))
