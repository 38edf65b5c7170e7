"""A search trial with an object that moves (``lab search --moving random|evasive``).

The object stands on the floor or on a table's top (a seeded placement on the surface ``--surface``
names, the floor by default, or ``--place``) and rides a carrier of the world
(:mod:`lab.sim.moving_object`) over that surface at ``--object-speed``, pausing ``--pause`` after each
leg. The agent, unless it is the static-map baseline (``predict=False``), runs the probability map's
prediction step (:mod:`lab.search.motion`) with the object's speed as its speed bound, over the
surfaces its navigator's costmap shows (the floor, and the raised cells a table's top is among: the
agent does not know which one the object is on), and its local search's pose EKF lets the object move
by the same bound (:class:`~lab.estimation.noise.ProcessNoise` ``sigma_v``), and its global colour
detections become tracks that the head follows while the robot approaches their predicted position
(:mod:`lab.search.follow`). A find is scored against the truth at the moment it was confirmed (the
local search's event), which the result records as ``moving.truth_time_s``, beside where the object
drove (:func:`moving_record`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from lab.errors import ConfigError
from lab.search.colour_track import ColourTrackConfig
from lab.search.config import SearchAgentConfig
from lab.search.motion import MotionModel, surfaces_from_costmap

__all__ = [
    "MOVING_POSITION_STD_M",
    "MOVING_REFINE_UPSAMPLE",
    "MOVING_SURFACES",
    "MovingOptions",
    "agent_config",
    "check_moving_surface",
    "found_time",
    "moving_record",
    "passable_of",
    "start_mover",
]

MOVING_KINDS = ("random", "evasive")
#: The surfaces a carrier drives on (a shelf's board is too narrow for one).
MOVING_SURFACES = ("floor", "table")

#: "Found" for a moving object's pose: the largest position standard deviation may reach this [m]
#: (the stationary object's bound is 1 cm). Under the pose EKF's constant-position model with the speed
#: bound as its velocity noise, each refinement frame adds ``(v dt)^2`` per axis (2.5 cm at 0.1 m/s and
#: a quarter second between frames), so the filter cannot average frames down: its deviation stays
#: near one frame's, 1-1.5 cm at local-search range, and the 1 cm bound refused every track of a
#: moving object. 2 cm is still well inside the 5 cm a find is scored against; how it was chosen:
#: docs/tuning/search-moving-object.md.
MOVING_POSITION_STD_M = 0.02

#: The local search's refinement regions are enlarged this many times for a moving object
#: (``LocalSearchConfig.refine_upsample``): the object drives on while the head turns to it, out of the
#: 0.6-0.9 m local-search range the robot stood at, and at 1.4-2 m the refinement frames of the
#: captured image matched too few features for an update (degenerate or gated out) where the enlarged
#: region matched about three times as many; how it was measured: docs/tuning/search-moving-object.md.
MOVING_REFINE_UPSAMPLE = 2


@dataclass(frozen=True)
class MovingOptions:
    """How the searched-for object moves, and whether the agent predicts it.

    Attributes
    ----------
    kind : {"random", "evasive"}
    speed_mps : float [m/s]
        The object's speed on a leg; the agent's speed bound.
    pause_s : float [s]
        How long it stands after each leg.
    predict : bool
        The agent's map has the prediction step (False: the static-map baseline on the same motion).
    surface : {"floor", "table"}
        Where a seeded placement puts it (``--surface``); a given placement (``--place``) is where it
        stands, and must be on one of these.
    """

    kind: str = "random"
    speed_mps: float = 0.1
    pause_s: float = 5.0
    predict: bool = True
    surface: str = "floor"

    def __post_init__(self):
        if self.kind not in MOVING_KINDS:
            raise ConfigError(f"--moving must be one of {', '.join(MOVING_KINDS)}, got {self.kind!r}")
        if not (
            isinstance(self.speed_mps, (int, float)) and math.isfinite(self.speed_mps) and self.speed_mps > 0
        ):
            raise ConfigError(f"--object-speed must be a finite number > 0 m/s, got {self.speed_mps!r}")
        if not (_number(self.pause_s) and self.pause_s >= 0):
            raise ConfigError(f"--pause must be a finite number >= 0 s, got {self.pause_s!r}")
        if self.surface not in MOVING_SURFACES:
            raise ConfigError(
                f"a moving object rides on {' or '.join(MOVING_SURFACES)}: --surface must be one of "
                f"{', '.join(MOVING_SURFACES)}, got {self.surface!r}"
            )

    def as_dict(self) -> dict:
        """The options in the result JSON's ``moving`` (:func:`moving_record` adds what happened)."""
        return {
            "kind": self.kind,
            "speed_mps": self.speed_mps,
            "pause_s": self.pause_s,
            "predict": self.predict,
        }


