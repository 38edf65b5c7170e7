"""The identification loop's handling of the box's look-alike turns, a blocked ring and a lost track.

Synthetic scenes (no rendering) check the turn bookkeeping and the common scoring pose; two short
simulator episodes (the circling baseline, so no lookup tables) check the defined fallbacks: a ring
whose goals are all unreachable makes the robot hold and retry, and a box that vanishes from view makes
the head scan and the base halt until the box is back, then the loop goes on.
"""

import math

import ident_scenes as S
import numpy as np
import pytest

from lab.errors import ConfigError
from lab.geometry import Pose2D, Rz, se3
from lab.identification import (
    ModelScorer,
    ScoringConfig,
    TurnEvidence,
    calc_current_entropy,
    turn_between,
    uniform,
    z_turns,
)


def test_turn_between_names_the_quarter_turn_and_refuses_other_rotations():
    turns = z_turns(4)
    G = S.box_pose(20.0)
    for k in range(4):
        assert turn_between(G, G @ turns[k], turns) == k
    assert turn_between(G, G @ se3(Rz(math.radians(95.0))), turns) == 1  # within the tolerance
    assert turn_between(G, G @ se3(Rz(math.radians(45.0))), turns) is None  # between two turns


def test_turn_evidence_sums_keyframes_and_follows_a_reseated_filter():
    ev = TurnEvidence(2, 4, window=3)
    assert np.all(ev.total() == 0.0)
    for _ in range(4):  # one more than the window: the first is dropped
        ev.add([[0.0, -1.0, -2.0, -0.5], [0.0, 0.0, 0.0, 0.0]])
    np.testing.assert_allclose(ev.total()[0], [0.0, -3.0, -6.0, -1.5])
    ev.reseated(0, 3)  # the filter now sits on what was turn 3: new turn j is old 3 + j
    np.testing.assert_allclose(ev.total()[0], [-1.5, 0.0, -3.0, -6.0])
    ev.forget(0)
    assert np.all(ev.total() == 0.0)
    with pytest.raises(ConfigError, match="shape"):
        ev.add(np.zeros((3, 4)))
    with pytest.raises(ConfigError, match="window"):
        TurnEvidence(2, 4, window=0)


def test_filters_on_a_wrong_turn_still_let_the_unique_face_identify_its_model():
    """Every filter sits half a turn off (it expects a shared face where the unique face is): scored
    only at the filters' poses nobody explains the unique face; with the look-alike turns as candidate
    poses the right one is found and the unique face's model wins."""
    dbs = S.databases()
    scorers = [ModelScorer(db) for db in dbs]
    rng = np.random.default_rng(11)
    G_WO, G_WC = S.box_pose(0.0), S.camera_at(5.0)  # the unique +X face of the true model, frontal
    wrong = S.estimate(G_WO @ z_turns(4)[2], G_WC)
    for k in range(4):
        f = S.observe(dbs[k], G_WO, G_WC, rng)
        without = calc_current_entropy(uniform(4), f, scorers, [wrong] * 4)
        np.testing.assert_allclose(without.P, 0.25, atol=1e-9)
        P = uniform(4)
        for _ in range(3):
            P = calc_current_entropy(P, f, scorers, [wrong] * 4, symmetries=z_turns(4)).P
        assert P.argmax() == k and P[k] > 0.9, (k, P)
        # a shared face, seen by filters on a wrong turn, leaves every model alike
        f = S.observe(dbs[k], G_WO, S.camera_at(180.0), rng)
        est = S.estimate(G_WO @ z_turns(4)[1], S.camera_at(180.0))
        b = calc_current_entropy(uniform(4), f, scorers, [est] * 4, symmetries=z_turns(4))
        np.testing.assert_allclose(b.P, 0.25, atol=1e-9)
        assert b.n_explained.min() >= 20


def test_the_common_pose_can_be_turned_off():
    cfg = ScoringConfig(common_pose=False)
    assert cfg.share_poses and not cfg.common_pose


# --- the loop in the simulator ------------------------------------------------------------------------


def _agent(world, carrier_model=1, floor_plan=None, **config):
    """An agent (circling baseline: no lookup tables) 1.2 m from a box showing a shared face."""
    from lab.identification.agent import AgentConfig, IdentificationAgent
    from lab.sim import SimRobot, load_box_models

    models = load_box_models()
    carrier = world.add_carrier(models[carrier_model], Pose2D(0.0, 0.0, 0.0), box_yaw=0.0)
    robot = SimRobot(world, start=Pose2D(-1.2, 0.0, 0.0), seed=0)
    agent = IdentificationAgent(
        robot,
        tuple(m.name for m in models),
        planner="circle",
        config=AgentConfig(**config),
        floor_plan=floor_plan,
    )
    robot.enable()
    return agent, carrier


