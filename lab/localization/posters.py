r"""The posters in the localizer's state: landmark SLAM seeded by a surveyed map.

A map measured in a room is off by 1-2 cm and 0.5-1 deg per poster (:attr:`Landmark.survey_sigma_m`,
``survey_sigma_rad``), and 1 deg of a poster's yaw, seen from 3 m, is 5 cm of the robot's position.
Held fixed, such a map pulls every update towards its error, and the covariance does not know. The
localizer (:class:`~lab.localization.filter.Localizer`) instead carries the planar pose
:math:`l_j = [x_j, y_j, \psi_j]` of each surveyed poster in its state, as landmark SLAM does::

    s = [x, y, theta, (k, c), l_1, l_2, ...]      (k, c: the odometry's calibration, when estimated)

* **augmentation**: a poster joins the state at its first observation, its survey as its prior and
  independent of everything else (until then nothing in the filter touches it, so joining then is the
  same as carrying it from the start)::

      s <- [s, l_j^survey],   P <- [[P, 0], [0, L_j]],   L_j = diag(sigma_m^2, sigma_m^2, sigma_rad^2)

* **prediction** moves the robot only: ``F_joint = blockdiag(F, I)``, the odometry's noise enters the
  robot's block (``P_rr <- F P_rr F^T + V M V^T``, ``P_rl <- F P_rl``);
* **update**: the measurement is :func:`~lab.localization.models.measurement_model`'s, now a function
  of the poster's state too (:func:`observe`)::

      h(x, l_j) = [R(theta)^T (l_xy - x_xy), wrap(psi_j - theta)]
      H = [dh/dx, 0, ..., 0, dh/dl_j, 0, ...],    dh/dl_j = [[R(theta)^T, 0], [0, 1]]

  and the filter's (iterated, gated) EKF equations are unchanged: its gate's ``S = H P H^T + Q`` holds
  the poster's uncertainty, the robot's covariance keeps its correlation with every poster (so it
  accounts for the map's error), and a poster seen again from a pose that other posters and the
  odometry fix moves towards where it is;
* **first sighting of a measured start** (:meth:`Localizer.first_sighting`): the pose one observation
  implies, :math:`x_z = g(z, l_j)` (:func:`~lab.localization.models.pose_from_observation`), depends on
  the poster as well, through :math:`J_l = \partial g / \partial l_j` (:func:`pose_jacobian_in_landmark`).
  Fusing it is the linear update of the pseudo-measurement :math:`0 = x - g(z, l_j)`, innovation
  :math:`d = x_z - \bar x`, ``H_f = [I, 0, ..., -J_l, ...]``, noise :math:`J_z Q J_z^T`; replacing the
  start by it sets :math:`x = x_z`, :math:`\mathrm{Cov}(x, y) = J_l\, \mathrm{Cov}(l_j, y)` for the
  rest of the state and :math:`\mathrm{Cov}(x) = J_z Q J_z^T + J_l L_j J_l^T`.

A landmark with both survey sigmas 0 (an exact map, the simulator's own scene) is not added: the filter
then is exactly the fixed-map one.

**The camera's yaw on the base** (``LocalizerConfig.camera_yaw_sigma_rad`` above 0): the pan zero and
the mounts' yaw turn every sighting by the same :math:`\beta` about the pan axis (at R's origin: the
camera's ``mount_R`` has x = y = 0), which a standing robot cannot tell from its own heading; a drive
can (the odometry moves the robot along its heading, the sightings show where it went). It is one
more state element, constant, prior :math:`N(0, \sigma_\beta^2)`, and the measurement becomes::

      h_beta = [R(-beta) h_xy, h_3 - beta],  dh_beta/ds = blockdiag(R(-beta), 1) dh/ds,
      dh_beta/dbeta = [dR(-beta)/dbeta h_xy, -1]

(the pose one sighting implies undoes it first: ``g(z_c, l)``, ``z_c = [R(beta) z_xy, z_3 + beta]``).
The robot's frames are then taken through the camera turned by the estimate
(:meth:`~lab.localization.LocalizedRobot.capture_stereo`, :func:`lab.mounts.with_head_yaw`), so what
the search places in the world is placed where the landmarks put the camera; and what a standing
robot's sightings fix, the camera's heading ``theta + beta``, is what its re-localization and reports
are judged on (:meth:`~lab.localization.Localizer.camera_pose`). In the simulator the state is on when
the profile states the mounts uncertain (:func:`lab.runs.room.sim_localizer_told`).

**The stereo's range scale** (``LocalizerConfig.range_scale_sigma`` above 0): a calibration's focal
length and baseline errors stretch every sighting's range by the same factor :math:`1 + \rho`. A
poster's fit reads its range more from its apparent size than from the disparity (the 3D points are
precise across the line of sight and not along it), so the focal lengths' error, which scales that
size, is most of it. Sightings from many places do not average it out: held exact, it bends the
posters' refined shape and pulls the robot towards or away from the posters it sees. It is one more
constant state element after the yaw, prior :math:`N(0, \sigma_\rho^2)`, and the measurement becomes::

      h_rho = [(1 + rho) R(-beta) h_xy, h_3 - beta],   dh_rho/drho = [R(-beta) h_xy, 0]

(the rows of ``H`` for the position times ``1 + rho``; the pose one sighting implies undoes it first:
``z_c = [R(beta) z_xy / (1 + rho), z_3 + beta]``). Posters seen at different ranges and in different
directions, each known to its survey, tell the scale from the robot's position. The robot's frames are
then taken through the camera with its focal lengths divided by ``1 + rho``
(:class:`~lab.localization.LocalizedRobot`), so what the search measures is corrected too.
"""

