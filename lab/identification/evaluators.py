"""The expected-entropy evaluator each planner uses: Monte Carlo (Eqs. (10)-(12)) or the lookup tables
(Eqs. (13)-(15)).

:func:`make_evaluator` builds one from what the agent is handed (its databases, the lookup tables a run
loaded, the robot's camera and the scoring rule); it reads no file and renders nothing. The
baselines (``random``, ``circle``) plan without one.
"""

from __future__ import annotations

from collections.abc import Sequence

from lab.errors import ConfigError
from lab.identification.loop_config import PlannerChoice
from lab.identification.lut import LookupTableEvaluator
from lab.identification.montecarlo import MonteCarloEvaluator
from lab.identification.scoring import ScoringConfig
from lab.identification.shared import shared_features
from lab.identification.tables import LookupTables
from lab.robot import StereoCamera
from lab.vision import FeatureDatabase

__all__ = ["make_evaluator"]


def make_evaluator(
    planner: PlannerChoice | str,
    databases: Sequence[FeatureDatabase],
    camera: StereoCamera,
    scoring: ScoringConfig | None = None,
    tables: LookupTables | None = None,
):
    """The evaluator of ``planner``: a :class:`LookupTableEvaluator` on ``tables`` (``lut``), a
    :class:`MonteCarloEvaluator` on ``databases`` (``mc``), or None (the baselines).

    Both pool the databases' shared features under ``scoring``, as the model probabilities do.

    Raises
    ------
    ConfigError
        An unknown planner, or ``lut`` without tables, or tables of other models than ``databases``.
    """
    try:
        planner = PlannerChoice(planner) if isinstance(planner, str) else planner
    except ValueError:
        raise ConfigError(
            f"unknown planner {planner!r}; planners: {', '.join(p.value for p in PlannerChoice)}"
        ) from None
    scoring = (scoring or ScoringConfig()).for_camera(camera)  # the clutter density: this camera's
    dbs = list(databases)
    if planner is PlannerChoice.LUT:
        if tables is None:
            raise ConfigError("the lut planner needs lookup tables (lab.training.get_tables builds them)")
        if tuple(tables.names) != tuple(db.name for db in dbs):
            raise ConfigError(
                f"lookup tables of {', '.join(tables.names)} do not match the databases "
                f"{', '.join(db.name for db in dbs)}"
            )
        return LookupTableEvaluator(tables, camera, scoring, shared=shared_features(dbs, scoring))
    if planner is PlannerChoice.MC:
        return MonteCarloEvaluator(dbs, camera, scoring, shared=shared_features(dbs, scoring))
    return None
