"""Notebook 02's checks: entropy (Eq. (5)), Bayes' rule over the models (Eq. (7)) and the information gain
(Eq. (4)) (assignment ``planning``).

See :mod:`lab.exercises` for what a check does and how it avoids carrying the answer.
"""

from __future__ import annotations

import math

import numpy as np

from lab.exercises.feedback import Feedback, Mistake, answer_array, call_answer, checked, close, verdict

__all__ = ["check_entropy", "check_model_probabilities", "check_information_gain"]

_PS = (np.array([0.25, 0.25, 0.25, 0.25]), np.array([0.7, 0.1, 0.15, 0.05]), np.array([0.5, 0.0, 0.5, 0.0]))


@checked
def check_entropy(entropy) -> Feedback:
    """Check ``entropy(P) -> H`` [nats], Eq. (5) of the identification paper with ``0 log 0 = 0``, against
    ``scipy.stats.entropy``."""

    name = "entropy"
    got = answer_array(name, [call_answer(name, entropy, P.copy()) for P in _PS], (len(_PS),))
    from scipy.stats import entropy as sp_entropy  # after the answer ran: a stub costs nothing

    want = np.array([sp_entropy(P) for P in _PS])
    mistakes = [
        Mistake(
            "bits",
            "that is in bits (log2): the paper's entropy is in nats, use the natural log",
            want / math.log(2),
        ),
        Mistake("sign", "a wrong sign: H = -sum P log P is never negative", -want),
        Mistake(
            "zero_log_zero",
            "NaN where a probability is 0: the term 0 log 0 counts as 0 (skip the zeros)",
            test=lambda g: close(g[:2], want[:2], 1e-9) and not np.isfinite(g[2]),
        ),
    ]
    return verdict(name, got, want, 1e-9, mistakes, "not -sum P log P")


_LL_CASES = (
    (np.array([0.1, 0.2, 0.3, 0.4]), np.array([-2.0, -1.0, -3.5, -0.5])),
    (np.array([0.25, 0.25, 0.25, 0.25]), np.array([-3000.0, -3001.0, -3004.0, -3000.5])),
)


@checked
def check_model_probabilities(model_probabilities) -> Feedback:
    """Check ``model_probabilities(P_prior, log_likelihood) -> P``, Bayes' rule over the models (Eq. (7)),
    against ``scipy.special.softmax(log P_prior + log_likelihood)``; the second case's likelihoods are
    ``exp(-3000)``, 0.0 in double precision."""

    name = "model_probabilities"
    got = np.concatenate(
        [
            answer_array(name, call_answer(name, model_probabilities, P.copy(), ll.copy()), (4,))
            for P, ll in _LL_CASES
        ]
    )
    from scipy.special import softmax  # after the answer ran: a stub costs nothing

    want = np.concatenate([softmax(np.log(P) + ll) for P, ll in _LL_CASES])
    (P1, ll1), (P2, ll2) = _LL_CASES
    mistakes = [
        Mistake(
            "normalisation",
            "missing normalisation: divide by the sum over the models "
            "(Eq. (7)'s denominator), so P sums to 1",
            test=lambda g: close(g[:4], P1 * np.exp(ll1), 1e-9),
        ),
        Mistake(
            "prior",
            "the prior is missing: multiply each likelihood by P(M_i) first",
            np.concatenate([softmax(ll1), softmax(ll2)]),
        ),
        Mistake(
            "log_space",
            "right for moderate likelihoods, but exp(-3000) is 0.0: stay in "
            "log space and subtract the largest before exp",
            test=lambda g: close(g[:4], want[:4], 1e-9) and not close(g[4:], want[4:], 1e-9),
        ),
        Mistake(
            "not_exponentiated",
            "these are LOG-likelihoods: exponentiate (or add them to log P) rather than multiply by them",
            test=lambda g: close(g[:4], P1 * ll1 / np.sum(P1 * ll1), 1e-9),
        ),
    ]
    return verdict(
        name, got, want, 1e-9, mistakes, "not Bayes' rule: P_i proportional to P_prior_i times likelihood_i"
    )


_IG_CASES = (
    (np.array([0.25, 0.25, 0.25, 0.25]), np.array([[0.8, 0.2], [0.3, 0.7], [0.3, 0.7], [0.3, 0.7]])),
    (
        np.array([0.6, 0.1, 0.2, 0.1]),
        np.array([[0.7, 0.2, 0.1], [0.1, 0.8, 0.1], [0.2, 0.2, 0.6], [1 / 3, 1 / 3, 1 / 3]]),
    ),
)


def _mutual_information(P, lik):
    joint = P[:, None] * lik  # p(M_i, y)
    py = joint.sum(axis=0)
    nz = joint > 0
    return float(np.sum(joint[nz] * np.log(joint[nz] / (P[:, None] * py[None, :])[nz])))


def _expected_entropy(P, lik, weights=None):
    from scipy.stats import entropy as sp_entropy

    joint = P[:, None] * lik
    py = joint.sum(axis=0)
    H_post = np.array([sp_entropy(joint[:, k] / py[k]) for k in range(lik.shape[1])])
    w = py if weights is None else weights
    return float(np.sum(w * H_post))


@checked
def check_information_gain(information_gain) -> Feedback:
    r"""Check ``information_gain(P, likelihood) -> I`` [nats], Eq. (4) for a discrete measurement:
    ``P`` (L,) the model probabilities, ``likelihood`` (L, Y) with ``likelihood[i, y] = p(y | M_i)``, and
    :math:`I = H(M) - E_y[H(M \mid y)]`. The reference is the mutual information computed from the joint
    distribution :math:`p(M_i, y)`, a different route to the same number."""

    name = "information_gain"
    got = answer_array(
        name,
        [call_answer(name, information_gain, P.copy(), L.copy()) for P, L in _IG_CASES],
        (len(_IG_CASES),),
    )
    from scipy.stats import entropy as sp_entropy  # after the answer ran: a stub costs nothing

    want = np.array([_mutual_information(P, L) for P, L in _IG_CASES])
    H = np.array([sp_entropy(P) for P, _ in _IG_CASES])
    EH = np.array([_expected_entropy(P, L) for P, L in _IG_CASES])
    unweighted = np.array(
        [
            H[k] - _expected_entropy(P, L, np.full(L.shape[1], 1 / L.shape[1]))
            for k, (P, L) in enumerate(_IG_CASES)
        ]
    )
    mistakes = [
        Mistake(
            "expected_entropy", "that is the expected entropy E[H+]: the gain is the entropy now MINUS it", EH
        ),
        Mistake(
            "sign", "a wrong sign: the gain is H now minus the expected entropy after, never negative", -want
        ),
        Mistake(
            "weights",
            "weight each outcome's posterior entropy by its probability "
            "p(y) = sum_i P_i p(y | M_i), not equally",
            unweighted,
        ),
        Mistake("bits", "that is in bits (log2): use the natural log (nats)", want / math.log(2)),
    ]
    return verdict(
        name, got, want, 1e-9, mistakes, "not H(M) - E_y[H(M | y)]: compute p(y), each posterior, its entropy"
    )
