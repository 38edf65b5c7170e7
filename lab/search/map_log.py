"""A record of every change a search makes to its probability map, to replay one run's observations
under another motion model: the map with and without the prediction step on the same run.

The agent changes ``M_p`` in two ways only: :meth:`~lab.search.probability_map.ProbabilityMap.observe`
(Eqs. (1)-(3), a detection or a miss) and, for a moving object,
:meth:`~lab.search.probability_map.ProbabilityMap.predict` (Eq. (1'), over the time since the last
prediction and the surfaces the robot believed then). :class:`MapLog` records both, with the robot's
time, and :meth:`MapLog.replay` applies the same observations to the same prior again, predicting
with another speed bound, or not at all (the static map of the paper on the same observations). The
decisions of the run (where the robot went) stay those of the run: a replay shows what another map
would have believed, not where another search would have looked.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lab.errors import ConfigError
from lab.search.motion import MotionModel
from lab.search.probability_map import ProbabilityMap

__all__ = ["MapLog", "MapStep"]


@dataclass(frozen=True, eq=False)
class MapStep:
    """One change to the map: an observation (``detection``) or a prediction (``dt_s`` over
    ``surfaces``), at robot time ``t`` [s]."""

    t: float
    detection: object = None
    dt_s: float = 0.0
    surfaces: np.ndarray | None = None


class MapLog:
    """Records the map changes of one agent (:meth:`attach` before its run) for :meth:`replay`."""

    def __init__(self):
        self.steps: list[MapStep] = []
        self.prior: np.ndarray | None = None
        self.spec = None
        self.model: MotionModel | None = None

    def attach(self, agent) -> None:
        """Record ``agent``'s map from now on: its map as the prior, and every ``observe`` and
        ``predict`` it makes (the map's methods wrapped on that one map)."""
        pmap, clock = agent.pmap, agent.robot
        self.prior, self.spec, self.model = pmap.P.copy(), pmap.spec, agent.config.motion
        self.steps.clear()
        observe, predict = pmap.observe, pmap.predict

        def observed(detection) -> None:
            self.steps.append(MapStep(clock.now(), detection=detection))
            observe(detection)

        def predicted(dt_s, passable, model) -> None:
            self.steps.append(MapStep(clock.now(), dt_s=float(dt_s), surfaces=np.array(passable, copy=True)))
            predict(dt_s, passable, model)

        pmap.observe, pmap.predict = observed, predicted

    def replay(self, model: MotionModel | None) -> list[tuple[float, np.ndarray]]:
        """The map after each recorded observation, ``(t, P)``, from the recorded prior and observations
        with the recorded predictions made under ``model`` (None or speed 0: no prediction, the static
        map; the run's own model: the run's maps, bit for bit)."""
        if self.prior is None:
            raise ConfigError("nothing recorded: MapLog.attach(agent) before the agent runs")
        pmap = ProbabilityMap(self.spec)
        pmap.P = self.prior.copy()  # as recorded (not normalised again: bit for bit)
        out = []
        for s in self.steps:
            if s.detection is not None:
                pmap.observe(s.detection)
                out.append((s.t, pmap.P.copy()))
            elif model is not None:
                pmap.predict(s.dt_s, s.surfaces, model)
        return out
