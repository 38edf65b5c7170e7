"""One perception step of the identification loop: a frame's features into the EKF bank and the model
probabilities (the left half of the paper's Fig. 3, up to *calcCurrentEntropy*).

The caller predicts the bank first (robot, pan-tilt and object motion since the last frame) and passes
the predictions in; this function matches the frame against every model, updates each filter, and
scores the frame against every model at the predicted poses (Eqs. (7)-(9)).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

from lab.errors import ConfigError
from lab.estimation import EKFBank, PoseEstimate, UpdateResult
from lab.identification.belief import Belief, calc_current_entropy
from lab.identification.scoring import ModelScorer, ScoringConfig, state_for_scoring
from lab.vision import Features3D, Matcher

__all__ = ["FrameObservation", "observe_frame"]


@dataclass(frozen=True)
class FrameObservation:
    """What one frame did.

    Attributes
    ----------
    belief : Belief
        Model probabilities and entropy after the frame.
    updates : tuple of UpdateResult
        Each model's EKF update.
    matches : tuple of (d_C, b_O, Sigma_d)
        Each model's matched pairs that its update was given (empty: not recorded).
    """

    belief: Belief
    updates: tuple[UpdateResult, ...] = field(repr=False)
    matches: tuple = field(default=(), repr=False)


def _shared(matcher: Matcher, scorer: ModelScorer, features: Features3D):
    """The scorer's exact nearest neighbours for the matcher, when both search the same database for
    the same number of neighbours (None: the matcher searches itself)."""
    if matcher.db is not scorer.db or matcher.k != scorer.k_neighbours or len(features) == 0:
        return None
    return scorer.neighbours(features)


def observe_frame(
    P,
    features: Features3D,
    bank: EKFBank,
    predicted: Sequence[PoseEstimate | None],
    matchers: Sequence[Matcher],
    scorers: Sequence[ModelScorer],
    config: ScoringConfig | None = None,
    symmetries: Sequence | None = None,
) -> FrameObservation:
    """Update every model's filter with the frame and the model probabilities with Eq. (7).

    Parameters
    ----------
    P : array_like, shape (L,)
        Model probabilities before the frame.
    features : Features3D
        The frame's ``D_k``.
    bank : EKFBank
        One filter per model, already predicted to the frame's time.
    predicted : sequence of PoseEstimate or None
        ``bank.predict(...)``'s output for this frame.
    matchers, scorers : sequences, one per model
        ``Matcher(db_i)`` (the EKF's correspondences) and ``ModelScorer(db_i)`` (the probabilities').
        When a matcher and its scorer share the database and ``k``, the frame is searched once per
        model: the matcher's ratio test runs on the scorer's exact nearest neighbours, which gives the
        matches of ``Matcher(db_i, method="brute")`` (``tests/test_ident_sim.py``).
    config : ScoringConfig, optional
    symmetries : sequence of ndarray (4, 4), optional
        The object's look-alike turns, passed to :func:`calc_current_entropy`.
    """
    L = len(bank)
    if not (len(predicted) == len(matchers) == len(scorers) == L):
        raise ConfigError(
            f"need one prediction, matcher and scorer per model: {len(predicted)}, {len(matchers)}, "
            f"{len(scorers)} for {L} filters"
        )
    matches = tuple(
        matchers[i].match(features, _shared(matchers[i], scorers[i], features)).pairs(features, scorers[i].db)
        for i in range(L)
    )
    updates = bank.update_all(list(matches))  # every model's matches, the filters' linear algebra batched
    states = [state_for_scoring(p, u) for p, u in zip(predicted, updates, strict=True)]
    belief = calc_current_entropy(P, features, scorers, states, config, symmetries)
    return FrameObservation(belief, updates, matches)
