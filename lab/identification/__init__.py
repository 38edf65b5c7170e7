"""Model identification with next-best-view planning: the identification paper's Sec. III and IV.

The data flow of one step, with the paper's three functions (Sec. IV)::

    frame -> stereo_features -> D_k                               (lab.vision)
    EKFBank.predict / update per model -> mu_bar, Sigma_bar         (lab.estimation)
    calc_current_entropy(P, D_k, scorers, states) -> Belief(P, H)   Eqs. (5), (7)-(9)   belief.py
        ModelScorer(db, config).score(D_k, x), one per model        Eq. (9)             scoring.py
        pool_shared_evidence (shared faces count alike)                                shared.py
        update_model_probabilities, entropy                         Eqs. (5), (7)       bayes.py
        (observe_frame does the updates and this in one call)                          step.py
    ModelHypotheses.from_estimates(P, estimates, G_WC[, z_turns(4), symmetry_log_weights(...)])
                                    the models' poses in W (and their look-alike turns)  hypotheses.py
    calc_possible_control_actions(centre, camera, is_reachable)     the ring of goals   actions.py
    calc_expected_entropy(evaluator, actions, hypotheses) -> E[H+]  Eq. (10)
        LookupTableEvaluator(tables)   W from Table I, Eqs. (13)-(15)                    lut.py, tables.py
        MonteCarloEvaluator(dbs)       sampled measurements, Eqs. (11)-(12)              montecarlo.py
    information_gain, next_best_action -> u*                        Eqs. (4), (6)       planner.py
    (plan_next_best_view chains the last three)

``lab tables`` builds the lookup tables offline from rendered views (:mod:`lab.training.tables`,
cached like the feature databases); :mod:`~lab.identification.synthetic` makes databases and tables
of any size without rendering. The agent is handed its databases and its evaluator: it never renders,
trains or reads a cache.
"""

from lab.identification.actions import (
    ActionConfig,
    CandidateAction,
    RingBlocked,
    aim_pan_tilt,
    calc_possible_control_actions,
    reachable_on,
)
from lab.identification.bayes import apply_floor, entropy, posterior, uniform, update_model_probabilities
from lab.identification.belief import Belief, calc_current_entropy
from lab.identification.hypotheses import (
    ModelHypotheses,
    NoObjectEstimate,
    TurnEvidence,
    symmetry_log_weights,
    turn_between,
    z_turns,
)
from lab.identification.lut import Eq15Constants, LookupTableEvaluator, eq15_log_likelihood
from lab.identification.montecarlo import MonteCarloConfig, MonteCarloEvaluator, cross_correspondences
from lab.identification.planner import (
    Plan,
    PlannerKind,
    ahead_on_ring,
    calc_expected_entropy,
    continue_direction,
    information_gain,
    next_best_action,
    plan_next_best_view,
    ring_smoothed,
)
from lab.identification.scoring import (
    Explanation,
    LikelihoodForm,
    ModelScore,
    ModelScorer,
    ScoringConfig,
    clutter_log_density,
    pose_estimate_rv,
    state_for_scoring,
)
from lab.identification.shared import (
    pool_shared_evidence,
    pools_shared_evidence,
    shared_features,
    shared_masks,
)
from lab.identification.step import FrameObservation, observe_frame
from lab.identification.tables import LookupTables, ModelTables, load_model_tables, save_model_tables
from lab.identification.viewpoints import nearest_viewpoint

__all__ = [
    "ActionConfig",
    "Belief",
    "CandidateAction",
    "Eq15Constants",
    "Explanation",
    "FrameObservation",
    "LikelihoodForm",
    "LookupTableEvaluator",
    "LookupTables",
    "ModelHypotheses",
    "ModelScore",
    "ModelScorer",
    "ModelTables",
    "MonteCarloConfig",
    "MonteCarloEvaluator",
    "NoObjectEstimate",
    "Plan",
    "PlannerKind",
    "RingBlocked",
    "ScoringConfig",
    "ahead_on_ring",
    "aim_pan_tilt",
    "apply_floor",
    "calc_current_entropy",
    "calc_expected_entropy",
    "calc_possible_control_actions",
    "clutter_log_density",
    "continue_direction",
    "cross_correspondences",
    "entropy",
    "eq15_log_likelihood",
    "make_evaluator",
    "information_gain",
    "load_model_tables",
    "nearest_viewpoint",
    "next_best_action",
    "observe_frame",
    "plan_next_best_view",
    "pose_estimate_rv",
    "pool_shared_evidence",
    "pools_shared_evidence",
    "posterior",
    "shared_features",
    "shared_masks",
    "reachable_on",
    "ring_smoothed",
    "save_model_tables",
    "state_for_scoring",
    "symmetry_log_weights",
    "TurnEvidence",
    "turn_between",
    "uniform",
    "update_model_probabilities",
    "z_turns",
]