def test_a_blocked_ring_holds_position_and_retries():
    from lab.identification.run import floor_plan
    from lab.sim import SimWorld

    with SimWorld("arena") as world:
        # a floor plan whose room does not even hold the robot: no goal is reachable on any ring
        agent, _ = _agent(world, floor_plan=floor_plan((1.0, 1.0), 0.2), retry_s=1.5)
        recs = [agent.step() for _ in range(22)]
    assert agent.n_actions == 0 and agent.n_blocked >= 2  # tried, held, tried again
    assert all(r.base_mode != "driving" for r in recs)
    assert recs[-1].head_mode == "tracking"  # it keeps observing meanwhile


def test_a_lost_track_scans_halts_and_resumes():
    from lab.sim import SimWorld

    with SimWorld("arena") as world:
        agent, carrier = _agent(world, lost_after_s=1.0, settle_s=0.6)
        before = [agent.step() for _ in range(6)]
        carrier.set_pose(Pose2D(0.0, 4.5, 0.0))  # the box vanishes: far away, out of view
        gone = [agent.step() for _ in range(10)]
        carrier.set_pose(Pose2D(0.0, 0.0, 0.0))  # and comes back
        back = []
        for _ in range(25):
            back.append(agent.step())
            if back[-1].head_mode == "tracking":
                break
    assert before[-1].head_mode == "tracking"
    assert agent.n_lost == 1
    scanning = [r for r in gone + back if r.head_mode == "scanning"]
    assert scanning and all(r.base_mode == "halted" for r in scanning)  # HALT while scanning
    assert back[-1].head_mode == "tracking"  # the track is re-established


def test_the_optional_visibility_rule_keeps_the_features_seen_from_that_direction():
    dbs = S.databases()
    assert ModelScorer(dbs[0]).visible(S.estimate(S.box_pose(0.0), S.camera_at(180.0))) is None  # off
    scorer = ModelScorer(dbs[0], ScoringConfig(visibility_deg=15.0))
    G_WO, G_WC = S.box_pose(0.0), S.camera_at(180.0)  # the -X face
    vis = scorer.visible(S.estimate(G_WO, G_WC))
    az = np.degrees(dbs[0].viewpoints[:, 0])
    near = np.abs((az - 180.0 + 180.0) % 360.0 - 180.0) <= 15.0
    np.testing.assert_array_equal(vis, dbs[0].seen_from[:, near].any(axis=1))
    assert (
        vis.any()
        and not vis[dbs[0].seen_from[:, np.abs((az + 180.0) % 360.0 - 180.0) <= 15.0].any(axis=1)].any()
    )
    f = S.observe(dbs[0], G_WO, G_WC, np.random.default_rng(3), clutter=0)
    assert scorer.explain(f, S.estimate(G_WO, G_WC)).n_explained == len(f)  # what is seen stays explained
    with pytest.raises(ConfigError, match="visibility_deg"):
        ScoringConfig(visibility_deg=0.0)


def test_a_goal_across_the_ring_is_reached_the_way_the_robot_was_going():
    from lab.identification.agent import AgentConfig, IdentificationAgent

    arc = IdentificationAgent._arc_path  # uses no agent state
    here = Pose2D(-1.0, 0.0, 0.0)  # azimuth 180 deg from the centre
    across = Pose2D(1.0, 0.02, math.pi)  # azimuth ~1 deg: the short way is clockwise, through y > 0
    assert np.all(arc(None, (0.0, 0.0), across, here)[1:-1, 1] > 0)
    assert np.all(arc(None, (0.0, 0.0), across, here, direction=-1)[1:-1, 1] > 0)
    ccw = arc(None, (0.0, 0.0), across, here, direction=1)  # the long way, through y < 0
    assert np.all(ccw[1:-1, 1] < 0)
    np.testing.assert_allclose(np.hypot(ccw[:, 0], ccw[:, 1]), 1.0, atol=1e-3)  # along the ring
    near = Pose2D(math.cos(math.radians(120)), math.sin(math.radians(120)), 0.0)
    assert np.all(arc(None, (0.0, 0.0), near, here, direction=1)[1:-1, 1] > 0)  # not across: short way
    with pytest.raises(ConfigError, match="keep_direction must be within"):
        AgentConfig(keep_direction=1.5)
