r"""Shared evidence: what every model's database holds counts identically for every model.

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
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from lab.identification.scoring import LikelihoodForm, ModelScore, ModelScorer, ScoringConfig
from lab.vision import FeatureDatabase, Matcher

__all__ = ["pool_shared_evidence", "pools_shared_evidence", "shared_features", "shared_masks"]


def shared_features(dbs: Sequence[FeatureDatabase], config: ScoringConfig | None = None) -> list[np.ndarray]:
    """Which database features every model shares (module docstring).

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
    per-feature likelihood (module docstring), and with more than one model. The
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
        With its clutter density resolved (:meth:`ScoringConfig.for_camera`).

    Returns
    -------
    list of ModelScore
        ``log p(D_k | ., M_i)`` of the module docstring: a measured feature that
        any model explains with a shared database feature counts for every model with the best of
        their densities; the others as before.
    """
    log_c = config.require_clutter_density()
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
        ll = ll_expl + (n - n_expl) * log_c
        out.append(ModelScore(ll, ll_expl, n_expl, n, sc.explanation))
    return out
