"""Object search with a grid probability map (the search paper), end to end.

The data flow, one module per stage::

    probability_map  M_p: Eqs. (1)-(3), the detection model with alpha and beta, the growing beta;
                     ProbabilityMap.observe applies either search's detections
    motion           the prediction step for a moving object: mass diffuses at the speed bound over
                     each surface the robot's costmap shows, the floor and the raised cells a table's
                     top is among (a no-op at speed 0); map_log replays a run's map without it
    global_search    pan-tilt scan -> colour back-projection -> N_hist clusters -> sparse stereo -> M_p
    local_search     9 pan-tilt views -> SIFT + EKF (RANSAC start, ROI, gate) -> 6D pose, or a second
                     look at the colour peaks near the cell on enlarged regions -> 6D pose or a miss;
                     "found" only for a pose that explains the image and rests on a face (pose_check);
                     the start's refinement and the "found" verdict in tracking
    strategies       where to look next: paper / rate / lawnmower / frontier; the rate strategy's cell
                     order by probability per second (detection_rates)
    agent            the closed loop, navigation injected, with its settings (config) and records
                     (records); after a miss that saw the object's colours, the side look: 35 deg
                     round the colour peak, each way, the second look again (local_search.look_at_points)
    budget           the time budget: a Robot wrapper that stops the run at its deadline
    navigate         the agent's navigate on a Navigator: scan once, then drive near each target
    report_policy    when to re-localize: before every drive, and before a find is reported (with a
                     detour to a landmark when none is seen well from where the object was found)

Around it, in the layers above: the search's object databases are trained in
:mod:`lab.training.search`; a trial (world, placement, agent, scoring against truth -> the ``lab
search`` JSON) is :mod:`lab.runs.search`, with object placement in :mod:`lab.runs.placement`; the
paper's Figs. 2, 5 and 6 are drawn in :mod:`lab.viz` (the algorithms never plot).
"""

from lab.search.agent import INTERRUPTED, SearchAgent
from lab.search.budget import BudgetedRobot, SearchBudgetExceeded
from lab.search.config import SearchAgentConfig
from lab.search.global_search import ColourPeak, GlobalSearchConfig, GlobalSearchResult, global_search
from lab.search.local_search import (
    LocalSearchConfig,
    LocalSearchResult,
    SecondLookConfig,
    local_search,
    look_at_points,
)
from lab.search.motion import MotionModel, diffuse_step, diffusion_coefficient, passable_from_costmap, predict
from lab.search.navigate import NavigatorAdapter
from lab.search.probability_map import (
    ColourPeakDetection,
    DetectionModel,
    LocalSearchDetection,
    ProbabilityMap,
    bayes_update,
    cells_within,
    constant_beta_field,
    detection_likelihood,
    growing_beta_field,
    map_peaks,
    observe,
    region_prior,
    uniform_prior,
    update,
    update_global,
)
from lab.search.records import AgentResult, MapSnapshot, Navigate, NavigationResult, SearchEvent
from lab.search.report_policy import RelocalizingNavigate, ReportPolicy
from lab.search.strategies import Strategy, detection_rates, frontier_cells, lawnmower_targets

__all__ = [
    "INTERRUPTED",
    "AgentResult",
    "BudgetedRobot",
    "ColourPeak",
    "ColourPeakDetection",
    "DetectionModel",
    "GlobalSearchConfig",
    "GlobalSearchResult",
    "LocalSearchConfig",
    "LocalSearchDetection",
    "LocalSearchResult",
    "SecondLookConfig",
    "MapSnapshot",
    "MotionModel",
    "NavigationResult",
    "NavigatorAdapter",
    "Navigate",
    "ProbabilityMap",
    "RelocalizingNavigate",
    "ReportPolicy",
    "SearchAgent",
    "SearchAgentConfig",
    "SearchBudgetExceeded",
    "SearchEvent",
    "Strategy",
    "detection_rates",
    "bayes_update",
    "cells_within",
    "constant_beta_field",
    "detection_likelihood",
    "frontier_cells",
    "global_search",
    "growing_beta_field",
    "lawnmower_targets",
    "local_search",
    "look_at_points",
    "map_peaks",
    "diffuse_step",
    "diffusion_coefficient",
    "passable_from_costmap",
    "predict",
    "observe",
    "region_prior",
    "uniform_prior",
    "update",
    "update_global",
]
