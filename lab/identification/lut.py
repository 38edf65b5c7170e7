r"""Expected entropy from the probability lookup tables: Eqs. (10) and (13)-(15) of the identification paper.

For a candidate action ``u+`` and an assumed true model ``M_i`` (each of its pose hypotheses):

1. the relative pose the action leads to, ``G_{C+,O_i}``, picks the table row of the nearest training
   pose ("the relative pose which best matches the predicted state of M_i"); when the pose is
   uncertain, the neighbouring rows too, weighted by the uncertainty of the viewing direction
   (:func:`~lab.identification.viewpoints.viewpoint_weights`);
2. ``W_ij``, the number of features of ``M_j`` that will correspond, is sampled from that row of the
   ``(i, j)`` table, for every ``j`` (:class:`~lab.identification.tables.LookupTables`: stratified
   quantile levels shared by all ``j``);
3. with the residual and its covariance taken constant, Eqs. (13)-(14), the likelihood of the predicted
   measurement under ``M_j`` is Eq. (15), times the clutter density for the measured features ``M_j``
   does not explain:

   .. math::

       p(\tilde{\mathbf{D}} \mid \theta, \mathbf{u}^+, M_j) =
           \left[(2\pi)^{3/2} |\Sigma_o|^{1/2}\right]^{-W_{ij}}
           \exp\!\left(-\frac{W_{ij}}{2} \delta_o^T \Sigma_o^{-1} \delta_o\right)
           \cdot c^{\,n - W_{ij}},
       \qquad n = \max_j W_{ij}

   (the paper prints ``(2 pi)^{W/2}``; each of the W features is 3-D, hence ``3W/2`` here). ``n``, the
   number of object features measured, is at least what any model explains; only differences
   between models matter, so ``n`` cancels in the posterior;
4. the posterior over the models (Eq. (7), with the same evidence weight and floor as the real update)
   and its entropy, averaged over the samples and weighted by ``P(M_i)``: Eq. (10).

Where the model probabilities pool shared evidence (the default; see
:mod:`~lab.identification.shared`), a feature every database holds counts
alike for every model and cancels in Eq. (7): ``W_ij`` then counts only the features of ``M_j`` that
are not shared, so a view of shared faces is expected to teach nothing, as it does.

:math:`\Sigma_o` is the innovation covariance of a typical feature (the stereo error at the predicted
depth plus the hypothesis's pose uncertainty) and :math:`\delta_o` a residual with
:math:`\delta_o^T \Sigma_o^{-1} \delta_o = 3`, the mean of a chi-square(3) variable
(:class:`Eq15Constants`).

Everything is table look-ups and array arithmetic: no image, no feature, no matrix inverse at decision
time; that is the point of the tables.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from lab.errors import ConfigError
from lab.identification.actions import CandidateAction
from lab.identification.bayes import entropy, posterior
from lab.identification.hypotheses import ModelHypotheses
from lab.identification.scoring import ScoringConfig
from lab.identification.shared import pools_shared_evidence
from lab.identification.tables import LookupTables
from lab.identification.viewpoints import direction_std, viewpoint_weights
from lab.robot import StereoCamera
from lab.vision.stereo import StereoParams, triangulation_covariance

__all__ = ["Eq15Constants", "LookupTableEvaluator", "eq15_log_likelihood"]

_LOG_2PI = math.log(2.0 * math.pi)


@dataclass(frozen=True)
class Eq15Constants:
    """How ``Sigma_o`` and ``delta_o`` of Eqs. (13)-(14) are set for a candidate action and a hypothesis.

    ``Sigma_o`` is the innovation covariance of a typical feature: the stereo error at the object's
    predicted depth on the optical axis, plus the pose uncertainty the hypothesis will carry there,
    ``C Sigma+ C^T`` for a feature ``feature_radius_m`` from O's centre (averaged over directions:
    ``Sigma_p + (rho^2 / 3) (tr(Sigma_phi) I - Sigma_phi)``). Constant over the features of a
    measurement, as Eq. (13) has it; it changes with the action and the hypothesis, so that an object
    whose pose is uncertain is expected to teach less, as the Monte Carlo finds. ``delta_o`` is a
    residual with ``delta_o^T Sigma_o^-1 delta_o = mahalanobis2`` (3, the mean of a chi-square(3)).

    Attributes
    ----------
    feature_radius_m : float [m]
        RMS distance of a database feature from O's centre (0.18 m for points on a 0.28 m cube's faces).
    mahalanobis2 : float
    """

    feature_radius_m: float = 0.18
    mahalanobis2: float = 3.0

    def __post_init__(self):
        if not (self.feature_radius_m >= 0 and self.mahalanobis2 >= 0):
            raise ConfigError("Eq15Constants needs feature_radius_m >= 0 and mahalanobis2 >= 0")

    def Sigma_o(
        self, camera: StereoCamera, depth_m, Sigma_rv, stereo: StereoParams | None = None
    ) -> np.ndarray:
        """Eq. (13): ``Sigma_o`` (..., 3, 3) [m^2] for objects at ``depth_m`` (...) with pose
        covariances ``Sigma_rv`` (..., 6, 6) over ``[x_r, phi]`` in the camera frame."""
        stereo = stereo or StereoParams()
        depth = np.asarray(depth_m, dtype=float)
        Sigma_rv = np.asarray(Sigma_rv, dtype=float)
        flat = depth.reshape(-1)
        uv = np.tile([camera.cx, camera.cy], (len(flat), 1))
        S_m = triangulation_covariance(uv, camera.fx * camera.baseline / flat, camera, stereo)
        S_m = S_m.reshape(depth.shape + (3, 3))
        S_p, S_phi = Sigma_rv[..., :3, :3], Sigma_rv[..., 3:, 3:]
        tr = np.trace(S_phi, axis1=-2, axis2=-1)[..., None, None]
        return S_m + S_p + self.feature_radius_m**2 / 3.0 * (tr * np.eye(3) - S_phi)

    def log_N_o(self, Sigma_o) -> np.ndarray:
        """``log N(delta_o; 0, Sigma_o)``: Eq. (15) with ``W = 1``, for (..., 3, 3) covariances."""
        return -0.5 * (3 * _LOG_2PI + np.linalg.slogdet(Sigma_o)[1] + self.mahalanobis2)

    def delta_o(self, Sigma_o) -> np.ndarray:
        """Eq. (14): a residual ``delta_o`` (3,) [m] with ``delta_o^T Sigma_o^-1 delta_o = mahalanobis2``
        (equal shares along the principal axes of ``Sigma_o``)."""
        w, U = np.linalg.eigh(np.asarray(Sigma_o, dtype=float))
        return U @ np.sqrt(w * self.mahalanobis2 / 3.0)


def eq15_log_likelihood(W, Sigma_o, delta_o) -> np.ndarray:
    r"""Eq. (15) as a log: ``W`` 3-D features with constant covariance and residual.

    .. math::

        \log p = -\frac{W}{2}\left(3 \log 2\pi + \log|\Sigma_o| + \delta_o^T \Sigma_o^{-1} \delta_o\right)

    Parameters
    ----------
    W : array_like of int
        Numbers of corresponding features.
    Sigma_o : ndarray, shape (3, 3) [m^2]
    delta_o : ndarray, shape (3,) [m]
    """
    Sigma_o = np.asarray(Sigma_o, dtype=float)
    delta_o = np.asarray(delta_o, dtype=float)
    per_feature = 3 * _LOG_2PI + np.linalg.slogdet(Sigma_o)[1] + delta_o @ np.linalg.solve(Sigma_o, delta_o)
    return -0.5 * np.asarray(W, dtype=float) * per_feature


class LookupTableEvaluator:
    """*calcExpectedEntropy* with the lookup tables (module docstring).

    Parameters
    ----------
    tables : LookupTables
        Built for the same models, in the same order, as the hypotheses the evaluator is asked about.
    camera : StereoCamera
        The robot's camera (for ``Sigma_o``).
    scoring : ScoringConfig, optional
        Evidence weight, floor and clutter density: the same as the model probabilities'. A clutter
        density left None is ``camera``'s (:meth:`ScoringConfig.for_camera`).
    n_frames : int
        Frames the robot observes at the goal; their evidence adds up.
    constants : Eq15Constants, optional
    shared : sequence of ndarray (N_j,) bool, optional
        The models' shared features (default: ``tables.shared``, which
        :func:`lab.training.get_tables` fills in).
        Where the scoring pools shared evidence
        (:func:`~lab.identification.shared.pools_shared_evidence`), those features count
        alike for every model and cancel in Eq. (7), so ``W_ij`` counts only the others
        (:meth:`LookupTables.without_features`); with the raw tables the evaluator would expect a
        view of shared faces to tell the models apart. Ignored where the scoring does not pool.
    """

    name = "lut"

    def __init__(
        self,
        tables: LookupTables,
        camera: StereoCamera,
        scoring: ScoringConfig | None = None,
        n_frames: int = 1,
        constants: Eq15Constants | None = None,
        shared: Sequence[np.ndarray] | None = None,
    ):
        if int(n_frames) != n_frames or n_frames < 1:
            raise ConfigError(f"n_frames must be a positive integer, got {n_frames}")
        self.tables = tables
        self.camera = camera
        self.scoring = (scoring or ScoringConfig()).for_camera(camera)  # camera's clutter unless set
        self.n_frames = int(n_frames)
        self.constants = constants or Eq15Constants()
        self.pooled = pools_shared_evidence(self.scoring, tables.n_models)
        shared = tables.shared if shared is None else shared
        if self.pooled and shared is None:
            raise ConfigError(
                "the scoring pools shared evidence (ScoringConfig.pool_shared) but the tables carry no "
                "shared features: pass shared=shared_features(dbs, scoring), "
                "or a scoring with pool_shared=False"
            )
        #: the tables W is sampled from: without the shared features where the scoring pools them
        self.W_tables = tables.without_features(shared) if self.pooled else tables

    def expected_entropy(self, actions: Sequence[CandidateAction], hypotheses: ModelHypotheses) -> np.ndarray:
        """``E[H+]`` of every action, Eq. (10), shape (A,) [nats].

        Each pose hypothesis ``h`` (of model ``i``) looks up the table rows of the training poses
        near its predicted relative pose, weighted by how uncertain the viewing direction is
        (:func:`~lab.identification.viewpoints.viewpoint_weights`; one row for a well-known pose).
        """
        L = self.tables.n_models
        if hypotheses.n_models != L:
            raise ConfigError(f"the hypotheses have {hypotheses.n_models} models, the tables {L}")
        if len(actions) == 0:
            return np.zeros(0)
        G_WC = np.stack([a.G_WC for a in actions])
        G_CO, Sigma = hypotheses.relative_to(G_WC)  # (A, H, ...): each hypothesis's predicted relative pose
        w = viewpoint_weights(G_CO, self.tables.viewpoints, direction_std(G_CO, Sigma), min_weight=0.02)
        a, h, v = np.nonzero(w)  # the (action, hypothesis, table row) triples to evaluate
        # Eqs. (13)-(15): one corresponding feature is worth log N(delta_o; 0, Sigma_o) - log c
        Sigma_o = self.constants.Sigma_o(self.camera, np.linalg.norm(G_CO[..., :3, 3], axis=-1), Sigma)
        lam = self.constants.log_N_o(Sigma_o) - self.scoring.log_clutter_density  # (A, H)
        # W[e, s, j]: features of M_j corresponding when hypothesis h is true, at quantile level s
        W = np.moveaxis(self.W_tables.W_quantiles[hypotheses.model[h], :, v, :], 1, 2).astype(float)
        # log p(D~ | M_j) = W_ij log N_o + (n - W_ij) log c; n log c is the same for every j and cancels
        ll = W * lam[a, h][:, None, None]
        with np.errstate(divide="ignore"):
            log_P = np.log(hypotheses.P)
        P_plus = posterior(log_P, self.n_frames * ll, self.scoring)  # Eq. (7) for every sample
        H_e = entropy(P_plus).mean(axis=-1)  # average over the samples of W
        EH = np.zeros(G_CO.shape[:2])
        np.add.at(EH, (a, h), w[a, h, v] * H_e)  # mix the rows of each hypothesis
        return EH @ hypotheses.probability  # Eq. (10): weight by P(M_i) P(pose | M_i)
