r"""The paper's *calcCurrentEntropy* (Sec. IV): a frame scored against every model at one common pose,
the model probabilities updated with it and their entropy.

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
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from lab.errors import ConfigError
from lab.estimation import PoseEstimate
from lab.identification.bayes import check_probabilities, entropy, update_model_probabilities
from lab.identification.scoring import ModelScore, ModelScorer, ScoringConfig, pose_estimate_rv
from lab.identification.shared import pool_shared_evidence, pools_shared_evidence, shared_masks
from lab.vision import Features3D

__all__ = ["Belief", "calc_current_entropy"]


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
    prior = check_probabilities(prior, "prior")
    L = len(prior)
    if len(scorers) != L or len(states) != L:
        raise ConfigError(f"need one scorer and one state per model: {len(scorers)}, {len(states)} for {L}")
    config = config or scorers[0].config
    pool = pools_shared_evidence(config, L)
    poses = [x for x in states if x is not None]
    scored_at = None
    if config.share_poses and poses and config.common_pose:
        poses = _candidate_poses(states, symmetries)
        table = [s.score_many(features, poses) for s in scorers]  # (L, C): model i at pose c
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
        scores = [max(s.score_many(features, poses), key=_by_likelihood, default=None) for s in scorers]
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