def check_moving_surface(surface: str) -> None:
    """Refuse a placement's ``surface`` (its kind) that a carrier cannot drive on."""
    if surface not in MOVING_SURFACES:
        raise ConfigError(
            f"--moving puts the object on the floor or a table's top; --place put it on the {surface}"
        )


def moving_record(moving: MovingOptions, mover, truth_time_s: float) -> dict:
    """The result JSON's ``moving``: the options, where it drove (``support``: ``floor`` or the name of
    the table whose top it drove on; the result's ``surface`` says ``table``), how far and in how many
    legs, how often it evaded, and ``truth_time_s``, the moment the find is scored at."""
    return {
        **moving.as_dict(),
        "support": mover.surface,
        "path_length_m": round(mover.path_length_m(), 4),
        "legs": int(mover.legs),
        "evasions": int(mover.evasions),
        "truth_time_s": truth_time_s,
    }


def _number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def agent_config(cfg: SearchAgentConfig, moving: MovingOptions) -> SearchAgentConfig:
    """The agent's config for a moving object: the map's motion model, the pose EKF's object motion
    at the speed bound, the found pose's position deviation bound that this motion allows
    (:data:`MOVING_POSITION_STD_M`), the refinement on enlarged regions (:data:`MOVING_REFINE_UPSAMPLE`)
    and the colour tracks the head follows (:mod:`lab.search.follow`); the baseline keeps the static
    config."""
    if not moving.predict:
        return cfg
    ls = cfg.local_search
    process = replace(ls.process, sigma_v=float(moving.speed_mps))  # constant position, velocity noise
    std = max(ls.max_position_std_m, MOVING_POSITION_STD_M)
    up = max(ls.refine_upsample, MOVING_REFINE_UPSAMPLE)
    local = replace(ls, process=process, max_position_std_m=std, refine_upsample=up)
    motion = MotionModel(speed_mps=float(moving.speed_mps))
    return replace(cfg, motion=motion, local_search=local, colour_track=ColourTrackConfig())


def start_mover(world, object: str, moving: MovingOptions, seed: int):
    """Put the object of a simulated world on its carrier (seeded apart from the trial's other draws)."""
    from lab.sim.moving_object import MovingKind, MovingObjectConfig, make_moving_object

    cfg = MovingObjectConfig(MovingKind(moving.kind), float(moving.speed_mps), float(moving.pause_s))
    return make_moving_object(world, object, cfg, np.random.default_rng([int(seed), 50]))


def passable_of(navigate, spec):
    """``passable()`` for the agent from the navigator's costmap (the robot's belief): the map's cells
    labelled by surface (:func:`lab.search.motion.surfaces_from_costmap`: the floor, and the raised
    cells that hold a table's top), or None (every cell one floor) when the navigate callable has no
    navigator."""
    navigator = getattr(navigate, "navigator", None)
    if navigator is None:
        return None
    costmap = navigator.costmap
    return lambda: surfaces_from_costmap(costmap.state, costmap.spec, spec)


def found_time(out) -> float | None:
    """The robot time at which the run's find was confirmed: its last local-search event; None when
    not found."""
    if not out.found:
        return None
    for e in reversed(out.events):
        if e.kind == "local":
            return e.t
    return out.t_end
