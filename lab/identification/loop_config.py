"""What the identification loop is set up with and what it records: the planner choice, the loop's
budgets and rates (:class:`AgentConfig`), and the records of its steps and decisions (the run's history,
read by the ``lab identify`` JSON, the figures and the live view)."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum

import numpy as np

from lab.errors import ConfigError

__all__ = ["AgentConfig", "DecisionRecord", "PlannerChoice", "StepRecord"]


class PlannerChoice(Enum):
    """How the next goal is chosen: the paper's planners and two baselines."""

    LUT = "lut"  # expected entropy from the lookup tables, Eq. (13)-(15)
    MC = "mc"  # expected entropy by Monte Carlo, Eq. (10)-(12)
    RANDOM = "random"  # a random ring position
    CIRCLE = "circle"  # the next ring position, always in the same direction


@dataclass(frozen=True)
class AgentConfig:
    """Budgets and rates of the loop.

    Attributes
    ----------
    dt : float [s]
        Control period: one stereo frame per step.
    stop_probability : float
        Identified when one model's probability stays at or above this ...
    dwell_s : float [s]
        ... for this long.
    max_actions : int
        Planning actions (goals) budget.
    max_time_s : float [s]
        Simulated (or real) time budget.
    circle_step_deg : float
        The circling baseline's step along the ring.
    arrive_xy, arrive_theta_deg : float [m], [deg]
        A goal is reached within these.
    settle_s : float [s]
        Frames of tracking before the first decision (the posterior takes in the first view).
    final_observe_s : float [s]
        Observation at the last goal once the action budget is spent.
    symmetry_turns : int
        The box's look-alike turns about its z axis (4: three shared faces and the unique one look
        alike from the side, so a filter can lock on the wrong quarter-turn; 1 turns the symmetry off).
    keyframe_s : float [s]
        A tracked frame is kept as a keyframe for the turn evidence at most this often ...
    keyframes : int
        ... and this many are kept (:class:`~lab.identification.hypotheses.TurnEvidence`).
    reseat_margin : float [nats, after the evidence weight]
        A filter is moved to another turn when the keyframes favour that turn over its own by this
        much (1.0: about eight features that its own pose puts on the wrong face).
    lost_after_s : float [s]
        The track is lost when no model's filter has taken in a frame for this long: the head scans
        and the base halts until a filter takes one in again (the paper's HALT).
    replan_shift_m : float [m]
        After a lost track, the interrupted goal is resumed unless the object's estimate moved more
        than this from where the goal was planned around; then the next-best view is recomputed.
    retry_s : float [s]
        When no goal of the ring is reachable (:class:`RingBlocked`), the robot holds position and keeps
        observing, and plans again after this long.
    keep_direction : float
        The ``lut`` and ``mc`` planners keep the last drive's direction round the ring when the best
        goal that way has at least this fraction of the best gain
        (:func:`~lab.identification.planner.continue_direction`): against an operator who turns the
        unique face away, only travel one way round gains on it. 1.0: always Eq. (6)'s argmax.
    roi : bool
        While the object is tracked (a filter has a pose and the track is not lost), extract SIFT only
        in the region of interest that holds the box at every filter's predicted pose and look-alike
        turn (:func:`~lab.vision.roi.tracked_roi`), and in the right image only in the band that can
        hold its features' partners; the full frame otherwise. False: always the full frame.
    roi_n_sigma : float
        Each box corner is widened by this many standard deviations of its pixel position and depth
        under the predicted pose's covariance ... 2 gives the final probabilities and poses that 3
        gives, and a faster step, SIFT's crops being smaller. Under a Gaussian prediction error a
        corner lies more than 2 standard deviations out on a given side 2.3 % of the time; the region
        then cuts a sliver of the box's border. How it was chosen:
        docs/tuning/identification-roi-n-sigma.md.
    roi_margin_px : float [px]
        ... and the region by this margin (a keypoint centred just off the box can still describe it;
        SIFT's own context around the region is :attr:`~lab.vision.stereo.StereoParams.roi_pad_px`).
        4 px gives the results that 10 px gives, and a faster step. How it was chosen:
        docs/tuning/identification-roi-margin.md.
    roi_max_fraction : float
        A region larger than this fraction of the image gives the full frame.
    """

    dt: float = 0.2
    stop_probability: float = 0.95
    dwell_s: float = 1.0
    max_actions: int = 8
    max_time_s: float = 240.0
    circle_step_deg: float = 60.0
    arrive_xy: float = 0.15
    arrive_theta_deg: float = 15.0
    settle_s: float = 1.0
    final_observe_s: float = 4.0
    symmetry_turns: int = 4
    keyframe_s: float = 1.0
    keyframes: int = 8
    reseat_margin: float = 1.0
    lost_after_s: float = 3.0
    replan_shift_m: float = 0.3
    retry_s: float = 2.0
    keep_direction: float = 0.5
    roi: bool = True
    roi_n_sigma: float = 2.0
    roi_margin_px: float = 4.0
    roi_max_fraction: float = 0.6

    def __post_init__(self):
        if not 0.02 <= self.dt <= 1.0:
            raise ConfigError(f"dt must be within [0.02, 1] s, got {self.dt}")
        if not 0.5 < self.stop_probability < 1.0:
            raise ConfigError(f"stop_probability must be within (0.5, 1), got {self.stop_probability}")
        if self.max_actions < 0:
            raise ConfigError(f"max_actions must be >= 0, got {self.max_actions}")
        if not (self.roi_n_sigma >= 0 and self.roi_margin_px >= 0 and 0 < self.roi_max_fraction <= 1):
            raise ConfigError(
                f"need roi_n_sigma >= 0, roi_margin_px >= 0 and roi_max_fraction within (0, 1], got "
                f"{self.roi_n_sigma}, {self.roi_margin_px}, {self.roi_max_fraction}"
            )
        if not 0 < self.keep_direction <= 1:
            raise ConfigError(f"keep_direction must be within (0, 1], got {self.keep_direction}")
        if self.symmetry_turns < 1 or self.keyframes < 1 or not self.reseat_margin > 0:
            raise ConfigError(
                f"symmetry_turns and keyframes must be >= 1 and reseat_margin > 0, got "
                f"{self.symmetry_turns}, {self.keyframes}, {self.reseat_margin}"
            )


