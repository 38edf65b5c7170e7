"""The identification loop's handling of the box's look-alike turns, a blocked ring, a lost track and
its direction of travel round the ring.

Synthetic scenes (no rendering) check the turn bookkeeping and the common scoring pose; two short
simulator episodes (the circling baseline, so no lookup tables) check the defined fallbacks: a ring
whose goals are all unreachable makes the robot hold and retry, and a box that vanishes from view makes
the head scan and the base halt until the box is back, then the loop goes on. Two more, with gains
scripted by the test, check that the planner keeps its direction of travel when the goal ahead is nearly
as good as the best (``keep_direction``) and turns back otherwise; and an identified model's filter is
seated on the turn at which its most decisive frame was scored.
"""

import math

import ident_scenes as S
import numpy as np
import pytest

from lab.errors import ConfigError
from lab.geometry import G_to_pose6, Pose2D, Rz, se3
from lab.identification import (
    Belief,
    ModelScorer,
    ScoringConfig,
    TurnEvidence,
    calc_current_entropy,
    entropy,
    pose_estimate_rv,
    turn_between,
    uniform,
    z_turns,
)
from lab.identification.agent import AgentConfig


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
    scorers = [ModelScorer(db, ScoringConfig().for_camera(S.CAMERA)) for db in dbs]
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


def _agent(world, carrier_model=1, floor_plan=None, planner="circle", evaluator=None, **config):
    """An agent (circling baseline by default: no lookup tables) 1.2 m from a box showing a shared face."""
    from lab.identification.agent import IdentificationAgent
    from lab.sim import SimRobot, load_box_models
    from lab.training import get_database

    models = load_box_models()
    carrier = world.add_carrier(models[carrier_model], Pose2D(0.0, 0.0, 0.0), box_yaw=0.0)
    robot = SimRobot(world, start=Pose2D(-1.2, 0.0, 0.0), seed=0)
    agent = IdentificationAgent(
        robot,
        [get_database(m.name) for m in models],
        planner=planner,
        evaluator=evaluator,
        config=AgentConfig(**config),
        floor_plan=floor_plan,
    )
    robot.enable()
    return agent, carrier


def test_the_agent_scores_with_the_clutter_density_of_its_robots_camera():
    """The agent's scoring config takes ``log c`` from ``robot.camera`` (no rendering: nothing is
    captured): the simulator's default camera gives the value that used to be an import-time constant,
    bit for bit, and a 640 x 480 camera its own; an explicit value is kept."""
    from lab.identification import clutter_log_density
    from lab.identification.agent import IdentificationAgent
    from lab.identification.synthetic import synthetic_box_databases
    from lab.robot import StereoCamera
    from lab.sim import SimRobot, SimWorld

    dbs = synthetic_box_databases(4, np.random.default_rng(0))  # handed to the agent: none is trained

    def agent_for(camera=None, scoring=None):
        with SimWorld("arena") as world:
            robot = SimRobot(world, start=Pose2D(-1.2, 0.0, 0.0), seed=0, camera=camera)
            return IdentificationAgent(robot, dbs, planner="circle", scoring=scoring)

    default = agent_for()
    assert default.scoring.log_clutter_density == float.fromhex("-0x1.1383e55a78440p+2")  # -4.30492528757992
    wide = StereoCamera.from_fov(640, 480, 60.0, 0.12, mount_R=(0.0, 0.0, 0.7))
    agent = agent_for(wide)
    assert agent.scoring.log_clutter_density == clutter_log_density(wide)
    assert agent.scoring.log_clutter_density != default.scoring.log_clutter_density
    assert all(s.config is agent.scoring for s in agent.scorers)
    assert agent_for(wide, ScoringConfig(log_clutter_density=-3.0)).scoring.log_clutter_density == -3.0


def test_a_blocked_ring_holds_position_and_retries():
    from lab.runs.identify import floor_plan
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
    assert (
        ModelScorer(dbs[0], ScoringConfig().for_camera(S.CAMERA)).visible(
            S.estimate(S.box_pose(0.0), S.camera_at(180.0))
        )
        is None
    )  # off
    scorer = ModelScorer(dbs[0], ScoringConfig(visibility_deg=15.0).for_camera(S.CAMERA))
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


