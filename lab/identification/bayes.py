r"""Bayes' rule over the L database models, the probability floor and the model entropy: Eqs. (5) and
(7) of the identification paper (Eq. (4), the information gain, is the planner's).

A frame's log-likelihoods ``log p(D_k | D_{1:k-1}, M_i)`` (:mod:`~lab.identification.scoring`, Eq. (9))
update the model probabilities by Eq. (7), in log space; Eq. (5) measures what is still unknown.

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

import numpy as np

from lab.errors import ConfigError
from lab.identification.scoring import ScoringConfig

__all__ = [
    "apply_floor",
    "check_probabilities",
    "entropy",
    "posterior",
    "uniform",
    "update_model_probabilities",
]


def uniform(n_models: int) -> np.ndarray:
    """The prior ``P_{0,i} = 1 / L`` (the paper's a-priori values when nothing favours a model)."""
    if int(n_models) != n_models or n_models < 1:
        raise ConfigError(f"the number of models must be a positive integer, got {n_models!r}")
    return np.full(int(n_models), 1.0 / n_models)


def check_probabilities(P, name: str = "P") -> np.ndarray:
    """``P`` as a float vector of model probabilities (finite, >= 0, summing to 1), or a
    :class:`~lab.errors.ConfigError` naming it ``name``."""
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
    prior = check_probabilities(prior, "prior")
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
