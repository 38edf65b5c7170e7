r"""Model probabilities: Bayes' rule over the L database models, Eqs. (5) and (7)-(9) of the
identification paper, and the paper's *calcCurrentEntropy*.

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
1 m), and the model that explains more of what is seen wins.

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

**Shared poses.** All models have the same geometry; they differ in their textures. A model's filter
that locked onto a look-alike pose (the box turned by 90 degrees: another copy of the shared page in
front) explains a slightly different set of features than one that did not, and that difference says
nothing about which model is right. So, by default, all models are scored at **one common pose**
(``share_poses`` with ``common_pose``): the filter pose ``x_c`` under which the frame is most probable
given the current belief,

.. math::

    c^* = \operatorname{argmax}_c \log \sum_i P(M_i \mid \mathbf{D}_{1:k-1})\,
          p(\mathbf{D}_k \mid x_c, M_i)^{\kappa},

since there is one box and only its identity is in doubt. Letting each model keep its *own* best pose
instead (``common_pose=False``: a profile likelihood per model) lets a model collect, frame after frame,
the few coincidental descriptor matches that a look-alike pose off by a quarter-turn gives its
database near its unique face; on shared faces that bias drifted the probabilities towards a wrong
model (measured: P(M0) = 0.72 for a true M2 in 47 s of shared faces, the 3 filters that started on a
wrong quarter-turn). At one common pose, shared faces are explained by every model alike, and on a
view of the unique face of ``M_k`` the pose that explains it wins and the other models explain none of it.

**Shared evidence.** The models share three faces, but their databases were trained apart: a feature
of a shared page may be in one database and not in another (SIFT finds slightly different keypoints
next to each model's unique face, the training merges views slightly differently), or sit a few
millimetres elsewhere and fail the gate. Each such difference is worth ~15 nats, and they do not
average out: a frame of shared faces explains, say, 13 features for ``M0`` and 12 for the others
whatever the true model, and frame after frame the posterior drifted towards ``M0`` (measured: P(M0) =
0.58, P(M3) = 0.06 for a true ``M3`` after 40 s of shared faces with the random planner). So, by default
(``pool_shared``), what every database holds counts identically for every model:

* a database feature is **shared** when, around it (within ``shared_region_m`` in O), at least
  ``shared_region_fraction`` of its database's features have a counterpart in *every* other database
  (a feature within ``shared_radius_m`` of the same object-frame position whose descriptor is closer
  than ``max_descriptor_distance``), and its own descriptor is that close to some feature of every
  other database (:func:`shared_features`; on the boxes: none of the unique face's, all of the
  shared face opposite it and 86-95 % of the two beside it, whose edges with the unique face stay
  the models' own);
* a measured feature that any model explains with a shared database feature is **shared evidence**:
  every model is scored as explaining it, with the same density, the best of those models'
  ``log N(d; ...)``. It then cancels in Eq. (7); only the other features (the unique faces', and
  whatever one database alone explains) tell the models apart:

.. math::

    \log p(\mathbf{D}_k \mid \cdot, M_i) = \sum_{m \in S} \max_j \log \mathcal{N}_j(\mathbf{d}_m)
      + \sum_{m \in E_i \setminus S} \log \mathcal{N}_i(\mathbf{d}_m)
      + (n_k - |S| - |E_i \setminus S|) \log c

with ``S`` the shared evidence and ``E_i`` the features ``M_i`` explains. It applies where all models
are scored at the one common pose (the default), so that "the same object-frame position" means the
same place in the image, and to the per-feature form of Eq. (9) (the joint form is left as it is).
The expected entropy predicts the same rule (:func:`pools_shared_evidence`): the lookup-table evaluator
counts only the features of ``M_j`` that are not shared (the tables themselves, and their cache key,
do not depend on it: the masks are applied when ``W`` is sampled), and the Monte Carlo evaluator pools
its sampled features as :func:`pool_shared_evidence` does. Without that, both expect to learn from
views of shared faces where one database lacks some of their features (measured on synthetic
databases missing 6 of 30 features per shared face: gains of 0.06 and 0.03 nats, against < 0.01
pooled; ``tests/test_ident_planning.py``).

**Visible features only (optional).** With ``visibility_deg`` set, a database feature can explain a
measured one only if it was seen in training from (about) the direction the pose puts the camera in:
its ``seen_from`` ring viewpoints include one within ``visibility_deg`` of that direction. It is meant
against a unique face's features near an edge explaining an oblique shared face's (the descriptor
threshold is loose on purpose, the gate a few centimetres). Measured: on still frontal views of shared
faces it takes the largest deviation from uniform from 0.045 to 0.001 (``tests/test_ident_sim.py``),
but in closed-loop episodes with the evasive mover it left the drift on shared faces at about 0.1 (0.15
without) and slowed identification (5-6 planning actions instead of 3-4, 3 episodes, since fewer of the
unique face's features count at oblique views), so it is off by default.

**Clutter density.** Uniform over the volume in which the stereo rig can triangulate a feature: the
image frustum between the nearest depth (largest disparity) and ``max_depth_m`` (see
:func:`clutter_log_density`; -4.3, i.e. 1 / 74 m^3, for the default camera and 5 m).

**Evidence weight.** Eq. (12)'s assumption that features are independent makes a frame's
log-likelihood a sum of n terms of ~16 nats; but the features of one frame share one render, one pose
error and one matching pass, and successive frames of a still scene repeat them. Taken at face value, a
single feature that one database happens to lack on a shared face would decide between models that
look identical there. Each frame's log-likelihood is therefore multiplied by ``evidence_weight``
(kappa, a "power likelihood"):

.. math::

    P(M_i \mid \mathbf{D}_{1:k}) \propto p(\mathbf{D}_k \mid \mathbf{D}_{1:k-1}, M_i)^{\kappa}\,
        P(M_i \mid \mathbf{D}_{1:k-1})            \qquad \text{Eq. (7)}

The default, 0.008, makes one explained feature worth ~0.12 nats: a view of a model's unique face
(15-35 features that only it explains) identifies it in two or three frames, while the one-feature
differences that matching noise leaves between models on shared faces move the probabilities by a few
percent at most (measured on rendered frames at 0.9-1.1 m: unique faces reach >= 0.95 within 3
frames, shared faces stay within 0.045 of uniform; 0.005 leaves a unique face short of 0.95 at 1.1 m,
0.01 lets shared faces drift by 0.054). The planning (Monte Carlo and lookup tables) uses the same
weight, so expected and actual updates agree.

**Floor.** After normalising in log space, no probability is allowed below ``floor`` (1e-3 by default):
probabilities below it are raised to it and the others scaled down so that the sum stays 1
(:func:`apply_floor`). A model knocked out by one bad frame (a mismatch, a lost track) comes back as
soon as the evidence favours it (log(1e-3) is ~7 nats: some 60 features more than the others explain,
two or three frames of its unique face), and a
frame that carries no evidence leaves the probabilities exactly as they were (the floor is idempotent;
it is not a mixing with the uniform distribution, which would drift every model towards 1/L).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import Enum

import numpy as np

from lab.errors import ConfigError
from lab.estimation import (
    OrientationChart,
    PoseEstimate,
    UpdateOutcome,
    UpdateResult,
    data_log_likelihood,
    measurement_jacobian_rv,
    measurement_model,
    rv_to_euler_jacobian,
)
from lab.estimation.fit import chi2_quantile
from lab.robot import StereoCamera
from lab.vision import FeatureDatabase, Features3D, Matcher, StereoParams

__all__ = [
    "Belief",
    "Explanation",
    "LikelihoodForm",
    "ModelScore",
    "ModelScorer",
    "ScoringConfig",
    "apply_floor",
    "calc_current_entropy",
    "clutter_log_density",
    "entropy",
    "pose_estimate_rv",
    "pool_shared_evidence",
    "pools_shared_evidence",
    "posterior",
    "shared_features",
    "shared_masks",
    "state_for_scoring",
    "uniform",
    "update_model_probabilities",
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
_DEFAULT_LOG_CLUTTER = clutter_log_density(StereoCamera.from_fov(320, 240, 60.0, 0.12))


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
    log_clutter_density : float [log 1/m^3]
        ``log c`` of an unexplained feature (default: :func:`clutter_log_density` of the default
        camera, -4.3).
    evidence_weight : float
        ``kappa`` in (0, 1]: each frame's log-likelihood is multiplied by it (module docstring).
    floor : float
        Smallest probability a model keeps (module docstring); ``L * floor`` must be < 1.
    likelihood : LikelihoodForm
        Per-feature product (default) or joint Gaussian.
    share_poses : bool
        Score the models at the filters' poses (module docstring); False: each model at its own
        filter's pose only.
    common_pose : bool
        With ``share_poses``: every model at the one pose that makes the frame most probable under the
        current belief (default); False: each model at its own best pose (a profile likelihood).
    visibility_deg : float or None [deg]
        A database feature explains only from directions within this angle of a training viewpoint
        that saw it (module docstring; 15 suits the 10-degree ring). None (default): any direction.
    pool_shared : bool
        Count shared evidence identically for every model (module docstring, "Shared evidence").
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
    log_clutter_density: float = _DEFAULT_LOG_CLUTTER
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
        if not math.isfinite(self.log_clutter_density):
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


# --- probabilities and entropy ------------------------------------------------------------------------


def uniform(n_models: int) -> np.ndarray:
    """The prior ``P_{0,i} = 1 / L`` (the paper's a-priori values when nothing favours a model)."""
    if int(n_models) != n_models or n_models < 1:
        raise ConfigError(f"the number of models must be a positive integer, got {n_models!r}")
    return np.full(int(n_models), 1.0 / n_models)


def _check_probabilities(P, name: str = "P") -> np.ndarray:
    P = np.asarray(P, dtype=float)
    if P.ndim != 1 or len(P) == 0:
        raise ConfigError(f"{name} must be a non-empty vector of model probabilities, got shape {P.shape}")
    if not np.all(np.isfinite(P)) or np.any(P < 0) or abs(P.sum() - 1.0) > 1e-6:
        raise ConfigError(f"{name} must be finite, >= 0 and sum to 1, got {P}")
    return P


def apply_floor(P, floor: float) -> np.ndarray:
    """Raise probabilities below ``floor`` to it and scale the others so that the sum stays 1.

    The result is ``max(floor, s P_i)`` with the one scale ``s`` that makes it sum to 1. Idempotent: a
    vector that already respects the floor is returned unchanged. Works along the last axis of an
    array of probability vectors. Requires ``L * floor < 1`` (:class:`~lab.errors.ConfigError`).
    """
    P = np.asarray(P, dtype=float)
    L = P.shape[-1]
    P = P / P.sum(axis=-1, keepdims=True)
    if floor <= 0.0:
        return P
    if L * floor >= 1.0:
        raise ConfigError(f"floor {floor} is too large for {L} models (need L * floor < 1)")
    low = P < floor
    out = P
    for _ in range(L):  # the set of floored entries only grows: at most L rounds (usually 1 or 2)
        n_low = low.sum(axis=-1, keepdims=True)
        rest = np.where(low, 0.0, P).sum(axis=-1, keepdims=True)
        out = np.where(low, floor, P * ((1.0 - floor * n_low) / rest))
        new_low = low | (out < floor)
        if not np.any(new_low != low):
            break
        low = new_low
    return out


def entropy(P) -> float | np.ndarray:
    r"""Model entropy, Eq. (5): ``H(M) = -sum_i P(M_i) log P(M_i)`` [nats], in ``[0, log L]``.

    .. math::

        H(M \mid \mathbf{D}_{1:k}, \mathbf{u}_{1:k-1}) = -\sum_i P(M_i \mid \cdot) \log P(M_i \mid \cdot)

    ``0 log 0`` is taken as 0. A float for one vector; along the last axis for an array of them.
    """
    P = np.asarray(P, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        terms = np.where(P > 0, P * np.log(np.where(P > 0, P, 1.0)), 0.0)
    H = np.maximum(0.0, -terms.sum(axis=-1))
    return float(H) if H.ndim == 0 else H


def posterior(log_prior, log_likelihoods, config: ScoringConfig) -> np.ndarray:
    """Eq. (7) for arrays: ``log_prior`` (L,) and ``log_likelihoods`` (..., L) -> posteriors (..., L)
    (the evidence weight, normalisation in log space and the floor, as :func:`update_model_probabilities`)."""
    log_post = np.asarray(log_prior, dtype=float) + config.evidence_weight * np.asarray(
        log_likelihoods, float
    )
    log_post = log_post - np.max(log_post, axis=-1, keepdims=True)
    return apply_floor(np.exp(log_post), config.floor)


def update_model_probabilities(prior, log_likelihoods, config: ScoringConfig | None = None) -> np.ndarray:
    r"""Bayes' rule, Eq. (7), in log space, with the evidence weight and the floor.

    .. math::

        P(M_i \mid \mathbf{D}_{1:k}) =
            \frac{p(\mathbf{D}_k \mid \cdot, M_i)^{\kappa}\, P(M_i \mid \mathbf{D}_{1:k-1})}
                 {\sum_j p(\mathbf{D}_k \mid \cdot, M_j)^{\kappa}\, P(M_j \mid \mathbf{D}_{1:k-1})}

    Parameters
    ----------
    prior : array_like, shape (L,)
        ``P(M_i | D_{1:k-1})``; sums to 1.
    log_likelihoods : array_like, shape (L,)
        ``log p(D_k | D_{1:k-1}, M_i)`` of every model on the same ``D_k`` (see :class:`ModelScorer`).
    config : ScoringConfig, optional

    Returns
    -------
    ndarray, shape (L,)
        The posterior: sums to 1, every entry >= ``config.floor``.
    """
    config = config or ScoringConfig()
    prior = _check_probabilities(prior, "prior")
    ll = np.asarray(log_likelihoods, dtype=float)
    if ll.shape != prior.shape:
        raise ConfigError(f"need one log-likelihood per model: {ll.shape} for {len(prior)} models")
    if np.any(np.isnan(ll)) or np.any(ll == np.inf):
        raise ConfigError(f"log-likelihoods must be finite or -inf, got {ll}")
    with np.errstate(divide="ignore"):
        log_post = np.log(prior) + config.evidence_weight * ll  # log of Eq. (7)'s numerator
    top = np.max(log_post)
    if not np.isfinite(top):  # every model impossible: nothing was learnt
        return apply_floor(prior, config.floor)
    P = np.exp(log_post - top)  # normalise in log space (log-sum-exp)
    return apply_floor(P / P.sum(), config.floor)


# --- scoring one frame against one model --------------------------------------------------------------


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


class ModelScorer:
    """Scores measured feature sets against one database model (module docstring).

    Parameters
    ----------
    db : FeatureDatabase
    config : ScoringConfig, optional
    """

    def __init__(self, db: FeatureDatabase, config: ScoringConfig | None = None):
        self.db = db
        self.config = config or ScoringConfig()
        self._matcher = Matcher(db, method="brute", k=self.config.k_neighbours)
        self._gate_m2 = chi2_quantile(self.config.gate_prob, 3)
        self._nn_cache: tuple | None = None  # (features, idx, dist) of the last feature set
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
        idx, dist = self._matcher.neighbours(features.descriptors)
        self._nn_cache = (features, idx, dist)
        return idx, dist

    @property
    def name(self) -> str:
        return self.db.name

    def explain(self, features: Features3D, estimate: PoseEstimate | None) -> Explanation:
        """Which measured features the model explains at pose ``estimate`` (object in the camera C)."""
        n = len(features)
        if estimate is None or n == 0 or len(self.db) == 0:
            return Explanation.none(n)
        cfg = self.config
        idx, dist = self._neighbours(features)  # (n, k) nearest descriptors
        rows, cols = np.nonzero(dist < cfg.max_descriptor_distance)
        l = idx[rows, cols]
        vis = self.visible(estimate)
        if vis is not None:  # only features the camera can see from there
            rows, l = rows[vis[l]], l[vis[l]]
        if len(rows) == 0:
            return Explanation.none(n)
        b = self.db.points_O[l]
        r = features.points_C[rows] - measurement_model(estimate.mu, b)  # d - H(mu_bar, b_l), Eq. (3)
        C = measurement_jacobian_rv(estimate.mu, b).reshape(-1, 3, 6)
        S = (
            C @ estimate.Sigma_rv @ np.swapaxes(C, 1, 2) + features.covariances[rows]
        )  # C Sigma_bar C^T + Sigma_d
        m2 = np.einsum("na,na->n", r, np.linalg.solve(S, r[..., None])[..., 0])
        ok = (m2 <= self._gate_m2) & (np.linalg.norm(r, axis=1) <= cfg.dist_max_m)
        rows, l, m2, S = rows[ok], l[ok], m2[ok], S[ok]
        # one database feature per measured feature: the candidate nearest in Mahalanobis distance
        best_m2 = np.full(n, np.inf)
        np.minimum.at(best_m2, rows, m2)
        win = np.flatnonzero(m2 == best_m2[rows])
        win = win[np.unique(rows[win], return_index=True)[1]]  # exact ties: the first candidate
        idx_db = np.full(n, -1)
        idx_db[rows[win]] = l[win]
        log_density = np.full(n, -np.inf)
        log_density[rows[win]] = -0.5 * (m2[win] + np.linalg.slogdet(S[win])[1] + 3 * _LOG_2PI)
        explained = idx_db >= 0
        return Explanation(explained, idx_db, np.where(explained, best_m2, np.inf), log_density)

    def score(self, features: Features3D, estimate: PoseEstimate | None) -> ModelScore:
        """``log p(D_k | D_{1:k-1}, M_i)`` on the whole feature set (module docstring)."""
        e = self.explain(features, estimate)
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


# --- shared evidence ---------------------------------------------------------------------------------


def shared_features(dbs: Sequence[FeatureDatabase], config: ScoringConfig | None = None) -> list[np.ndarray]:
    """Which database features every model shares (module docstring, "Shared evidence").

    Parameters
    ----------
    dbs : sequence of FeatureDatabase, length L
    config : ScoringConfig, optional
        ``shared_radius_m``, ``max_descriptor_distance``, ``shared_region_m``, ``shared_region_fraction``.

    Returns
    -------
    list of ndarray, shape (N_i,), bool
        Per database: its feature has, around it, enough features with a counterpart (same position in
        O within ``shared_radius_m``, descriptor within ``max_descriptor_distance``) in every other
        database, and a look-alike (descriptor within ``max_descriptor_distance``) in each of them.
        With one database nothing is shared.
    """
    from scipy.spatial import cKDTree

    cfg = config or ScoringConfig()
    if len(dbs) < 2:
        return [np.zeros(len(db), bool) for db in dbs]
    trees = [cKDTree(db.points_O) if len(db) else None for db in dbs]
    out = []
    for i, db in enumerate(dbs):
        counterpart = np.ones(len(db), bool)  # has one in every other database
        for j, other in enumerate(dbs):
            if j == i:
                continue
            if trees[i] is None or trees[j] is None:
                counterpart[:] = False
                continue
            pairs = trees[i].sparse_distance_matrix(trees[j], cfg.shared_radius_m, output_type="ndarray")
            a, b = pairs["i"], pairs["j"]
            close = (
                np.linalg.norm(db.descriptors[a].astype(float) - other.descriptors[b], axis=1)
                < cfg.max_descriptor_distance
            )
            has = np.zeros(len(db), bool)
            has[a[close]] = True
            counterpart &= has
        if len(db) == 0:
            out.append(counterpart)
            continue
        around = trees[i].query_ball_point(db.points_O, cfg.shared_region_m)  # includes the feature itself
        frac = np.array([counterpart[nb].mean() for nb in around])
        # the feature's own page is in every other database, wherever (a look-alike face): without this
        # a unique face's feature next to an edge would be shared by its neighbours on the shared face
        look_alike = np.ones(len(db), bool)
        for j, other in enumerate(dbs):
            if j != i and len(other) == 0:  # an empty database shares nothing
                look_alike[:] = False
            elif j != i:
                _, dist = Matcher(other, method="brute", k=1).neighbours(db.descriptors)
                look_alike &= dist[:, 0] < cfg.max_descriptor_distance
        out.append((frac >= cfg.shared_region_fraction) & look_alike)
    return out


def pools_shared_evidence(config: ScoringConfig, n_models: int) -> bool:
    """Whether the model probabilities count shared evidence identically for every model.

    ``config.pool_shared`` takes effect only where all models are scored at one common pose with the
    per-feature likelihood (module docstring, "Shared evidence"), and with more than one model. The
    expected-entropy evaluators ask the same question, so that they predict what the update will do.
    """
    return bool(
        config.pool_shared
        and config.share_poses
        and config.common_pose
        and config.likelihood is LikelihoodForm.PER_FEATURE
        and n_models > 1
    )


def shared_masks(scorers: Sequence[ModelScorer]) -> list[np.ndarray]:
    """:func:`shared_features` of the scorers' databases (their first scorer's config), computed once
    per group of scorers and kept on them."""
    key = tuple(id(s.db) for s in scorers)
    if all(s._shared is not None and s._shared[0] == key for s in scorers):
        return [s._shared[1] for s in scorers]
    masks = shared_features([s.db for s in scorers], scorers[0].config)
    for s, m in zip(scorers, masks, strict=True):
        s._shared = (key, m)
    return masks


def pool_shared_evidence(
    scores: Sequence[ModelScore], shared: Sequence[np.ndarray], config: ScoringConfig
) -> list[ModelScore]:
    """Every model's score on one frame, with the shared evidence counted identically for all.

    Parameters
    ----------
    scores : sequence of ModelScore, length L
        Each model's score of the same frame at the same pose (per-feature form).
    shared : sequence of ndarray (N_i,) bool
        :func:`shared_features` of the models' databases.
    config : ScoringConfig

    Returns
    -------
    list of ModelScore
        ``log p(D_k | ., M_i)`` of the module docstring's "Shared evidence": a measured feature that
        any model explains with a shared database feature counts for every model with the best of
        their densities; the others as before.
    """
    E = np.array([sc.explanation.explained for sc in scores])  # (L, n)
    if E.size == 0:
        return list(scores)
    idx = np.array([sc.explanation.idx_db for sc in scores])
    ld = np.array([sc.explanation.log_density for sc in scores])
    by_shared = np.array(
        [
            E[i] & mask[np.where(E[i], idx[i], 0)] if len(mask) else E[i] & False
            for i, mask in enumerate(shared)
        ]
    )
    S = by_shared.any(axis=0)  # shared evidence
    pooled = np.max(np.where(E, ld, -np.inf), axis=0)  # the best density among the models explaining it
    out = []
    n = E.shape[1]
    for i, sc in enumerate(scores):
        own = E[i] & ~S
        ll_expl = float(np.sum(pooled[S]) + np.sum(ld[i, own]))
        n_expl = int(np.count_nonzero(S) + np.count_nonzero(own))
        ll = ll_expl + (n - n_expl) * config.log_clutter_density
        out.append(ModelScore(ll, ll_expl, n_expl, n, sc.explanation))
    return out


# --- calcCurrentEntropy ------------------------------------------------------------------------------


@dataclass(frozen=True)
class Belief:
    """The model probabilities and entropy after a frame (what *calcCurrentEntropy* returns).

    Attributes
    ----------
    P : ndarray, shape (L,)
        ``P(M_i | D_{1:k})``.
    H : float [nats]
        Eq. (5) of ``P``.
    log_likelihoods : ndarray, shape (L,)
        Each model's ``log p(D_k | ., M_i)`` on this frame (before the evidence weight).
    n_explained : ndarray, shape (L,), int
        Measured features each model explains.
    n_features : int
        Size of ``D_k``.
    pose : PoseEstimate or None
        Under the common pose (``ScoringConfig.common_pose``): the candidate pose, in C, that every
        model was scored at on this frame (a filter's pose or one of its look-alike turns: the one that
        explains the frame best over the models). None under the other scorings.
    """

    P: np.ndarray
    H: float
    log_likelihoods: np.ndarray = field(repr=False)
    n_explained: np.ndarray = field(repr=False)
    n_features: int = 0
    pose: PoseEstimate | None = field(default=None, repr=False)

    @property
    def map_model(self) -> int:
        """Index of the most probable model."""
        return int(np.argmax(self.P))


def _candidate_poses(states, symmetries) -> list[PoseEstimate]:
    """The filters' poses and their look-alike turns ``G_CO S_k``, without near-duplicates (1 cm, 2 deg)."""
    from lab.geometry import G_to_pose6  # local: geometry is light, but keep the import next to its use

    out: list[PoseEstimate] = []
    seen: list[np.ndarray] = []
    for x in states:
        if x is None:
            continue
        for S in symmetries if symmetries is not None else (None,):
            G = x.G_CO if S is None else x.G_CO @ np.asarray(S, dtype=float)
            dup = False
            for H in seen:
                if np.linalg.norm(H[:3, 3] - G[:3, 3]) < 0.01:
                    c = (np.trace(H[:3, :3].T @ G[:3, :3]) - 1.0) / 2.0
                    if c > math.cos(math.radians(2.0)):
                        dup = True
                        break
            if dup:
                continue
            seen.append(G)
            out.append(x if S is None else pose_estimate_rv(G_to_pose6(G), x.Sigma_rv, x.t))
    return out


def calc_current_entropy(
    prior,
    features: Features3D,
    scorers: Sequence[ModelScorer],
    states: Sequence[PoseEstimate | None],
    config: ScoringConfig | None = None,
    symmetries: Sequence[np.ndarray] | None = None,
) -> Belief:
    """The paper's *calcCurrentEntropy* (Sec. IV): score ``D_k`` against every model, update the model
    probabilities with Eq. (7) and return them with their entropy, Eq. (5).

    Parameters
    ----------
    prior : array_like, shape (L,)
        ``P(M_i | D_{1:k-1})``.
    features : Features3D
        ``D_k``, the frame's features in the camera frame C.
    scorers : sequence of ModelScorer, length L
        One per database model, in the order of ``prior``.
    states : sequence of PoseEstimate or None, length L
        Each model's pose to score with (:func:`state_for_scoring`); None: the model explains nothing.
    config : ScoringConfig, optional
        The evidence weight and floor (default: the first scorer's config).
    symmetries : sequence of ndarray (4, 4), optional
        The object's look-alike turns (:func:`~lab.identification.hypotheses.z_turns`): with the common
        pose, each filter's pose turned by each of them is a candidate too (the uncertainty in C is
        unchanged by a turn about O's origin), so a filter locked on the wrong quarter-turn still
        offers the right pose with its accuracy.
    """
    prior = _check_probabilities(prior, "prior")
    L = len(prior)
    if len(scorers) != L or len(states) != L:
        raise ConfigError(f"need one scorer and one state per model: {len(scorers)}, {len(states)} for {L}")
    config = config or scorers[0].config
    pool = pools_shared_evidence(config, L)
    poses = [x for x in states if x is not None]
    scored_at = None
    if config.share_poses and poses and config.common_pose:
        poses = _candidate_poses(states, symmetries)
        table = [[s.score(features, x) for x in poses] for s in scorers]  # (L, C): model i at pose c
        if pool:  # shared evidence counted identically for every model, at each pose
            masks = shared_masks(scorers)
            cols = [pool_shared_evidence([row[c] for row in table], masks, config) for c in range(len(poses))]
            table = [[cols[c][i] for c in range(len(poses))] for i in range(L)]
        ll_LC = np.array([[sc.log_likelihood for sc in row] for row in table])
        with np.errstate(divide="ignore"):
            joint = np.log(prior)[:, None] + config.evidence_weight * ll_LC
        top = joint.max(axis=0)
        marginal = top + np.log(np.exp(joint - top).sum(axis=0))  # log sum_i P_i p(D | x_c, M_i)^kappa
        c = int(np.argmax(marginal))
        scores = [row[c] for row in table]
        scored_at = poses[c]
    elif config.share_poses:
        scores = [
            max((s.score(features, x) for x in poses), key=_by_likelihood, default=None) for s in scorers
        ]
        scores = [
            sc if sc is not None else s.score(features, None) for s, sc in zip(scorers, scores, strict=True)
        ]
    else:
        scores = [s.score(features, x) for s, x in zip(scorers, states, strict=True)]
    ll = np.array([s.log_likelihood for s in scores])
    P = update_model_probabilities(prior, ll, config)
    return Belief(P, entropy(P), ll, np.array([s.n_explained for s in scores]), len(features), scored_at)


def _by_likelihood(score: ModelScore) -> float:
    return score.log_likelihood