class _ScriptedGains:
    """An expected-entropy evaluator whose gains the test sets: one profile over the goals' azimuths
    [deg] per decision."""

    name = "lut"

    def __init__(self, *profiles):
        self.profiles = list(profiles)

    def expected_entropy(self, actions, hypotheses):
        gain = self.profiles.pop(0)(np.degrees([a.azimuth for a in actions]))
        return entropy(hypotheses.P) - gain


def _bump(centre_deg, height):
    return lambda az: height * np.clip(1 - np.abs((az - centre_deg + 180) % 360 - 180) / 30, 0, None)


@pytest.mark.parametrize("keep", [AgentConfig().keep_direction, 1.0])
def test_the_planner_keeps_its_direction_round_the_ring_when_the_goal_ahead_is_nearly_as_good(keep):
    from lab.sim import SimWorld

    # the robot starts at azimuth 180 deg; the first decision sends it clockwise to 120 deg; at the
    # second the best goal is back at 180 deg (0.5 nats), and 60 deg ahead has 0.4 (80 % of it)
    assert AgentConfig().keep_direction < 0.8
    scripted = _ScriptedGains(_bump(120, 0.5), lambda az: _bump(180, 0.5)(az) + _bump(60, 0.4)(az))
    with SimWorld("arena") as world:
        agent, _ = _agent(world, planner="lut", evaluator=scripted, keep_direction=keep)
        for _ in range(150):
            agent.step()
            if agent.n_actions == 2:
                break
    first, second = agent.decisions

    def azimuth(d):  # of the chosen goal, from the ring's centre [deg]
        x, y, _ = d.candidates[d.chosen]
        return math.degrees(math.atan2(y - d.centre_W[1], x - d.centre_W[0]))

    assert azimuth(first) == pytest.approx(120, abs=1) and first.direction == -1 and not first.kept_direction
    if keep < 0.8:  # keeps going clockwise, to the goal ahead
        assert azimuth(second) == pytest.approx(60, abs=1)
        assert second.direction == -1 and second.kept_direction
    else:  # Eq. (6): turns back to the best goal
        assert azimuth(second) == pytest.approx(180, abs=1)
        assert second.direction == 1 and not second.kept_direction
    assert second.to_json()["kept_direction"] is second.kept_direction


def test_an_identified_models_filter_is_seated_on_the_turn_its_most_decisive_frame_was_scored_at():
    from lab.sim import SimWorld

    with SimWorld("arena") as world:
        agent, _ = _agent(world)
    G = se3(Rz(0.3), [0.1, 0.0, 1.2])  # model 1's filter, in C
    Sigma_rv = np.diag([1e-4] * 3 + [1e-3] * 3)
    agent.bank[1].initialize(G_to_pose6(G), None, Sigma_rv=Sigma_rv)

    def frame(G_scored, ll):  # a frame's belief: scored at G_scored, with these log-likelihoods
        return Belief(
            uniform(4),
            0.0,
            np.asarray(ll, float),
            np.zeros(4, int),
            0,
            pose_estimate_rv(G_to_pose6(G_scored), Sigma_rv),
        )

    agent._note_decisive_turn(frame(G @ agent.turns[2], [0.0, 60.0, 0.0, 0.0]))  # the unique face: turn 2
    agent._note_decisive_turn(frame(G, [0.0, 0.5, 0.0, 0.0]))  # then shared faces, at its own pose
    agent._note_decisive_turn(frame(G @ agent.turns[1], [0.0, -3.0, 2.0, 0.0]))  # against it: ignored
    agent._seat_identified(1)
    np.testing.assert_allclose(agent.bank[1].estimate.G_CO, G @ agent.turns[2], atol=1e-6)
    assert agent.n_reseats == 1
    agent._seat_identified(1)  # seated once: the record went with the old pose
    assert agent.n_reseats == 1
    agent._seat_identified(0)  # no decisive frame for model 0: nothing to do
    assert agent.n_reseats == 1


def test_a_goal_across_the_ring_is_reached_the_way_the_robot_was_going():
    from lab.identification.agent import IdentificationAgent

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