from __future__ import annotations

import math

import numpy as np

from lab.geometry import wrap_angle
from lab.localization.landmarks import Landmark
from lab.localization.models import measurement_jacobian, measurement_model, pose_from_observation

__all__ = [
    "PosterStates",
    "landmark_jacobian",
    "observe",
    "pose_jacobian_in_landmark",
    "sighting_pose",
    "survey_prior",
]


def survey_prior(landmark: Landmark) -> tuple[np.ndarray, np.ndarray]:
    """The poster's planar pose ``l`` (3,) from the map and its covariance ``diag(sm^2, sm^2, sr^2)``."""
    sm, sr = landmark.survey_sigma_m, landmark.survey_sigma_rad
    return landmark.planar, np.diag([sm * sm, sm * sm, sr * sr])


def landmark_jacobian(x, l) -> np.ndarray:
    r"""``dh/dl`` (3, 3) of :func:`~lab.localization.models.measurement_model` at pose ``x``:

    .. math:: \frac{\partial h}{\partial l} = \begin{bmatrix} \cos\theta & \sin\theta & 0 \\
              -\sin\theta & \cos\theta & 0 \\ 0 & 0 & 1 \end{bmatrix}
    """
    c, s = math.cos(float(x[2])), math.sin(float(x[2]))
    return np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])


def pose_jacobian_in_landmark(z, l) -> np.ndarray:
    r"""``J_l = dx/dl`` (3, 3) of :func:`~lab.localization.models.pose_from_observation`: how the pose
    one observation ``z`` implies moves with the landmark's planar pose ``l``. With
    :math:`\theta = \psi - z_3`, :math:`[x, y]^T = l_{xy} - R(\theta) [z_1, z_2]^T`:

    .. math:: J_l = \begin{bmatrix} 1 & 0 & z_1 \sin\theta + z_2 \cos\theta \\
                                    0 & 1 & -z_1 \cos\theta + z_2 \sin\theta \\ 0 & 0 & 1 \end{bmatrix}
    """
    th = wrap_angle(float(l[2]) - float(z[2]))
    c, s = math.cos(th), math.sin(th)
    return np.array([[1.0, 0.0, s * z[0] + c * z[1]], [0.0, 1.0, -c * z[0] + s * z[1]], [0.0, 0.0, 1.0]])


