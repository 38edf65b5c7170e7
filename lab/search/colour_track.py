r"""A global colour detection of a moving object kept as a track: a Kalman filter in the plane and its
re-observation with the pan-tilt head.

The search paper's global search turns a colour peak into a raised map cell and forgets it; for an
object that drives (issue 50) the robot would then approach where the object *was*. The predicting
search keeps each used colour peak of its last global search as a :class:`ColourTrack`: the peak's
stereo point ``p_W`` starts a filter on the object's position and velocity in the floor plane, and
while the robot approaches, the head is pointed at the track's predicted position
(:func:`lab.search.tracking.aim_at`), one frame is taken, the colour blob nearest the predicted pixel
is found (:func:`find_blob`) and the filter updated: the identification paper's pan-tilt tracking, which
keeps the object centred in the view, one frame per leg of the approach.

**The model** (a constant-velocity model at the object's speed bound ``v``). The state is
``x = (p_x, p_y, v_x, v_y)`` [m, m/s]:

.. math::

    x_{k+1} = F x_k + w_k, \qquad F = \begin{pmatrix} I & \Delta t\, I \\ 0 & I \end{pmatrix}, \qquad
    Q = q \begin{pmatrix} \Delta t^3/3\, I & \Delta t^2/2\, I \\ \Delta t^2/2\, I & \Delta t\, I \end{pmatrix}
    \quad (T1)

(white-noise acceleration of spectral density ``q``). A carrier turns to a new heading after every
leg, so the velocity forgets itself over about a leg's time ``tau``: ``q = v^2 / (2 tau)`` grows the
velocity's variance per axis by ``v^2 / 2`` (a speed ``v`` in a random direction) over ``tau``. A new
track starts at the peak's point with the velocity unknown within the bound, ``P_v = (v^2 / 2) I``.

The measurement is the blob's stereo point in the plane, ``z = H x + n``, ``H = (I\ 0)``, with ``R``
the first-order triangulation covariance of the blob's pixel and disparity
(:func:`lab.vision.stereo.triangulation_covariance`) rotated into the world, plus ``sigma_floor^2 I``
for what it leaves out (the blob is on the object's face, not at its centre; the robot's own pose).
The update is the Kalman filter's, in Joseph form:

.. math::

    S = H P H^T + R, \quad K = P H^T S^{-1}, \quad x \leftarrow x + K (z - H x), \quad
    P \leftarrow (I - K H) P (I - K H)^T + K R K^T \quad (T2)

gated by the innovation's Mahalanobis distance ``y^T S^{-1} y <= gate_chi2`` (another thing of the
object's colours is not the object).

**Where the object will be.** :meth:`ColourTrack.position_at` extrapolates the position with the
velocity estimate clipped to the speed bound (a filter fed noisy stereo points may estimate a velocity
above it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lab.errors import ConfigError
from lab.geometry import se3_inv, transform_points
from lab.robot import StereoFrame
from lab.search.global_search import peak_disparity, strongest_clusters, window_mean
from lab.vision.colour import back_project
from lab.vision.dense import checked_disparity
from lab.vision.stereo import StereoParams, triangulate, triangulation_covariance

__all__ = ["Blob", "ColourTrack", "ColourTrackConfig", "find_blob", "transition", "white_noise_q"]


@dataclass(frozen=True)
class ColourTrackConfig:
    """Settings of the colour track and of following it (:mod:`lab.search.follow`).

    Attributes
    ----------
    tau_s : float [s]
        The velocity's time scale (about one leg of the carrier): ``q = v^2 / (2 tau)`` in Eq. (T1).
    sigma_px, sigma_disparity_px : float [px]
        The blob centre's pixel noise and its median disparity's noise (a window's centre, not a
        keypoint: a few pixels).
    sigma_floor_m : float [m]
        Added to the measurement's deviation along each axis (face against centre, the robot's pose).
    gate_chi2 : float
        Largest Mahalanobis distance squared of a measurement (9.21: 99 % of a 2-D Gaussian).
    gate_px : float [px]
        The blob is looked for within this many pixels of the predicted one, or within the track's
        three-sigma position deviation seen from the camera when that is wider (:meth:`ColourTrack.gate_px`:
        a track seen early in a scan may have driven a metre since).
    min_strength : float
        The blob's smallest window mean (as the global search's peaks).
    lost_after_s : float [s]
        A track not re-detected for this long (counted from its last sighting, or from the start of the
        approach when that is later) is lost: the approach falls back to the map's cell.
    leg_m : float [m]
        How far the robot drives between two re-observations while it approaches.
    max_legs : int
        At most this many legs (and frames) per approach.
    match_m : float [m]
        A map target within this distance of where a track started is that track's (the map's peak
        came from its colour peak).
    """

    tau_s: float = 10.0
    sigma_px: float = 3.0
    sigma_disparity_px: float = 1.0
    sigma_floor_m: float = 0.1
    gate_chi2: float = 9.21
    gate_px: float = 60.0
    min_strength: float = 0.15
    lost_after_s: float = 20.0
    leg_m: float = 1.0
    max_legs: int = 8
    match_m: float = 0.45

    def __post_init__(self):
        positive = (
            "tau_s",
            "sigma_px",
            "sigma_disparity_px",
            "gate_chi2",
            "gate_px",
            "lost_after_s",
            "leg_m",
        )
        for name in positive:
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ConfigError(f"ColourTrackConfig.{name} must be a finite number > 0, got {v!r}")
        if not (math.isfinite(self.sigma_floor_m) and self.sigma_floor_m >= 0):
            raise ConfigError(f"ColourTrackConfig.sigma_floor_m must be >= 0 m, got {self.sigma_floor_m!r}")
        if self.max_legs < 1:
            raise ConfigError(f"ColourTrackConfig.max_legs must be >= 1, got {self.max_legs!r}")


def transition(dt: float) -> np.ndarray:
    """``F`` of Eq. (T1) for ``dt`` [s] (state order ``p_x, p_y, v_x, v_y``)."""
    F = np.eye(4)
    F[0, 2] = F[1, 3] = dt
    return F


def white_noise_q(dt: float, q: float) -> np.ndarray:
    """``Q`` of Eq. (T1): white-noise acceleration of spectral density ``q`` [m^2/s^3] over ``dt`` [s]."""
    Q = np.zeros((4, 4))
    for i in (0, 1):
        Q[i, i] = dt**3 / 3.0
        Q[i, i + 2] = Q[i + 2, i] = dt**2 / 2.0
        Q[i + 2, i + 2] = dt
    return q * Q


class ColourTrack:
    """The filter of Eqs. (T1)-(T2) on one colour peak.

    Parameters
    ----------
    p_W : array-like, shape (3,) [m]
        The peak's stereo point (its height is kept to aim the head and predict the pixel).
    R_xy : ndarray, shape (2, 2) [m^2]
        Its covariance in the plane.
    t : float [s]
        When it was seen (robot time).
    speed_mps : float [m/s]
        The speed bound ``v``.
    config : ColourTrackConfig
    """

    def __init__(self, p_W, R_xy, t: float, speed_mps: float, config: ColourTrackConfig):
        if not (math.isfinite(speed_mps) and speed_mps > 0):
            raise ConfigError(f"a colour track needs a speed bound > 0 m/s, got {speed_mps!r}")
        p = np.asarray(p_W, float)
        self.config, self.speed = config, float(speed_mps)
        self.q = self.speed**2 / (2.0 * config.tau_s)
        self.x = np.array([p[0], p[1], 0.0, 0.0])
        self.P = np.zeros((4, 4))
        self.P[:2, :2] = np.asarray(R_xy, float)
        self.P[2:, 2:] = 0.5 * self.speed**2 * np.eye(2)
        self.z = float(p[2])
        self.t = self.t_seen = self.t_start = float(t)
        self.start_xy = (float(p[0]), float(p[1]))
        self.updates = 0  # re-detections applied
        self.frames = 0  # re-observation frames taken

    def predict(self, t: float) -> None:
        """Eq. (T1) to robot time ``t`` [s] (a time before the filter's own is refused)."""
        dt = float(t) - self.t
        if dt < -1e-9:
            raise ConfigError(f"cannot predict the colour track back in time ({t} s < {self.t} s)")
        if dt > 0:
            F = transition(dt)
            self.x = F @ self.x
            self.P = F @ self.P @ F.T + white_noise_q(dt, self.q)
            self.t = float(t)

    def innovation(self, z_xy) -> tuple[np.ndarray, np.ndarray]:
        """``y = z - H x`` and ``H P H^T`` (add ``R`` for ``S``)."""
        return np.asarray(z_xy, float) - self.x[:2], self.P[:2, :2].copy()

    def update(self, z_xy, R_xy, t: float) -> bool:
        """Eq. (T2) with a measurement ``z_xy`` [m] of covariance ``R_xy`` [m^2] taken at ``t`` [s];
        False (nothing changed but the prediction) when the gate refuses it."""
        self.predict(t)
        y, HPH = self.innovation(z_xy)
        S = HPH + np.asarray(R_xy, float)
        if float(y @ np.linalg.solve(S, y)) > self.config.gate_chi2:
            return False
        H = np.hstack([np.eye(2), np.zeros((2, 2))])
        K = self.P @ H.T @ np.linalg.inv(S)
        self.x = self.x + K @ y
        IKH = np.eye(4) - K @ H
        self.P = IKH @ self.P @ IKH.T + K @ np.asarray(R_xy, float) @ K.T
        self.t_seen = self.t
        self.updates += 1
        return True

    def position_at(self, t: float) -> np.ndarray:
        """The predicted position (x, y) [m] at robot time ``t`` [s] >= the filter's, with the velocity
        estimate clipped to the speed bound."""
        v = self.x[2:]
        s = float(np.linalg.norm(v))
        if s > self.speed:
            v = v * (self.speed / s)
        return self.x[:2] + v * max(0.0, float(t) - self.t)

    def point_at(self, t: float) -> np.ndarray:
        """The predicted 3D point [m] (the seen height) at time ``t``, to aim the head at."""
        return np.array([*self.position_at(t), self.z])

    def lost(self, t: float, since: float = -math.inf) -> bool:
        """Not re-detected for ``lost_after_s`` at time ``t`` [s], counted from the last sighting or from
        ``since`` [s] (when the re-observations began), whichever is later."""
        return float(t) - max(self.t_seen, float(since)) > self.config.lost_after_s

    def gate_px(self, depth_m: float, f_px: float) -> float:
        """The search radius [px] round the predicted pixel of a point ``depth_m`` [m] in front of a
        camera of focal length ``f_px``: ``gate_px``, or three position deviations (the covariance's
        largest axis) as seen at that depth, whichever is larger."""
        sigma = math.sqrt(max(0.0, float(np.linalg.eigvalsh(self.P[:2, :2])[-1])))
        return max(self.config.gate_px, 3.0 * sigma * f_px / max(depth_m, 0.1))


@dataclass(frozen=True)
class Blob:
    """A colour blob of one frame: its pixel, strength, stereo point in the world and that point's
    covariance in the plane."""

    uv: tuple[float, float]
    strength: float
    p_W: np.ndarray
    R_xy: np.ndarray


def measurement_xy(
    frame: StereoFrame, uv, disparity: float, config: ColourTrackConfig
) -> tuple[np.ndarray, np.ndarray]:
    """The stereo point in the world ``p_W`` (3,) [m] of a pixel and its disparity, and its covariance in
    the plane (2, 2) [m^2] (the module docstring's ``R``)."""
    cam = frame.camera
    uv_l = np.array([[float(uv[0]), float(uv[1])]])
    p_C = triangulate(uv_l, uv_l - np.array([[disparity, 0.0]]), cam)[0]
    params = StereoParams(sigma_px=config.sigma_px, sigma_disparity=config.sigma_disparity_px)
    S_C = triangulation_covariance(uv_l, np.array([disparity]), cam, params)[0]
    G_WC = frame.odom.G() @ frame.G_RC
    R_WC = G_WC[:3, :3]
    S_W = R_WC @ S_C @ R_WC.T
    return transform_points(G_WC, p_C), S_W[:2, :2] + config.sigma_floor_m**2 * np.eye(2)


def predicted_pixel(frame: StereoFrame, p_W) -> tuple[float, float, float] | None:
    """Where the world point ``p_W`` [m] falls in the frame's left image, and its depth [m]: ``(u, v,
    Z)``; None when it is behind the camera or outside the image."""
    p_C = transform_points(se3_inv(frame.odom.G() @ frame.G_RC), np.asarray(p_W, float))
    if p_C[2] <= 0.05:
        return None
    u, v = frame.camera.project(p_C[None, :])[0]
    if not (0 <= u < frame.camera.width and 0 <= v < frame.camera.height):
        return None
    return float(u), float(v), float(p_C[2])


def find_blob(
    frame: StereoFrame,
    colour_model: np.ndarray,
    space: str,
    uv_pred,
    config: ColourTrackConfig,
    gate_px: float | None = None,
    window_px: int = 7,
    num_disparities: int = 48,
) -> Blob | None:
    """The strongest colour blob within ``gate_px`` [px] (default ``config.gate_px``) of the predicted
    pixel ``uv_pred``: the global
    search's back-projection of ``colour_model`` (its ratio histogram), window means, the strongest
    cluster in the gate, its median disparity and stereo point. None when there is no blob of at least
    ``min_strength`` or no disparity at it."""
    bp = back_project(frame.left, colour_model, space)
    wm = window_mean(bp, window_px)
    H, W = wm.shape
    vv, uu = np.mgrid[0:H, 0:W]
    gate = config.gate_px if gate_px is None else gate_px
    wm[(uu - uv_pred[0]) ** 2 + (vv - uv_pred[1]) ** 2 > gate**2] = 0.0
    clusters = strongest_clusters(wm, 1, config.min_strength, 1)
    if not clusters:
        return None
    u, v, strength = clusters[0]
    disp = checked_disparity(frame.left, frame.right, num_disparities=num_disparities)
    d = peak_disparity(disp, bp, u, v, window_px)
    if d is None or not d > 0:
        return None
    p_W, R = measurement_xy(frame, (u, v), d, config)
    return Blob((float(u), float(v)), float(strength), p_W, R)