@dataclass(frozen=True)
class StepRecord:
    """What happened in one control step (the run's history)."""

    t: float
    posterior: np.ndarray = field(repr=False)
    head_mode: str
    base_mode: str  # "driving", "halted", "idle"
    odom: tuple[float, float, float]
    n_features: int
    action: int | None  # index of the decision taken in this step, if any
    estimates_W: np.ndarray = field(repr=False)  # (L, 4, 4) each model's object pose in W (NaN: none)


@dataclass(frozen=True)
class DecisionRecord:
    """One planning decision: the candidates, their gains and the chosen goal."""

    t: float
    planner: str
    candidates: np.ndarray = field(repr=False)  # (K, 3) x, y, heading of each candidate goal
    gains: np.ndarray = field(repr=False)  # (K,) information gain [nats] (NaN for the baselines)
    chosen: int
    centre_W: np.ndarray = field(repr=False)  # (3,) the ring's centre
    elapsed_s: float
    direction: int = 0  # travel round the ring: +1 counter-clockwise, -1 clockwise, 0 staying put
    kept_direction: bool = False  # chosen over Eq. (6)'s argmax to keep the direction of travel

    def to_json(self, t0: float = 0.0) -> dict:
        """The ``decisions`` entry of the ``lab identify`` JSON (times from ``t0``)."""
        g = self.gains[self.chosen]
        return {
            "t": self.t - t0,
            "chosen": self.chosen,
            "gain": float(g) if np.isfinite(g) else None,
            "elapsed_s": self.elapsed_s,
            "direction": self.direction,
            "kept_direction": self.kept_direction,
        }
