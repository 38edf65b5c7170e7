r"""The camera's mounts and the pan-tilt's zero, estimated from a standing robot's sightings of posters.

A calibration routine (``lab hardware calibrate``, :mod:`lab.runs.calibrate`) turns the head over a
pattern of pan and tilt angles and fits each poster it sees (:class:`~lab.localization.LandmarkObserver`:
stereo features of the real images, the poster's database, RANSAC + Gauss-Newton), giving the poster's
6-DOF pose in the camera, ``G_CL``, with its covariance ``Sigma_rv`` over ``[t, phi]``. This module
solves, by least squares, for the angles that make every sighting agree with the surveyed map.

**The model.** For sighting ``k`` (head at ``pan_k, tilt_k``, base at odometry ``o_k``) of poster ``j``:

.. math::

    \hat G_{CL,k} = \big(G_{WR}(b_0)\, G(o_0)^{-1} G(o_k)\; G_{RC}(pan_k, tilt_k;\ \theta)\big)^{-1}
                    \, G_{WL}(l_j + \delta_j)

    G_{RC} = T(m)\, Rot(\rho_h, \pi_h, 0)\, R_z(pan)\, R_y(-(tilt + \tau))
             \, T(o)\, Rot(\rho_c, 0, \psi_c)\, R_{BO}

(:func:`lab.mounts.mounted_G_RC`) with the unknowns

* ``theta = (rho_h, pi_h, tau, rho_c, psi_c)``: the head's roll and pitch on the mast, the tilt's
  zero, the camera's roll and yaw on its bracket;
* ``b_0 = (x, y, heading)``: the base's true pose at the first sighting (a nuisance, its prior the
  odometry's start with the start's stated sigma);
* ``delta_j = (dx, dy, dz, dyaw)`` of each surveyed poster (a nuisance, its prior its survey sigma;
  posters with no survey sigma are exact).

The residual of a sighting is ``[t_meas - t_hat, Log(R_meas R_hat^T)]`` whitened by the fit's
covariance (plus a floor, :attr:`MountCalibrationConfig.floor_m` / ``floor_rad``); the priors are
whitened by their sigmas. After a robust first solve (soft L1) the sightings beyond the chi-square
gate are dropped and the problem solved again with squared residuals. The covariance is
``(J^T J)^{-1}`` at the solution, scaled by the reduced chi-square when it exceeds 1.

**What a standing robot can and cannot tell apart.**

* The head's *yaw* on the mast and the *pan zero* are one rotation about the pan axis, and that axis
  passes through the base's own vertical: both add to the base's heading. They are not estimated (held
  at 0); the base's heading absorbs them, and so does the localizer's heading on the robot.
* The camera's *pitch* on its bracket and the *tilt zero* are one rotation about the tilt axis (apart
  from the camera centre's offset of a few centimetres from that axis, under a millimetre of lever for
  a degree): ``tau`` is their sum, ``tilt_zero - camera_pitch`` in the simulator's terms.
* The head's roll and pitch tilt the pan axis: seen as a pan-dependent tilt of the view, observable
  when the head pans round. The camera's roll is a roll at every pan; its yaw differs from a pan only
  at a non-zero tilt (a yaw about the tilted camera's body axis is part roll), so the pattern needs
  several tilts.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from lab.errors import ConfigError
from lab.geometry import Pose2D, Rz, relative_pose2d, se3, se3_inv
from lab.localization.landmarks import Landmark
from lab.mounts import HeadMounts, mounted_G_RC

__all__ = [
    "ESTIMATED",
    "MountCalibration",
    "MountCalibrationConfig",
    "MountSighting",
    "predicted_G_CL",
    "solve_mounts",
]

#: The angles solved for, in the parameter vector's order.
ESTIMATED = ("head_roll", "head_pitch", "tilt_zero", "camera_roll", "camera_yaw")
_N_BASE, _N_MOUNT, _N_POSTER = 3, len(ESTIMATED), 4


@dataclass(frozen=True)
class MountSighting:
    """One poster fitted in one frame.

    Attributes
    ----------
    landmark : Landmark
        The map's poster (surveyed pose, its survey sigma).
    pan, tilt : float [rad]
        The head's reported angles at the frame.
    G_CL : ndarray (4, 4)
        The fitted pose of the poster in the camera.
    Sigma_rv : ndarray (6, 6)
        The fit's covariance over ``[t_CL, phi]`` (``R_CL <- Exp(phi) R_CL``).
    odom : Pose2D
        The base's odometry at the frame (any fixed frame: only its change between frames is used).
    """

    landmark: Landmark
    pan: float
    tilt: float
    G_CL: np.ndarray = field(repr=False)
    Sigma_rv: np.ndarray = field(repr=False)
    odom: Pose2D = Pose2D(0.0, 0.0, 0.0)


@dataclass(frozen=True)
class MountCalibrationConfig:
    """Settings of :func:`solve_mounts`.

    Attributes
    ----------
    floor_m, floor_rad : float [m], [rad]
        Added in quadrature to each sighting's stated translation and rotation sigma: RANSAC's
        covariance leaves out the database's own error (the poster's features placed from training
        renders), which is common to all sightings of a poster.
    prior_rad : float [rad]
        The prior sigma of each mount angle about 0: weak (several times a bracket's error), so that
        an angle the pattern does not see is held near 0 rather than left to wander.
    gate : float
        Squared Mahalanobis distance (6 dof) beyond which a sighting is dropped after the robust solve
        (a wrong fit): chi-square's 99.9 % point.
    min_sightings : int
        Fewer sightings than this is an error (the problem has up to 8 + 4 per poster unknowns).
    """

    floor_m: float = 0.002
    floor_rad: float = math.radians(0.1)
    prior_rad: float = math.radians(2.0)
    gate: float = 22.46
    min_sightings: int = 8

    def __post_init__(self):
        for k in ("floor_m", "floor_rad", "prior_rad", "gate"):
            v = getattr(self, k)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ConfigError(f"MountCalibrationConfig.{k} must be a finite number > 0, got {v!r}")
        if self.min_sightings < 3:
            raise ConfigError(f"MountCalibrationConfig.min_sightings must be >= 3, got {self.min_sightings}")


@dataclass(frozen=True)
class MountCalibration:
    """The result of :func:`solve_mounts`.

    Attributes
    ----------
    mounts : HeadMounts
        The estimated angles (the unobservable ones at 0) and their deviations.
    theta : ndarray (5,) [rad]
        The estimated angles in :data:`ESTIMATED`'s order; ``cov`` their covariance (5, 5).
    start : Pose2D
        The base's estimated pose at the first sighting.
    n_used, n_rejected : int
        Sightings used, and dropped by the gate.
    chi2_dof : float
        The reduced chi-square of the final solve (about 1 when the sightings' covariances are right).
    posters : dict name -> (dx, dy, dz, dyaw)
        The surveyed posters' estimated corrections [m, rad].
    """

    mounts: HeadMounts
    theta: np.ndarray = field(repr=False)
    cov: np.ndarray = field(repr=False)
    start: Pose2D
    n_used: int
    n_rejected: int
    chi2_dof: float
    posters: dict = field(default_factory=dict, repr=False)

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(np.diag(self.cov))


def _G_WL(lm: Landmark, d) -> np.ndarray:
    c = np.asarray(lm.centre_W, float) + np.asarray(d[:3], float)
    return se3(Rz(lm.yaw + float(d[3])), c)


def predicted_G_CL(s: MountSighting, camera, base_W: Pose2D, odom0: Pose2D, theta, d=(0, 0, 0, 0)):
    """``hat G_CL`` of the module's equation for sighting ``s``: the base at ``base_W`` when its odometry
    read ``odom0``, the angles ``theta`` (:data:`ESTIMATED`), the poster's correction ``d``."""
    G_WR = base_W.G() @ relative_pose2d(odom0, s.odom)
    hr, hp, tz, cr, cy = (float(v) for v in theta)
    G_RC = mounted_G_RC(
        s.pan, s.tilt, camera.mount_R, camera.camera_offset_P, (hr, hp, 0), (cr, 0, cy), 0, tz
    )
    return se3_inv(G_WR @ G_RC) @ _G_WL(s.landmark, d)


def _pose_residual(G_meas: np.ndarray, G_hat: np.ndarray) -> np.ndarray:
    dt = G_meas[:3, 3] - G_hat[:3, 3]
    phi = Rotation.from_matrix(G_meas[:3, :3] @ G_hat[:3, :3].T).as_rotvec()
    return np.concatenate([dt, phi])


class _Problem:
    """The stacked residuals of :func:`solve_mounts` over ``p = [b_0 (3), theta (5), delta_j (4 each)]``."""

    def __init__(self, sightings, camera, start: Pose2D, start_sigma, config: MountCalibrationConfig):
        self.s, self.camera, self.cfg = list(sightings), camera, config
        self.odom0 = self.s[0].odom
        self.start = start
        self.start_sigma = np.array([start_sigma[0], start_sigma[0], start_sigma[1]], float)
        names = sorted({x.landmark.name for x in self.s if x.landmark.surveyed})
        self.poster_index = {n: i for i, n in enumerate(names)}
        self.poster_sigma = {
            x.landmark.name: np.array([x.landmark.survey_sigma_m] * 3 + [x.landmark.survey_sigma_rad])
            for x in self.s
            if x.landmark.surveyed
        }
        floor = np.array([config.floor_m] * 3 + [config.floor_rad] * 3) ** 2
        self.W = [np.linalg.inv(np.linalg.cholesky(x.Sigma_rv + np.diag(floor))) for x in self.s]
        self.n = _N_BASE + _N_MOUNT + _N_POSTER * len(names)

    def unpack(self, p):
        base = Pose2D(*p[:_N_BASE])
        theta = p[_N_BASE : _N_BASE + _N_MOUNT]
        return base, theta

    def poster_d(self, p, name: str):
        i = self.poster_index.get(name)
        if i is None:
            return np.zeros(4)
        k = _N_BASE + _N_MOUNT + _N_POSTER * i
        return p[k : k + _N_POSTER]

    def sighting_residuals(self, p, used) -> np.ndarray:
        base, theta = self.unpack(p)
        out = []
        for x, W, u in zip(self.s, self.W, used, strict=True):
            if u:
                G_hat = predicted_G_CL(
                    x, self.camera, base, self.odom0, theta, self.poster_d(p, x.landmark.name)
                )
                out.append(W @ _pose_residual(x.G_CL, G_hat))
        return np.concatenate(out) if out else np.zeros(0)

    def prior_residuals(self, p) -> np.ndarray:
        b0 = np.array([self.start.x, self.start.y, self.start.theta])
        db = p[:_N_BASE] - b0
        db[2] = math.remainder(db[2], 2 * math.pi)
        out = [db / self.start_sigma, p[_N_BASE : _N_BASE + _N_MOUNT] / self.cfg.prior_rad]
        for name in self.poster_index:
            out.append(self.poster_d(p, name) / self.poster_sigma[name])
        return np.concatenate(out)

    def residuals(self, p, used) -> np.ndarray:
        return np.concatenate([self.sighting_residuals(p, used), self.prior_residuals(p)])


def solve_mounts(
    sightings,
    camera,
    start: Pose2D,
    start_sigma: tuple[float, float],
    config: MountCalibrationConfig | None = None,
) -> MountCalibration:
    """Estimate the mounts (the module's model) from ``sightings`` (:class:`MountSighting`).

    Parameters
    ----------
    sightings : sequence of MountSighting
    camera : StereoCamera
        The nominal kinematics (``mount_R``, ``camera_offset_P``); its own mounts, if any, are ignored.
    start : Pose2D
        The base's pose in the map's frame at the first sighting as the robot believes it (its odometry
        placed at the room's start); the prior of ``b_0``.
    start_sigma : (sigma_m, sigma_rad)
        How well ``start`` is known (``[room] start_sigma``).
    config : MountCalibrationConfig, optional

    Raises
    ------
    ConfigError
        Too few sightings, a bad ``start_sigma``, or a solve that did not converge.
    """
    cfg = config or MountCalibrationConfig()
    sightings = list(sightings)
    if len(sightings) < cfg.min_sightings:
        raise ConfigError(
            f"mount calibration needs at least {cfg.min_sightings} poster sightings, got {len(sightings)}: "
            "turn the head towards the posters (a wider pan pattern), or check the landmark map"
        )
    if not (len(start_sigma) == 2 and all(math.isfinite(v) and v > 0 for v in start_sigma)):
        raise ConfigError(f"start_sigma must be (sigma_m, sigma_rad), both > 0, got {start_sigma!r}")
    prob = _Problem(sightings, camera, start, start_sigma, cfg)
    p0 = np.zeros(prob.n)
    p0[:_N_BASE] = (start.x, start.y, start.theta)
    used = np.ones(len(sightings), bool)
    first = least_squares(lambda p: prob.residuals(p, used), p0, loss="soft_l1", f_scale=3.0, x_scale=0.01)
    r = prob.sighting_residuals(first.x, used).reshape(-1, 6)
    used = np.sum(r**2, axis=1) <= cfg.gate
    if used.sum() < cfg.min_sightings:
        raise ConfigError(
            f"mount calibration: only {int(used.sum())} of {len(sightings)} sightings agree with the map "
            f"(at least {cfg.min_sightings} needed): is the landmark map the room's, and the start right?"
        )
    sol = least_squares(lambda p: prob.residuals(p, used), first.x, x_scale=0.01)
    if not sol.success:
        raise ConfigError(f"mount calibration did not converge: {sol.message}")
    dof = max(1, sol.fun.size - prob.n)
    chi2_dof = float(np.sum(sol.fun**2) / dof)
    cov_all = np.linalg.pinv(sol.jac.T @ sol.jac) * max(1.0, chi2_dof)
    k = slice(_N_BASE, _N_BASE + _N_MOUNT)
    base, theta = prob.unpack(sol.x)
    cov = cov_all[k, k]
    std = np.sqrt(np.diag(cov))
    mounts = HeadMounts(
        head_rpy=(float(theta[0]), float(theta[1]), 0.0),
        camera_rpy=(float(theta[3]), 0.0, float(theta[4])),
        pan_zero=0.0,
        tilt_zero=float(theta[2]),
        std={
            "head_rpy": [float(std[0]), float(std[1]), 0.0],
            "camera_rpy": [float(std[3]), 0.0, float(std[4])],
            "pan_zero": 0.0,
            "tilt_zero": float(std[2]),
        },
        estimated=ESTIMATED,
    )
    posters = {n: tuple(map(float, prob.poster_d(sol.x, n))) for n in prob.poster_index}
    return MountCalibration(
        mounts, np.array(theta, float), cov, base, int(used.sum()), int((~used).sum()), chi2_dof, posters
    )
