r"""The next-best view: information gain, Eq. (4), and its maximisation, Eq. (6).

The paper's Sec. IV divides the computation into three functions; here they are
:func:`~lab.identification.belief.calc_current_entropy` (model probabilities and entropy after a
frame), :func:`~lab.identification.actions.calc_possible_control_actions` (the ring of reachable goals)
and :func:`calc_expected_entropy` (with an evaluator: lookup tables or Monte Carlo).
:func:`plan_next_best_view` chains the last two:

.. math::

    I_{\mathbf{u}} = H(M \mid \mathbf{D}_{1:k}, \mathbf{u}_{1:k-1})
        - E_{\mathbf{D}_{k+1}}[H(M \mid \mathbf{D}_{1:k+1}, \mathbf{u}_{1:k})]     \qquad \text{Eq. (4)}

    \mathbf{u}^* = \operatorname{argmax}_{\mathbf{u}} I_{\mathbf{u}}               \qquad \text{Eq. (6)}
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from enum import Enum
from typing import Protocol

import numpy as np

from lab.errors import ConfigError
from lab.geometry import Pose2D
from lab.identification.actions import ActionConfig, CandidateAction, calc_possible_control_actions
from lab.identification.bayes import entropy
from lab.identification.hypotheses import ModelHypotheses
from lab.robot import StereoCamera

__all__ = [
    "ExpectedEntropyEvaluator",
    "Plan",
    "PlannerKind",
    "ahead_on_ring",
    "calc_expected_entropy",
    "continue_direction",
    "information_gain",
    "next_best_action",
    "plan_next_best_view",
    "ring_smoothed",
]


class PlannerKind(Enum):
    """How the expected entropy is computed."""

    LUT = "lut"  # lookup tables, Eqs. (13)-(15): LookupTableEvaluator
    MONTE_CARLO = "mc"  # sampled measurements, Eqs. (10)-(12): MonteCarloEvaluator


class ExpectedEntropyEvaluator(Protocol):
    """What :func:`calc_expected_entropy` needs: ``E[H+]`` of each candidate action."""

    name: str

    def expected_entropy(
        self, actions: Sequence[CandidateAction], hypotheses: ModelHypotheses
    ) -> np.ndarray: ...


def calc_expected_entropy(
    evaluator: ExpectedEntropyEvaluator, actions: Sequence[CandidateAction], hypotheses: ModelHypotheses
) -> np.ndarray:
    """The paper's *calcExpectedEntropy*: ``E[H+]`` of every candidate action, Eq. (10), shape (A,)."""
    return np.asarray(evaluator.expected_entropy(actions, hypotheses), dtype=float)


def information_gain(H, expected_entropy) -> np.ndarray:
    """Eq. (4): ``I_u = H(M | D_{1:k}) - E[H(M | D_{1:k+1})]`` for each action [nats], at least 0.

    With the exact posterior an observation cannot raise the entropy on average (the posterior is a
    martingale and the entropy concave), so ``I_u >= 0``. The expected entropies here come from
    approximate likelihoods (Eqs. (12)-(15), the evidence weight, the floor), under which an action that
    teaches (almost) nothing can come out a hair above the current entropy (measured: below 0.01 nats);
    that is approximation noise, not a loss of information, and it is reported as a gain of 0. The raw
    expected entropies stay available (:attr:`Plan.expected_entropy`).
    """
    return np.maximum(0.0, float(H) - np.asarray(expected_entropy, dtype=float))


def next_best_action(gains, tie_tol: float = 0.05, tie_break=None) -> int:
    """Eq. (6): the index of the action with the largest information gain.

    Gains within ``tie_tol`` (relative) of the largest count as equally good: they differ by less than
    the approximations behind them. Among those, the largest ``tie_break`` value wins (the planner
    passes each goal's gain averaged with its neighbours on the ring, so that the middle of a plateau of
    good goals is chosen rather than its edge, where a small pose error loses the view); then the first.

    Parameters
    ----------
    gains : array_like, shape (A,) [nats]
    tie_tol : float
        Relative tolerance (0: exact ties only).
    tie_break : array_like, shape (A,), optional
    """
    g = np.asarray(gains, dtype=float)
    if g.ndim != 1 or len(g) == 0:
        raise ConfigError("next_best_action needs a non-empty vector of gains")
    if not np.all(np.isfinite(g)):
        raise ConfigError(f"information gains must be finite, got {g}")
    top = g.max()
    near = np.flatnonzero(g >= top - tie_tol * abs(top) - 1e-12)
    if tie_break is None or len(near) == 1:
        return int(near[0])
    t = np.asarray(tie_break, dtype=float)[near]
    return int(near[np.flatnonzero(t >= t.max() - 1e-12)[0]])


def ring_smoothed(gains, actions: Sequence[CandidateAction]) -> np.ndarray:
    """Each goal's gain averaged with its ring neighbours (weights 1/4, 1/2, 1/4); a neighbour that is
    not a candidate (blocked) counts as no gain."""
    g = np.asarray(gains, dtype=float)
    by_key = {(round(a.radius_m, 6), a.index): k for k, a in enumerate(actions)}
    n = int(round(360.0 / _ring_step_deg(actions)))  # goals on a full ring
    out = np.empty_like(g)
    for k, a in enumerate(actions):
        side = [by_key.get((round(a.radius_m, 6), (a.index + d) % n)) for d in (-1, 1)]
        out[k] = 0.5 * g[k] + sum(0.25 * g[s] for s in side if s is not None)
    return out


