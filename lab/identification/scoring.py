r"""Scoring a frame against one model's database: Eq. (9) of the identification paper, with a clutter
density for the features the model does not explain.

Every model is scored on the **same** measured feature set ``D_k`` (all the frame's 3D features):

.. math::

    \log p(\mathbf{D}_k \mid \mathbf{D}_{1:k-1}, M_i)
      = \underbrace{\log \mathcal{N}(\mathbf{D}^{i}_k;\ \mathbf{H}(\bar\mu_{k,i}),
            C \bar\Sigma_{k,i} C^T + \Sigma_m)}_{\text{Eq. (9), the features } M_i \text{ explains}}
      + (n_k - n^{i}_k) \log c

where ``D^i_k`` are the ``n^i_k`` measured features that model ``M_i`` *explains* and the other
``n_k - n^i_k`` are scored under a clutter density ``c``. Without the clutter term a model that explains
fewer features would be scored on fewer numbers, and its likelihood could not be compared with the
others'; with it, explaining a feature is worth ``log N(d) - log c`` (about 15 nats for a feature at
1 m), and the model that explains more of what is seen wins. The scores update the model probabilities
by Bayes' rule (:mod:`~lab.identification.bayes`); which pose the models are scored at and how the
features every database holds are counted are :mod:`~lab.identification.belief`'s and
:mod:`~lab.identification.shared`'s.

**Eq. (9), per feature.** By default the Gaussian is evaluated as the product of each explained
feature's marginal ``N(d_m; H_m(mu_bar), C_m Sigma_bar C_m^T + Sigma_m)`` (Eq. (12)'s independence,
which the planning uses too). The joint form couples the features through the shared pose uncertainty
``C Sigma_bar C^T``; then one feature that passes its own gate but disagrees with the pose the others
imply costs hundreds of nats (measured: 170 nats for one feature on a shared face), which is more
than a whole view of a unique face is worth. :class:`LikelihoodForm` selects either.

**Explained.** A measured feature ``d`` is explained by ``M_i`` when a database feature ``b_l`` of
``M_i`` has a descriptor within ``max_descriptor_distance`` of ``d``'s *and* passes the geometric gate
under the model's predicted pose (Mahalanobis distance under ``C_l Sigma_bar C_l^T + Sigma_d`` within
the chi-square(3) quantile ``gate_prob``, and within ``dist_max_m``). Geometry, not Lowe's ratio test,
picks among look-alike candidates: a page printed on three faces gives three candidates, at most one of
which is where the pose puts it. A measured feature with several gated candidates (aliases) is
explained **once**, by the candidate nearest in Mahalanobis distance. The plain ratio test is not used
here on purpose: whether it passes depends on the *other* features of a database (a unique face's
feature can be the "second nearest" in one database and not in another), so on a shared face it would
let the four models explain different numbers of the very same features.

**Visible features only (optional).** With ``visibility_deg`` set, a database feature can explain a
measured one only if it was seen in training from (about) the direction the pose puts the camera in:
its ``seen_from`` ring viewpoints include one within ``visibility_deg`` of that direction. It is meant
against a unique face's features near an edge explaining an oblique shared face's (the descriptor
threshold is loose on purpose, the gate a few centimetres). It removes the drift on still frontal
views of shared faces (``tests/test_ident_sim.py``), but in closed-loop episodes with the evasive mover
it left most of the drift and slowed identification, since fewer of the unique face's features count
at oblique views, so it is off by default. How it was chosen: docs/tuning/visibility-rule.md.

**Clutter density.** Uniform over the volume in which the stereo rig can triangulate a feature: the
image frustum between the nearest depth (largest disparity) and ``max_depth_m`` (see
:func:`clutter_log_density`; -4.3, i.e. 1 / 74 m^3, for the default camera and 5 m).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from enum import Enum

import numpy as np

from lab.errors import ConfigError
from lab.estimation import (
    OrientationChart,
    PoseEstimate,
    UpdateOutcome,
    UpdateResult,
    data_log_likelihood,
    rv_to_euler_jacobian,
)
from lab.estimation.fit import chi2_quantile
from lab.geometry import euler_zyx_to_R
from lab.robot import StereoCamera
from lab.vision import FeatureDatabase, Features3D, JointIndex, Matcher, StereoParams

__all__ = [
    "Explanation",
    "LikelihoodForm",
    "ModelScore",
    "ModelScorer",
    "ScoringConfig",
    "clutter_log_density",
    "pose_estimate_rv",
    "state_for_scoring",
]


def clutter_log_density(
    camera: StereoCamera, stereo: StereoParams | None = None, max_depth_m: float = 5.0
) -> float:
    r"""``log c``: a density uniform over the volume where the stereo rig can triangulate a feature.

    The image frustum between ``Z_min = f_x B / max_disparity`` and ``Z_max = min(f_x B /
    min_disparity, max_depth_m)``; a slice at depth ``Z`` is ``(W Z / f_x) (H Z / f_y)``, so

    .. math:: V = \frac{W H}{f_x f_y} \frac{Z_{max}^3 - Z_{min}^3}{3}, \qquad \log c = -\log V

    Parameters
    ----------
    camera : StereoCamera
    stereo : StereoParams, optional
        Its disparity range bounds the depths.
    max_depth_m : float [m]
        Farthest depth counted (the stereo range reaches tens of metres, but a room ends well before).

    Returns
    -------
    float [log of 1/m^3]
    """
    stereo = stereo or StereoParams()
    if not max_depth_m > 0:
        raise ConfigError(f"max_depth_m must be > 0 m, got {max_depth_m}")
    fB = camera.fx * camera.baseline
    z_min = fB / stereo.max_disparity
    z_max = min(fB / stereo.min_disparity, max_depth_m)
    if z_max <= z_min:
        raise ConfigError(
            f"max_depth_m {max_depth_m} m is nearer than the stereo range's start {z_min:.3f} m"
        )
    volume = camera.width * camera.height / (camera.fx * camera.fy) * (z_max**3 - z_min**3) / 3.0
    return -math.log(volume)


_LOG_2PI = math.log(2.0 * math.pi)


class LikelihoodForm(Enum):
    """How Eq. (9) is evaluated over the features a model explains."""

    #: Product of each feature's marginal ``N(d_m; H_m(mu_bar), C_m Sigma_bar C_m^T + Sigma_m)``: Eq. (12)'s
    #: independence assumption, as the planning uses it (the default; module docstring).
    PER_FEATURE = "per_feature"
    #: One Gaussian over all of them, ``N(D; H(mu_bar), C Sigma_bar C^T + Sigma_m)``: exact for correct
    #: associations, but one feature that passes its own gate and disagrees with the others' pose costs
    #: hundreds of nats (measured on shared faces).
    JOINT = "joint"


@dataclass(frozen=True)
class ScoringConfig:
    """How a frame is scored against the models and how the probabilities are updated.

    Attributes
    ----------
    max_descriptor_distance : float
        A database feature can explain a measured one only when their SIFT descriptors are closer than
        this (L2, OpenCV scale, descriptor norms ~512). Measured on the box databases: the shared page
        matches across models at 150-250, unrelated textures are farther.
    k_neighbours : int
        Nearest database descriptors considered per measured feature (look-alikes on several faces).
    gate_prob : float
        Chi-square(3) probability of the geometric gate (0.999 -> 16.27), as the EKF's.
    dist_max_m : float [m]
        Euclidean gate on the residual, as the EKF's.
    log_clutter_density : float or None [log 1/m^3]
        ``log c`` of an unexplained feature. None (the default): from the robot's camera, filled in by
        :meth:`for_camera` (:func:`clutter_log_density`; -4.3 for the 320 x 240, 60 degree, 0.12 m
        camera). A scorer needs it resolved (:meth:`require_clutter_density`).
    evidence_weight : float
        ``kappa`` in (0, 1]: each frame's log-likelihood is multiplied by it
        (:mod:`~lab.identification.bayes`).
    floor : float
        Smallest probability a model keeps (:mod:`~lab.identification.bayes`); ``L * floor`` must be < 1.
    likelihood : LikelihoodForm
        Per-feature product (default) or joint Gaussian.
    share_poses : bool
        Score the models at the filters' poses (:mod:`~lab.identification.belief`); False: each model
        at its own filter's pose only.
    common_pose : bool
        With ``share_poses``: every model at the one pose that makes the frame most probable under the
        current belief (default); False: each model at its own best pose (a profile likelihood).
    visibility_deg : float or None [deg]
        A database feature explains only from directions within this angle of a training viewpoint
        that saw it (module docstring; 15 suits the 10-degree ring). None (default): any direction.
    pool_shared : bool
        Count shared evidence identically for every model (:mod:`~lab.identification.shared`).
    shared_radius_m : float [m]
        A database feature's counterpart in another database is within this distance in O ...
    shared_region_m : float [m]
        ... and a database feature is shared when, within this distance of it, ...
    shared_region_fraction : float
        ... at least this fraction of its database's features have counterparts in every other one.
    """

    max_descriptor_distance: float = 250.0
    k_neighbours: int = 8
    gate_prob: float = 0.999
    dist_max_m: float = 0.15
    log_clutter_density: float | None = None
    evidence_weight: float = 0.008
    floor: float = 1e-3
    likelihood: LikelihoodForm = LikelihoodForm.PER_FEATURE
    share_poses: bool = True
    common_pose: bool = True
    visibility_deg: float | None = None
    pool_shared: bool = True
    shared_radius_m: float = 0.01
    shared_region_m: float = 0.05
    shared_region_fraction: float = 0.5

    def __post_init__(self):
        if not self.max_descriptor_distance > 0:
            raise ConfigError(f"max_descriptor_distance must be > 0, got {self.max_descriptor_distance}")
        if int(self.k_neighbours) != self.k_neighbours or self.k_neighbours < 1:
            raise ConfigError(f"k_neighbours must be a positive integer, got {self.k_neighbours}")
        if not 0.0 < self.gate_prob < 1.0:
            raise ConfigError(f"gate_prob must be within (0, 1), got {self.gate_prob}")
        if not self.dist_max_m > 0:
            raise ConfigError(f"dist_max_m must be > 0 m, got {self.dist_max_m}")
        if self.log_clutter_density is not None and not math.isfinite(self.log_clutter_density):
            raise ConfigError(f"log_clutter_density must be finite, got {self.log_clutter_density}")
        if not 0.0 < self.evidence_weight <= 1.0:
            raise ConfigError(f"evidence_weight must be within (0, 1], got {self.evidence_weight}")
        if not 0.0 <= self.floor < 0.5:
            raise ConfigError(f"floor must be within [0, 0.5), got {self.floor}")
        if self.visibility_deg is not None and not 0.0 < self.visibility_deg <= 180.0:
            raise ConfigError(f"visibility_deg must be within (0, 180] or None, got {self.visibility_deg}")
        if not (self.shared_radius_m > 0 and self.shared_region_m >= 0):
            raise ConfigError(
                f"shared_radius_m must be > 0 m and shared_region_m >= 0 m, got {self.shared_radius_m}, "
                f"{self.shared_region_m}"
            )
        if not 0.0 < self.shared_region_fraction <= 1.0:
            raise ConfigError(
                f"shared_region_fraction must be within (0, 1], got {self.shared_region_fraction}"
            )

    def for_camera(self, camera: StereoCamera, stereo: StereoParams | None = None) -> ScoringConfig:
        """This config with the clutter density of ``camera`` filled in where it is None.

        Parameters
        ----------
        camera : StereoCamera
            The robot's camera (``robot.camera``): its image size, focal lengths and baseline bound the
            volume :func:`clutter_log_density` spreads a clutter feature over.
        stereo : StereoParams, optional
            The stereo matcher's disparity range (default: :class:`~lab.vision.StereoParams`).

        Returns
        -------
        ScoringConfig
            ``self`` when it already has an explicit ``log_clutter_density``; else a copy with
            ``clutter_log_density(camera, stereo)``.
        """
        if self.log_clutter_density is not None:
            return self
        return replace(self, log_clutter_density=clutter_log_density(camera, stereo))

    def require_clutter_density(self) -> float:
        """``log_clutter_density``, or a :class:`~lab.errors.ConfigError` where it was never resolved."""
        if self.log_clutter_density is None:
            raise ConfigError(
                "the ScoringConfig has no clutter density (log_clutter_density is None): build it from "
                "the robot's camera with ScoringConfig(...).for_camera(robot.camera)"
            )
        return self.log_clutter_density


@dataclass(frozen=True)
class Explanation:
    """Which measured features one model explains (at most one database feature each).

    Attributes
    ----------
    explained : ndarray, shape (n,), bool
    idx_db : ndarray, shape (n,), int
        The explaining database feature (-1 where unexplained).
    m2 : ndarray, shape (n,)
        Its squared Mahalanobis distance (inf where unexplained).
    log_density : ndarray, shape (n,)
        ``log N(d; H(mu_bar, b_l), C_l Sigma_bar C_l^T + Sigma_d)`` of the explaining feature
        (-inf where unexplained).
    """

    explained: np.ndarray = field(repr=False)
    idx_db: np.ndarray = field(repr=False)
    m2: np.ndarray = field(repr=False)
    log_density: np.ndarray = field(repr=False)

    @property
    def n_explained(self) -> int:
        return int(np.count_nonzero(self.explained))

    @classmethod
    def none(cls, n: int) -> Explanation:
        return cls(np.zeros(n, bool), np.full(n, -1), np.full(n, np.inf), np.full(n, -np.inf))


@dataclass(frozen=True)
class ModelScore:
    """One model's score on one frame.

    Attributes
    ----------
    log_likelihood : float
        ``log p(D_k | D_{1:k-1}, M_i)``: Eq. (9) over the explained features plus ``log c`` for each
        other feature (not yet multiplied by the evidence weight).
    log_likelihood_explained : float
        The Eq. (9) part alone (0 when nothing is explained).
    n_explained, n_features : int
    explanation : Explanation
    """

    log_likelihood: float
    log_likelihood_explained: float
    n_explained: int
    n_features: int
    explanation: Explanation = field(repr=False)


def pose_estimate_rv(mu, Sigma_rv, t: float = 0.0) -> PoseEstimate:
    """A :class:`PoseEstimate` from a covariance over ``[x_r, phi]`` (the rotation-vector chart).

    Its Euler covariance is derived (and may be huge near gimbal lock, where it is not used here).
    """
    mu = np.asarray(mu, dtype=float)
    T_inv = rv_to_euler_jacobian(mu)
    with np.errstate(over="ignore", invalid="ignore"):
        Sigma = T_inv @ np.asarray(Sigma_rv, dtype=float) @ T_inv.T
    return PoseEstimate(mu, np.nan_to_num(Sigma, posinf=1e12, neginf=-1e12), t, Sigma_rv=Sigma_rv)


def state_for_scoring(predicted: PoseEstimate | None, result: UpdateResult | None) -> PoseEstimate | None:
    """The pose to score a frame with, for one model (the ``mu_bar, Sigma_bar`` of Eqs. (8)-(9)).

    * the filter was (re-)initialised by this frame: its new estimate (there was no prediction);
    * else the prediction made before the update (``EKFBank.predict``'s output for this model);
    * else None: the model has no pose yet and explains nothing.
    """
    if result is not None and result.outcome in (UpdateOutcome.INITIALIZED, UpdateOutcome.REINITIALIZED):
        return result.estimate
    return predicted


def _predicted_covariance(q: np.ndarray, Sigma_rv: np.ndarray) -> np.ndarray:
    """``C_l Sigma_bar C_l^T`` (m, 3, 3), ``Sigma_bar`` (6, 6) or one per row (m, 6, 6), for
    ``C_l = [I, -[q_l]_x]`` (the rotation-vector chart's Jacobian of ``H`` at ``q_l = R b_l``), written
    out in the 3x3 blocks ``A, B; B^T, D`` of ``Sigma_bar``: ``A + Q B^T + B Q^T + Q D Q^T`` with
    ``Q = -[q_l]_x``."""
    A, B, D = Sigma_rv[..., :3, :3], Sigma_rv[..., :3, 3:], Sigma_rv[..., 3:, 3:]
    Q = np.zeros((len(q), 3, 3))
    x, y, z = q[:, 0], q[:, 1], q[:, 2]
    Q[:, 0, 1], Q[:, 0, 2] = z, -y  # -[q]_x
    Q[:, 1, 0], Q[:, 1, 2] = -z, x
    Q[:, 2, 0], Q[:, 2, 1] = y, -x
    QBt = Q @ np.swapaxes(B, -1, -2)  # Q B^T
    return A + QBt + np.swapaxes(QBt, 1, 2) + Q @ D @ np.swapaxes(Q, 1, 2)


def _mahalanobis_3(S: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``r^T S^-1 r`` and ``log|S|`` of m symmetric positive definite 3x3 matrices (m, 3, 3) and
    residuals (m, 3), by the Cholesky factor written out (no LAPACK call per matrix). A matrix that is
    not positive definite gives NaN (its candidate then fails the gate)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        l11 = np.sqrt(S[:, 0, 0])
        l21 = S[:, 1, 0] / l11
        l31 = S[:, 2, 0] / l11
        l22 = np.sqrt(S[:, 1, 1] - l21 * l21)
        l32 = (S[:, 2, 1] - l31 * l21) / l22
        l33 = np.sqrt(S[:, 2, 2] - l31 * l31 - l32 * l32)
        y1 = r[:, 0] / l11  # L y = r, forward substitution
        y2 = (r[:, 1] - l21 * y1) / l22
        y3 = (r[:, 2] - l31 * y1 - l32 * y2) / l33
        m2 = y1 * y1 + y2 * y2 + y3 * y3
        logdet = 2.0 * (np.log(l11) + np.log(l22) + np.log(l33))
    return m2, logdet


class ModelScorer:
    """Scores measured feature sets against one database model (module docstring).

    Parameters
    ----------
    db : FeatureDatabase
    config : ScoringConfig
        With its clutter density resolved (:meth:`ScoringConfig.for_camera`); else
        :class:`~lab.errors.ConfigError`.
    index : JointIndex, optional
        One index over every model's database, searched once a frame for all of them
        (:class:`~lab.vision.JointIndex`: the same neighbours as this model's own exact search) ...
    model : int
        ... in which ``db`` is database ``model``.
    """

    def __init__(
        self, db: FeatureDatabase, config: ScoringConfig, index: JointIndex | None = None, model: int = 0
    ):
        config.require_clutter_density()
        self.db = db
        self.config = config
        self._matcher = Matcher(db, method="brute", k=self.config.k_neighbours)
        if index is not None and not (
            0 <= model < len(index.dbs) and index.dbs[model] is db and index.k[model] == self._matcher.k
        ):
            raise ConfigError(
                f"the joint index's database {model} must be this scorer's ({db.name}), searched for "
                f"{self._matcher.k} neighbours"
            )
        self._index, self._model = index, model
        self._gate_m2 = chi2_quantile(self.config.gate_prob, 3)
        self._nn_cache: tuple | None = None  # (features, idx, dist) of the last feature set
        self._cand_cache: tuple | None = None  # (features, its descriptor candidates)
        self._shared: tuple | None = None  # (ids of the group's databases, shared_features mask)
        self._view_dirs = None
        if self.config.visibility_deg is not None and db.seen_from.size:
            from lab.identification.viewpoints import viewpoint_directions

            self._view_dirs = viewpoint_directions(db.viewpoints)  # (V, 3) unit vectors in O

    def visible(self, estimate: PoseEstimate) -> np.ndarray | None:
        """Which database features the camera can see at ``estimate`` (N,) bool, or None (all): those a
        training viewpoint within ``visibility_deg`` of the camera's direction in O saw."""
        if self._view_dirs is None:
            return None
        from lab.identification.viewpoints import camera_direction_O

        u = camera_direction_O(estimate.G_CO)
        near = self._view_dirs @ u >= math.cos(math.radians(self.config.visibility_deg))
        return self.db.seen_from[:, near].any(axis=1)

    @property
    def k_neighbours(self) -> int:
        """Nearest database descriptors searched per measured feature (at most the database's size)."""
        return self._matcher.k

    def neighbours(self, features: Features3D) -> tuple[np.ndarray, np.ndarray]:
        """The exact ``k_neighbours`` nearest database descriptors of each measured feature (indices
        and L2 distances, (n, k) each, nearest first). They do not depend on the pose, so a frame
        scored at several poses (pose sharing, look-alike turns) searches once, and the EKF's matcher
        reuses the same search (:func:`~lab.identification.step.observe_frame`)."""
        return self._neighbours(features)

    def _neighbours(self, features: Features3D) -> tuple[np.ndarray, np.ndarray]:
        c = self._nn_cache
        if c is not None and c[0] is features:
            return c[1], c[2]
        if self._index is not None:  # every model's search at once, kept by the index for the others
            idx, dist = self._index.neighbours(features.descriptors)[self._model]
        else:
            idx, dist = self._matcher.neighbours(features.descriptors)
        self._nn_cache = (features, idx, dist)
        return idx, dist

    @property
    def name(self) -> str:
        return self.db.name

    def _candidates(self, features: Features3D):
        """The frame's descriptor candidates, which do not depend on the pose: ``(rows, l, d, Sigma_d,
        b)``, the measured feature, the database feature within ``max_descriptor_distance`` of it, the
        measured point, its covariance and the database point (kept for the frame's other poses)."""
        c = self._cand_cache
        if c is not None and c[0] is features:
            return c[1]
        idx, dist = self._neighbours(features)  # (n, k) nearest descriptors
        rows, cols = np.nonzero(dist < self.config.max_descriptor_distance)
        l = idx[rows, cols]
        out = (rows, l, features.points_C[rows], features.covariances[rows], self.db.points_O[l])
        self._cand_cache = (features, out)
        return out

    def explain(self, features: Features3D, estimate: PoseEstimate | None) -> Explanation:
        """Which measured features the model explains at pose ``estimate`` (object in the camera C);
        :meth:`explain_many` with one pose."""
        return self.explain_many(features, [estimate])[0]

    def explain_many(
        self, features: Features3D, estimates: Sequence[PoseEstimate | None]
    ) -> list[Explanation]:
        r"""Which measured features the model explains at each of the poses (object in the camera C).

        For each pose and descriptor candidate ``(d, b_l)`` (found once per frame): the residual
        ``r = d - H(mu_bar, b_l)`` (Eq. (3)), the Euclidean gate ``|r| <= dist_max_m`` first (it
        needs no covariance, and rejects most look-alike candidates), then on those left the
        Mahalanobis gate under ``S = C_l Sigma_bar C_l^T + Sigma_d`` with ``C_l = [I, -[R b_l]_x]``
        (the rotation-vector chart), by a closed-form 3x3 Cholesky factor ``S = L L^T``:

        .. math:: m^2 = |L^{-1} r|^2, \qquad \log|S| = 2 \textstyle\sum_i \log L_{ii}

        All poses are evaluated in one vectorised pass (a frame is scored at every filter's pose and
        its look-alike turns). ``tests/test_ident_probabilities.py`` checks the result against a dense
        per-candidate reference.
        """
        n = len(features)
        out = [Explanation.none(n) for _ in estimates]
        live = [k for k, e in enumerate(estimates) if e is not None]
        if n == 0 or len(self.db) == 0 or not live:
            return out
        cfg = self.config
        rows, l, d, Sd, b = self._candidates(features)
        if len(rows) == 0:
            return out
        mus = np.array([np.asarray(estimates[k].mu, dtype=float) for k in live])  # (P, 6)
        R = np.stack([euler_zyx_to_R(mu[3], mu[4], mu[5]) for mu in mus])  # (P, 3, 3)
        q = b[None] @ np.swapaxes(R, 1, 2)  # R b_l, (P, m, 3)
        r = d[None] - (q + mus[:, None, :3])  # d - H(mu_bar, b_l), Eq. (3)
        near = np.linalg.norm(r, axis=2) <= cfg.dist_max_m  # the Euclidean gate, (P, m)
        for c, k in enumerate(live):
            vis = self.visible(estimates[k])
            if vis is not None:  # only features the camera can see from there
                near[c] &= vis[l]
        pc, j = np.nonzero(near)  # (pose, candidate) pairs left, by pose then candidate
        Sigma_bar = np.stack([np.asarray(estimates[k].Sigma_rv, dtype=float) for k in live])
        S = _predicted_covariance(q[pc, j], Sigma_bar[pc]) + Sd[j]  # C Sigma_bar C^T + Sigma_d
        m2, logdet = _mahalanobis_3(S, r[pc, j])
        ok = m2 <= self._gate_m2
        pc, j, m2, logdet = pc[ok], j[ok], m2[ok], logdet[ok]
        # one database feature per measured feature and pose: the candidate nearest in Mahalanobis
        # distance (exact ties: the first candidate)
        key = pc * n + rows[j]
        best_m2 = np.full(len(live) * n, np.inf)
        np.minimum.at(best_m2, key, m2)
        win = np.flatnonzero(m2 == best_m2[key])
        win = win[np.unique(key[win], return_index=True)[1]]
        idx_db = np.full(len(live) * n, -1)
        idx_db[key[win]] = l[j[win]]
        log_density = np.full(len(live) * n, -np.inf)
        log_density[key[win]] = -0.5 * (m2[win] + logdet[win] + 3 * _LOG_2PI)
        explained = idx_db >= 0
        best_m2 = np.where(explained, best_m2, np.inf)
        for c, k in enumerate(live):
            sl = slice(c * n, (c + 1) * n)
            out[k] = Explanation(explained[sl], idx_db[sl], best_m2[sl], log_density[sl])
        return out

    def score(self, features: Features3D, estimate: PoseEstimate | None) -> ModelScore:
        """``log p(D_k | D_{1:k-1}, M_i)`` on the whole feature set (module docstring)."""
        return self._scored(features, estimate, self.explain(features, estimate))

    def score_many(self, features: Features3D, estimates: Sequence[PoseEstimate | None]) -> list[ModelScore]:
        """:meth:`score` at each of the poses (one vectorised :meth:`explain_many`)."""
        return [
            self._scored(features, x, e)
            for x, e in zip(estimates, self.explain_many(features, estimates), strict=True)
        ]

    def _scored(self, features: Features3D, estimate: PoseEstimate | None, e: Explanation) -> ModelScore:
        n = len(features)
        ll_expl = 0.0
        if e.n_explained and self.config.likelihood is LikelihoodForm.PER_FEATURE:
            ll_expl = float(np.sum(e.log_density[e.explained]))  # Eq. (9) as Eq. (12)'s product
        elif e.n_explained:
            sel = e.explained
            ll_expl = data_log_likelihood(  # Eq. (9), one joint Gaussian over the explained features
                features.points_C[sel],
                self.db.points_O[e.idx_db[sel]],
                features.covariances[sel],
                estimate.mu,
                estimate.Sigma_rv,
                chart=OrientationChart.ROTATION_VECTOR,
            )
        ll = ll_expl + (n - e.n_explained) * self.config.log_clutter_density  # clutter for the rest
        return ModelScore(float(ll), float(ll_expl), e.n_explained, n, e)
