"""Object search with a grid probability map (the search paper), end to end.

The data flow, one module per stage::

    probability_map  M_p: Eqs. (1)-(3), the detection model with alpha and beta, the growing beta
    global_search    pan-tilt scan -> colour back-projection -> N_hist clusters -> sparse stereo -> M_p
    local_search     9 pan-tilt views -> SIFT + EKF (RANSAC start, ROI, gate) -> 6D pose or a miss
    agent            the closed loop (paper / lawnmower / frontier), navigation injected
    budget           the time budget: a Robot wrapper that stops the run at its deadline
    baselines        where the lawnmower and frontier baselines look next
    trial            run_search: world, placement, agent, scoring against truth -> the `lab search` JSON
    placement        valid spots on the floor, tables and shelf; searchable object names
    training         the search's object databases (three training rings)
    figures          the paper's Figs. 2, 5 and 6 (matplotlib; the algorithms never plot)
"""

from lab.search.agent import (
    AgentConfig,
    AgentResult,
    MapSnapshot,
    NavigationResult,
    SearchAgent,
    SearchEvent,
    Strategy,
)
from lab.search.budget import BudgetedRobot, SearchBudgetExceeded
from lab.search.global_search import ColourPeak, GlobalSearchConfig, GlobalSearchResult, global_search
from lab.search.local_search import LocalSearchConfig, LocalSearchResult, local_search
from lab.search.placement import check_placement, random_placement, searchable_objects
from lab.search.probability_map import (
    DetectionModel,
    ProbabilityMap,
    bayes_update,
    constant_beta_field,
    detection_likelihood,
    growing_beta_field,
    map_peaks,
    region_prior,
    uniform_prior,
    update,
    update_global,
)
from lab.search.training import SEARCH_TRAINING, search_database
from lab.search.trial import SearchResult, SearchTrace, run_search

__all__ = [
    "SEARCH_TRAINING",
    "AgentConfig",
    "AgentResult",
    "BudgetedRobot",
    "ColourPeak",
    "DetectionModel",
    "GlobalSearchConfig",
    "GlobalSearchResult",
    "LocalSearchConfig",
    "LocalSearchResult",
    "MapSnapshot",
    "NavigationResult",
    "ProbabilityMap",
    "SearchAgent",
    "SearchBudgetExceeded",
    "SearchEvent",
    "SearchResult",
    "SearchTrace",
    "Strategy",
    "bayes_update",
    "check_placement",
    "constant_beta_field",
    "detection_likelihood",
    "global_search",
    "growing_beta_field",
    "local_search",
    "map_peaks",
    "random_placement",
    "region_prior",
    "run_search",
    "search_database",
    "searchable_objects",
    "uniform_prior",
    "update",
    "update_global",
]
