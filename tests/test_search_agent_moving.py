"""The search agent with a moving object's prediction step (SearchAgentConfig.motion): opt-in, the
static search unchanged without it, and with it the map predicted on the robot's clock between
updates, over the cells the robot believes passable."""

from __future__ import annotations

import numpy as np
import pytest
from test_search_agent import SPEC, scripted_run

from lab.search.config import SearchAgentConfig
from lab.search.motion import MotionModel, predict
from lab.search.probability_map import LocalSearchDetection, ProbabilityMap

DISTRACTOR, OBJECT = (1.5, 0.5), (-1.5, 1.9)
PEAKS = [(DISTRACTOR, 0.9), (OBJECT, 0.6)]


def record(out):
    return [(e.t, e.kind, e.cell, e.detail) for e in out.events], [s.P for s in out.snapshots], out.P_final


@pytest.mark.parametrize("motion", [None, MotionModel(speed_mps=0.0)])
def test_without_a_moving_object_the_run_is_the_static_one_bit_for_bit(monkeypatch, motion):
    static, _, _ = scripted_run(monkeypatch, OBJECT, PEAKS)
    other, _, _ = scripted_run(monkeypatch, OBJECT, PEAKS, config=SearchAgentConfig(motion=motion))
    ev0, snaps0, P0 = record(static)
    ev1, snaps1, P1 = record(other)
    assert ev1 == ev0
    assert len(snaps1) == len(snaps0) and all(
        np.array_equal(a, b) for a, b in zip(snaps0, snaps1, strict=True)
    )
    assert np.array_equal(P1, P0)


def test_a_moving_object_map_is_predicted_on_the_robots_clock(monkeypatch):
    """Between the global search's update and the failed local search's, the map diffuses for exactly
    the robot time that passed: the snapshot after the miss is Eq. (1) applied to the predicted map."""
    model = MotionModel(speed_mps=0.05)
    out, _, _ = scripted_run(monkeypatch, OBJECT, PEAKS, config=SearchAgentConfig(motion=model))
    assert out.found
    g = [s for s in out.snapshots if s.label == "global search"][0]
    miss = [s for s in out.snapshots if s.label == "local search failed"][0]
    # recompute: predict the global snapshot to the miss's time, then the local miss's update
    P = predict(g.P, np.ones(SPEC.shape, bool), miss.t - g.t, model, SPEC.resolution)
    pmap = ProbabilityMap(SPEC, P)
    cfg = SearchAgentConfig().local_search
    pmap.observe(LocalSearchDetection(miss.cell, 0, cfg.detection))
    np.testing.assert_allclose(miss.P, pmap.P, rtol=1e-9, atol=1e-15)
    assert abs(miss.P.sum() - 1.0) < 1e-12


def test_a_distractor_is_given_up_for_a_moving_object_too(monkeypatch):
    """A thing of the object's colours stays put while the object moves: the cells two failed searches
    answered for are excluded as for a stationary object (without it the robot went back to a
    distractor again and again), while the prediction keeps moving mass into them."""
    far_object = (2.5, 3.5)
    motion = MotionModel(speed_mps=0.05)

    def near_distractor(config):
        out, script, _ = scripted_run(
            monkeypatch,
            far_object,
            [(DISTRACTOR, 0.95)],
            max_time=400.0,
            config=config,
            visible=lambda p: False,
        )
        dx, dy = SPEC.cell_to_world(*SPEC.world_to_cell(*DISTRACTOR))
        near = [
            c for c in script.local_cells if np.hypot(*np.subtract(SPEC.cell_to_world(*c), (dx, dy))) < 0.45
        ]
        return out, len(near)

    out, n = near_distractor(SearchAgentConfig(motion=motion))
    off, n_off = near_distractor(SearchAgentConfig(motion=motion, max_local_misses=0))
    assert any(e.kind == "exclude" for e in out.events) and not any(e.kind == "exclude" for e in off.events)
    assert n <= 3 < n_off  # given up after the misses; without the exclusion it keeps going back


def test_the_passable_mask_is_read_from_the_agent(monkeypatch):
    """The agent asks ``passable()`` at each prediction; a wall across the map changes the prediction
    (the unit tests of lab/search/motion.py show that no mass crosses it)."""
    import lab.search.agent as agent_mod
    from lab.search.agent import SearchAgent

    calls = []
    orig = SearchAgent.__init__

    def init(self, *a, **k):
        wall = np.ones(SPEC.shape, bool)
        wall[:, 25] = False
        k["passable"] = lambda: calls.append(1) or wall
        orig(self, *a, **k)

    cfg = SearchAgentConfig(motion=MotionModel(speed_mps=0.1))
    open_room, _, _ = scripted_run(monkeypatch, OBJECT, PEAKS, config=cfg)
    monkeypatch.setattr(agent_mod.SearchAgent, "__init__", init)
    walled, _, _ = scripted_run(monkeypatch, OBJECT, PEAKS, config=cfg)
    assert calls
    assert not np.array_equal(walled.P_final, open_room.P_final)
    assert walled.P_final.sum() == pytest.approx(1.0, abs=1e-12)


def test_a_map_log_replays_the_run_and_the_same_run_without_prediction(monkeypatch):
    """MapLog records a predicting run's map changes: replayed with the run's motion model it gives
    the run's own maps bit for bit (its snapshots after each update, and the final map); replayed
    without a model, or at speed 0, it is the same observations on a static map, which the Bayes
    updates alone give (no prediction between them)."""
    import lab.search.agent as agent_mod
    from lab.search.agent import SearchAgent
    from lab.search.map_log import MapLog

    log = MapLog()
    orig = SearchAgent.__init__

    def init(self, *a, **k):
        orig(self, *a, **k)
        log.attach(self)

    monkeypatch.setattr(agent_mod.SearchAgent, "__init__", init)
    model = MotionModel(speed_mps=0.05)
    out, _, _ = scripted_run(monkeypatch, OBJECT, PEAKS, config=SearchAgentConfig(motion=model))
    assert any(s.detection is None and s.dt_s > 0 for s in log.steps)  # it predicted
    run = log.replay(model)
    np.testing.assert_array_equal(run[-1][1], out.P_final)
    maps = {t: P for t, P in run}  # the last map of each moment: after all its updates
    matched = [s for s in out.snapshots if s.t in maps]
    assert len(matched) >= 2  # the global search's and the failed local search's
    for snap in matched:
        np.testing.assert_array_equal(maps[snap.t], snap.P)
    static = log.replay(None)
    P = ProbabilityMap(SPEC)
    for s in log.steps:
        if s.detection is not None:
            P.observe(s.detection)
    np.testing.assert_array_equal(static[-1][1], P.P)
    assert not np.array_equal(static[-1][1], run[-1][1])
    assert all(np.array_equal(a[1], b[1]) for a, b in zip(static, log.replay(MotionModel(0.0)), strict=True))
