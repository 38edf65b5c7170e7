"""The predicting search follows a colour detection (SearchAgentConfig.colour_track, lab.search.follow):
with scripted searches on a kinematic robot, an object seen by the global search then drives away at
0.1 m/s; the agent approaches its track in legs and looks where the object is when it arrives, while
without the track it looks at the cell where the object was seen and misses. The re-observation is a
stand-in (a measurement of the scripted object's position); the perception behind it is tested in
test_search_follow_sim.py."""

from __future__ import annotations

import math

import numpy as np
from test_search_agent import SPEC, Script, scripted_run

import lab.search.agent as agent_mod
import lab.search.follow as follow_mod
from lab.search.colour_track import ColourTrack, ColourTrackConfig
from lab.search.config import SearchAgentConfig
from lab.search.motion import MotionModel

SEEN, SPEED, T_LEAVES = (-1.5, 1.9), 0.1, 12.0  # where the scan sees it; it leaves (+x) when the scan ends


def object_at(t: float) -> tuple[float, float]:
    return (SEEN[0] + SPEED * max(0.0, t - T_LEAVES), SEEN[1])


class MovingScript(Script):
    """The scripted searches with the object where :func:`object_at` puts it at the robot's time."""

    @property
    def object_xy(self):
        return object_at(self.robot.now())

    @object_xy.setter
    def object_xy(self, value):
        pass

    def global_search(self, robot, db, pmap, config):
        res = super().global_search(robot, db, pmap, config)
        res.colour_model = None  # the stand-in re-observation needs none
        return res


def run(monkeypatch, colour_track):
    monkeypatch.setattr("test_search_agent.Script", MovingScript)
    monkeypatch.setattr(
        agent_mod,
        "start_tracks",
        lambda res, speed, cfg: [ColourTrack((*SEEN, 0.1), 0.01 * np.eye(2), T_LEAVES, speed, cfg)],
    )
    seen = []

    def reobserve(robot, track, colour_model, db):
        t = robot.now()
        seen.append(t)
        return track.update(object_at(t), 0.0025 * np.eye(2), t)

    monkeypatch.setattr(follow_mod, "reobserve", reobserve)
    cfg = SearchAgentConfig(motion=MotionModel(speed_mps=SPEED), colour_track=colour_track)
    out, script, robot = scripted_run(monkeypatch, SEEN, [(SEEN, 0.9)], max_time=120.0, config=cfg)
    return out, script, seen


def test_the_agent_looks_where_the_followed_object_is_not_where_it_was_seen(monkeypatch):
    out, script, seen = run(monkeypatch, ColourTrackConfig())
    assert out.found, out.reason
    nav = next(e for e in out.events if e.kind == "navigate")
    assert nav.detail.startswith("followed a colour track")
    assert len(seen) >= 3  # re-observed between legs
    t_local = nav.t  # the local search starts when the robot has arrived
    where = SPEC.world_to_cell(*object_at(t_local))
    first = script.local_cells[0]
    assert max(abs(first[0] - where[0]), abs(first[1] - where[1])) <= 1  # where it is when the robot looks
    assert math.dist(object_at(t_local), SEEN) > 1.5  # far from where it was seen
    assert out.local_searches == 1


def test_without_the_track_the_agent_looks_where_it_was_seen_and_misses(monkeypatch):
    out, script, seen = run(monkeypatch, None)
    assert not seen
    assert script.local_cells[0] == SPEC.world_to_cell(*SEEN)
    assert next(e for e in out.events if e.kind == "local").detail == "scripted"
    assert out.local_searches >= 1 and not any(e.detail.startswith("followed") for e in out.events)
