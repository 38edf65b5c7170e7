r"""Expected entropy from the probability lookup tables: Eqs. (10) and (13)-(15) of the identification paper.

For a candidate action ``u+`` and an assumed true model ``M_i``:

1. the relative pose the action leads to, ``G_{C+,O_i}``, picks the table row of the nearest training
   pose (:func:`~lab.identification.viewpoints.nearest_viewpoint`);
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

:math:`\Sigma_o` is the covariance of a feature's innovation at the ring distance (the stereo error at
that depth on the optical axis, plus a pose term) and :math:`\delta_o` a residual with
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
from lab.identification.hypotheses import ModelHypotheses
from lab.identification.probabilities import ScoringConfig, entropy, posterior
from lab.identification.tables import LookupTables
from lab.identification.viewpoints import nearest_viewpoint
from lab.robot import StereoCamera
from lab.vision.stereo import StereoParams, triangulation_covariance

__all__ = ["Eq15Constants", "LookupTableEvaluator", "eq15_log_likelihood"]

_LOG_2PI = math.log(2.0 * math.pi)


@dataclass(frozen=True)
class Eq15Constants:
    """``Sigma_o`` and ``delta_o`` of Eqs. (13)-(14), built from the camera's stereo error model.

    Attributes
    ----------
    depth_m : float [m]
        Depth of the typical feature (the ring's distance).
    pose_std_m : float [m]
        Standard deviation added on every axis for the pose uncertainty ``C Sigma_bar C^T`` of a tracked
        object (measured on the rendered frames: 1-2 cm).
    mahalanobis2 : float
        ``delta_o^T Sigma_o^-1 delta_o`` (3: the chi-square(3) mean).
    """

    depth_m: float = 1.0
    pose_std_m: float = 0.015
    mahalanobis2: float = 3.0

    def __post_init__(self):
        if not (self.depth_m > 0 and self.pose_std_m >= 0 and self.mahalanobis2 >= 0):
            raise ConfigError("Eq15Constants needs depth_m > 0, pose_std_m >= 0 and mahalanobis2 >= 0")

    def Sigma_o(self, camera: StereoCamera, stereo: StereoParams | None = None) -> np.ndarray:
        """Eq. (13): ``Sigma_o``, shape (3, 3) [m^2]."""
        stereo = stereo or StereoParams()
        uv = np.array([[camera.cx, camera.cy]])
        disparity = np.array([camera.fx * camera.baseline / self.depth_m])
        S = triangulation_covariance(uv, disparity, camera, stereo)[0]
        return S + self.pose_std_m**2 * np.eye(3)

    def delta_o(self, camera: StereoCamera, stereo: StereoParams | None = None) -> np.ndarray:
        """Eq. (14): a residual ``delta_o`` (3,) [m] with ``delta_o^T Sigma_o^-1 delta_o = mahalanobis2``
        (equal shares along the principal axes of ``Sigma_o``)."""
        w, U = np.linalg.eigh(self.Sigma_o(camera, stereo))
        return U @ (np.sqrt(w * self.mahalanobis2 / 3.0))


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
        Evidence weight, floor and clutter density: the same as the model probabilities'.
    n_frames : int
        Frames the robot observes at the goal; their evidence adds up.
    constants : Eq15Constants, optional
    """

    name = "lut"

    def __init__(
        self,
        tables: LookupTables,
        camera: StereoCamera,
        scoring: ScoringConfig | None = None,
        n_frames: int = 1,
        constants: Eq15Constants | None = None,
    ):
        if int(n_frames) != n_frames or n_frames < 1:
            raise ConfigError(f"n_frames must be a positive integer, got {n_frames}")
        self.tables = tables
        self.scoring = scoring or ScoringConfig()
        self.n_frames = int(n_frames)
        self.constants = constants or Eq15Constants()
        Sigma_o, delta_o = self.constants.Sigma_o(camera), self.constants.delta_o(camera)
        #: log N(delta_o; 0, Sigma_o): what one corresponding feature contributes, Eq. (15) with W = 1
        self.log_N_o = float(eq15_log_likelihood(1, Sigma_o, delta_o))

    def expected_entropy(self, actions: Sequence[CandidateAction], hypotheses: ModelHypotheses) -> np.ndarray:
        """``E[H+]`` of every action, Eq. (10), shape (A,) [nats]."""
        L = self.tables.n_models
        if hypotheses.n_models != L:
            raise ConfigError(f"the hypotheses have {hypotheses.n_models} models, the tables {L}")
        if len(actions) == 0:
            return np.zeros(0)
        G_WC = np.stack([a.G_WC for a in actions])
        G_CO, _ = hypotheses.relative_to(G_WC)  # (A, L, 4, 4): each model's predicted relative pose
        v = nearest_viewpoint(G_CO, self.tables.viewpoints)  # (A, L): the table row of each (u+, M_i)
        # W[a, i, j, s]: features of M_j corresponding when M_i is true, at quantile level s
        W = self.tables.W_quantiles[np.arange(L)[None, :], :, v, :]  # (A, L_i, L_j, S)
        W = np.moveaxis(W, 2, 3).astype(float)  # (A, L_i, S, L_j): models last
        n = W.max(axis=-1, keepdims=True)  # object features measured
        log_c = self.scoring.log_clutter_density
        ll = W * self.log_N_o + (n - W) * log_c  # Eq. (15) and the clutter term
        with np.errstate(divide="ignore"):
            log_P = np.log(hypotheses.P)
        P_plus = posterior(log_P, self.n_frames * ll, self.scoring)  # Eq. (7) for every sample
        H_plus = entropy(P_plus)  # (A, L_i, S)
        return H_plus.mean(axis=-1) @ hypotheses.P  # Eq. (10): average over samples, weight by P(M_i)