def ahead_on_ring(actions: Sequence[CandidateAction], azimuth: float, direction: int) -> np.ndarray:
    """Which goals lie ahead of ``azimuth`` [rad] when travelling the ring in ``direction`` (+1
    counter-clockwise, -1 clockwise): at least one ring step along it and at most half a turn and half a
    step (so the goal straight across counts for both directions)."""
    if direction not in (1, -1):
        raise ConfigError(f"direction must be +1 (counter-clockwise) or -1 (clockwise), got {direction!r}")
    step = np.radians(_ring_step_deg(actions))
    az = np.array([a.azimuth for a in actions])
    d = np.mod(direction * (az - azimuth), 2 * np.pi)
    return (d >= 0.5 * step) & (d <= np.pi + 0.5 * step)


def continue_direction(
    gains, actions: Sequence[CandidateAction], azimuth: float, direction: int, ratio: float, tie_break=None
) -> int | None:
    """The best goal ahead in the direction of travel when its gain is at least ``ratio`` times the best
    gain anywhere; None when no goal ahead is that good (then Eq. (6)'s argmax stands).

    Against an operator who keeps turning the unique face away (the paper's experiment), only travel
    that keeps one direction round the ring gains on the face: it closes the angle at the robot's
    angular speed minus the box's turn rate, and a reversal gives the gained angle back. The gain of
    Eq. (4) is computed for the object as it is now and cannot see that; ``ratio`` says how much of it
    to give up for keeping on (1: none).

    Parameters
    ----------
    gains : array_like, shape (A,) [nats]
    actions : sequence of CandidateAction
    azimuth : float [rad]
        The robot's direction from the object's centre.
    direction : int
        +1 (counter-clockwise) or -1 (clockwise): the last drive's.
    ratio : float
        In (0, 1].
    tie_break : array_like, shape (A,), optional
        As in :func:`next_best_action`, among the goals ahead.
    """
    g = np.asarray(gains, dtype=float)
    if not 0 < ratio <= 1:
        raise ConfigError(f"ratio must be within (0, 1], got {ratio}")
    if g.shape != (len(actions),):
        raise ConfigError(f"gains has shape {g.shape}; expected ({len(actions)},), one per action")
    ahead = np.flatnonzero(ahead_on_ring(actions, azimuth, direction))
    if len(ahead) == 0:
        return None
    tb = None if tie_break is None else np.asarray(tie_break, dtype=float)[ahead]
    k = int(ahead[next_best_action(g[ahead], tie_break=tb)])
    top = float(g.max())
    return k if top <= 0 or g[k] >= ratio * top else None


def _ring_step_deg(actions: Sequence[CandidateAction]) -> float:
    for a in actions:
        if a.index > 0:
            return float(np.degrees(a.azimuth) / a.index)
    return 360.0


@dataclass(frozen=True)
class Plan:
    """The outcome of one next-best-view decision.

    Attributes
    ----------
    actions : tuple of CandidateAction
    H : float [nats]
        Current model entropy, Eq. (5).
    expected_entropy : ndarray, shape (A,) [nats]
        ``E[H+]`` of each action, Eq. (10).
    gain : ndarray, shape (A,) [nats]
        Eq. (4).
    best : int
        Eq. (6): index of the chosen action.
    planner : str
        ``"lut"`` or ``"mc"``.
    elapsed_s : float [s]
        Wall time of the decision (candidates and expected entropies).
    """

    actions: tuple[CandidateAction, ...] = field(repr=False)
    H: float
    expected_entropy: np.ndarray = field(repr=False)
    gain: np.ndarray = field(repr=False)
    best: int
    planner: str
    elapsed_s: float

    @property
    def action(self) -> CandidateAction:
        """The next-best action ``u*``."""
        return self.actions[self.best]


def plan_next_best_view(
    hypotheses: ModelHypotheses,
    camera: StereoCamera,
    evaluator: ExpectedEntropyEvaluator,
    action_config: ActionConfig | None = None,
    is_reachable: Callable[[Pose2D], bool] | None = None,
) -> Plan:
    """Candidate goals around the object, their expected entropies and the best one (Eqs. (4)-(6), (10)).

    Raises
    ------
    RingBlocked
        No candidate goal is reachable (from :func:`calc_possible_control_actions`).
    """
    t0 = time.perf_counter()
    actions = calc_possible_control_actions(hypotheses.object_centre_W(), camera, action_config, is_reachable)
    EH = calc_expected_entropy(evaluator, actions, hypotheses)
    H = entropy(hypotheses.P)
    gain = information_gain(H, EH)
    best = next_best_action(gain, tie_break=ring_smoothed(gain, actions))
    return Plan(actions, H, EH, gain, best, evaluator.name, time.perf_counter() - t0)