def observe(
    s, landmark: Landmark, j: int | None, b: int | None = None, g: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """``h(s)`` (3,) and ``H = dh/ds`` (3, n) of a landmark observation on the state ``s`` (n,).

    The robot's pose is ``s[:3]``; the landmark's planar pose is the state's block ``s[j:j + 3]`` when it
    is in the state (``j``), else its map pose (held fixed: ``H`` is zero there); ``s[b]`` the camera's
    yaw on the base and ``s[g]`` the stereo's range scale when they are estimated (``b``, ``g``; see the
    module docstring)."""
    s = np.asarray(s, float)
    l = landmark.planar if j is None else s[j : j + 3]
    H = np.zeros((3, len(s)))
    H[:, :3] = measurement_jacobian(s[:3], l)
    if j is not None:
        H[:, j : j + 3] = landmark_jacobian(s[:3], l)
    h = measurement_model(s[:3], l)
    if b is None and g is None:
        return h, H
    beta = 0.0 if b is None else float(s[b])
    k = 1.0 if g is None else 1.0 + float(s[g])
    c, sn = math.cos(beta), math.sin(beta)
    R = np.array([[c, sn], [-sn, c]])  # R(-beta)
    turned = R @ h[:2]
    H[:2] = k * (R @ H[:2])
    if b is not None:
        H[:2, b] = k * (np.array([[-sn, c], [-c, -sn]]) @ h[:2])  # k dR(-beta)/dbeta h_xy
        H[2, b] = -1.0
    if g is not None:
        H[:2, g] = turned
    return np.array([*(k * turned), wrap_angle(h[2] - beta)]), H


def sighting_pose(
    s, z, Q, landmark: Landmark, j: int | None, b: int | None = None, g: int | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The robot pose ``x_z`` one observation ``z`` (covariance ``Q``) implies
    (:func:`~lab.localization.models.pose_from_observation`), its covariance ``J_z Q J_z^T`` through the
    observation, and ``J_l = dx_z/ds`` (3, n) through the state: the poster's block at ``j`` (zero when
    the landmark is held fixed, ``j`` None), the camera's yaw ``s[b]`` and the range scale ``s[g]`` (when
    estimated)."""
    s = np.asarray(s, float)
    z = np.asarray(z, float)
    l = landmark.planar if j is None else s[j : j + 3]
    M = np.eye(3)  # dz_c/dz
    if b is not None or g is not None:  # undo them: z_c = [R(beta) z_xy / k, z_3 + beta]
        beta = 0.0 if b is None else float(s[b])
        k = 1.0 if g is None else 1.0 + float(s[g])
        c, sn = math.cos(beta), math.sin(beta)
        M[:2, :2] = np.array([[c, -sn], [sn, c]]) / k
        dz_db = np.array([(-sn * z[0] - c * z[1]) / k, (c * z[0] - sn * z[1]) / k, 1.0])
        z = M @ z + [0.0, 0.0, beta]
        dz_dg = np.array([-z[0] / k, -z[1] / k, 0.0])
    x_z, J = pose_from_observation(z, l)
    Jl = np.zeros((3, len(s)))
    if j is not None:
        Jl[:, j : j + 3] = pose_jacobian_in_landmark(z, l)
    if b is not None:
        Jl[:, b] = J @ dz_db
    if g is not None:
        Jl[:, g] = J @ dz_dg
    return x_z, J @ M @ Q @ M.T @ J.T, Jl


class PosterStates:
    """Which surveyed posters are in the localizer's state, and where: the blocks after the robot's.

    Parameters
    ----------
    first : int
        The index of the state where the posters begin (after the pose and the odometry's calibration).
    """

    def __init__(self, first: int):
        self.first = int(first)
        self.index: dict[str, int] = {}

    def __len__(self) -> int:
        return len(self.index)

    def index_of(self, landmark: Landmark) -> int | None:
        """The state index of the landmark's block, or None when it is not in the state."""
        return self.index.get(landmark.name)

    def augment(self, s: np.ndarray, P: np.ndarray, landmark: Landmark) -> tuple[np.ndarray, np.ndarray, int]:
        """The state and covariance with ``landmark`` appended, seeded by its survey
        (:func:`survey_prior`, independent of the rest), and its block's index."""
        if landmark.name in self.index:
            raise ValueError(f"landmark {landmark.name!r} is already in the state")
        l, L = survey_prior(landmark)
        n = len(s)
        P_new = np.zeros((n + 3, n + 3))
        P_new[:n, :n] = P
        P_new[n:, n:] = L
        self.index[landmark.name] = n
        return np.concatenate([s, l]), P_new, n

    def augment_all(
        self, s: np.ndarray, P: np.ndarray, landmarks: list[Landmark], L: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The state and covariance with every one of ``landmarks`` appended at once, seeded by their
        planar poses and joint covariance ``L`` (3n, 3n), independent of the rest: a room surveyed once
        (:mod:`lab.localization.stored_survey`), whose posters are correlated with each other."""
        taken = [lm.name for lm in landmarks if lm.name in self.index]
        if taken:
            raise ValueError(f"landmarks {taken!r} are already in the state")
        L = np.asarray(L, float)
        if L.shape != (3 * len(landmarks),) * 2:
            raise ValueError(
                f"the joint prior must be {3 * len(landmarks)} x {3 * len(landmarks)}, got {L.shape}"
            )
        n = len(s)
        P_new = np.zeros((n + len(L), n + len(L)))
        P_new[:n, :n] = P
        P_new[n:, n:] = L
        for i, lm in enumerate(landmarks):
            self.index[lm.name] = n + 3 * i
        return np.concatenate([s, *(lm.planar for lm in landmarks)]), P_new

    def augment_camera(
        self, s: np.ndarray, P: np.ndarray, sigma: float, what: str
    ) -> tuple[np.ndarray, np.ndarray, int]:
        """The state and covariance with one of the camera's constants appended (the yaw on the base
        [rad], the range scale [-]: prior ``N(0, sigma^2)``, independent of the rest), and its index;
        before any poster (call it first)."""
        if self.index:
            raise ValueError(f"the {what} joins the state before any poster")
        n = len(s)
        P_new = np.zeros((n + 1, n + 1))
        P_new[:n, :n] = P
        P_new[n, n] = float(sigma) ** 2
        self.first = n + 1
        return np.concatenate([s, [0.0]]), P_new, n

    def angles(self) -> list[int]:
        """The state's indices that are angles (wrapped after each step): the heading and each yaw."""
        return [2] + [j + 2 for j in self.index.values()]

    def estimates(self, s: np.ndarray, P: np.ndarray) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Each poster in the state: its planar pose ``[x, y, yaw]`` and covariance (3, 3), by name."""
        return {name: (s[j : j + 3].copy(), P[j : j + 3, j : j + 3].copy()) for name, j in self.index.items()}
