"""The agents on a :class:`~lab.hardware.robot.HardwareRobot`: what ``lab identify --robot CONFIG`` runs.

With ``[camera] source = "sim"`` (``hardware/rehearsal.toml``) the run is a rehearsal
(:mod:`lab.hardware.rehearsal`): the emulators and the rendered world are started here, the box is
``true_model`` moved by ``mover``, and the result is scored against the rendered world's truth, with the
fields of the ``lab identify`` contract. On a real robot there is no truth: ``true_model``,
``success`` and the pose error are None.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import time
from pathlib import Path

import numpy as np

from lab.geometry import se3_inv
from lab.hardware.config import HardwareConfig, load_config
from lab.io import write_json_atomic

__all__ = ["identify_on_robot"]


def _pose_error(G_est: np.ndarray, G_true: np.ndarray) -> dict:
    R = G_est[:3, :3].T @ G_true[:3, :3]
    return {
        "translation_m": float(np.linalg.norm(G_est[:3, 3] - G_true[:3, 3])),
        "rotation_deg": math.degrees(math.acos(float(np.clip((np.trace(R) - 1) / 2, -1, 1)))),
    }


def identify_on_robot(
    config: str | Path | HardwareConfig,
    *,
    planner: str = "lut",
    seed: int = 0,
    max_actions: int = 8,
    max_time_s: float = 240.0,
    true_model: int = 1,
    mover: str = "static",
    json_path: Path | None = None,
    progress=None,
    record: Path | None = None,
    keep_direction: float | None = None,
) -> dict:
    """Run the unchanged :class:`~lab.identification.agent.IdentificationAgent` on the robot a config
    describes and return the ``lab identify`` JSON (also written to ``json_path``).

    ``true_model`` and ``mover`` set the rendered scene of a rehearsal and are ignored otherwise.
    ``progress`` (callable(str)), if given, gets one line per decision. ``record``, if given, is where
    the run's animation goes: the live view (:mod:`lab.viz.live`) drawn at every step.
    ``keep_direction``, if given, replaces :attr:`AgentConfig.keep_direction
    <lab.identification.agent.AgentConfig>`.
    """
    from lab.hardware.rehearsal import rehearsal
    from lab.hardware.robot import HardwareRobot
    from lab.identification.agent import AgentConfig, IdentificationAgent

    cfg = config if isinstance(config, HardwareConfig) else load_config(config)
    agent_config = AgentConfig(max_actions=max_actions, max_time_s=max_time_s)
    if keep_direction is not None:
        agent_config = dataclasses.replace(agent_config, keep_direction=keep_direction)
    sim = cfg.camera.source == "sim"
    t_wall = time.perf_counter()
    with contextlib.ExitStack() as stack:
        if sim:
            r = stack.enter_context(rehearsal(cfg, true_model=true_model, mover=mover, seed=seed))
            robot = r.robot
        else:
            r = None
            robot = stack.enter_context(HardwareRobot(cfg))
        agent = IdentificationAgent(
            robot,
            planner=planner,
            seed=seed,
            config=agent_config,
        )
        if progress is not None:
            seen = [0]

            def on_step(a, frame):
                if len(a.decisions) > seen[0]:
                    seen[0] = len(a.decisions)
                    progress(f"decision {seen[0]} at t={frame.t - t0:.1f} s: P = {np.round(a.P, 3).tolist()}")

            agent.on_step = on_step
        recorder = None
        if record is not None:
            from lab.viz.live import LiveView
            from lab.viz.recorder import Recorder

            recorder = Recorder(record)  # one frame per step, chained after the progress lines
            LiveView.for_identification(agent, rate_hz=None, recorder=recorder, widget=False)
        t0 = robot.now()
        identified = agent.run()
        elapsed = robot.now() - t0
        truth = r.truth() if r is not None else None
        watchdog_stops = robot.watchdog_stops
    wall = time.perf_counter() - t_wall
    if recorder is not None:
        written = recorder.close()
        if progress is not None:
            progress(f"recording: {written}")
    pose_error = {"translation_m": None, "rotation_deg": None}
    if truth is not None and truth.G_WO is not None and agent.bank.estimates[true_model] is not None:
        pose_error = _pose_error(agent.bank.estimates[true_model].G_CO, se3_inv(truth.G_WC) @ truth.G_WO)
    result = {
        "true_model": true_model if sim else None,
        "identified_model": identified,
        "success": (identified == true_model) if sim else None,
        "actions": agent.n_actions,
        "sim_time_s": elapsed,  # the robot's (wall) clock: a rehearsal's scene runs on it too
        "wall_time_s": wall,
        "final_posterior": [float(p) for p in (agent.P / agent.P.sum())],
        "history": [
            {
                "t": s.t - t0,
                "posterior": [float(p) for p in s.posterior],
                "ptu_state": s.head_mode,
                "base_state": s.base_mode,
                "action": s.action,
            }
            for s in agent.steps
        ],
        "pose_error": pose_error,
        "planner": planner,
        "seed": seed,
        "mover": mover if sim else None,
        "robot": str(cfg.path) if cfg.path is not None else cfg.robot.name,
        "rehearsal": sim,
        "watchdog_stops": watchdog_stops,
        "keep_direction": agent.config.keep_direction,
        "decisions": [d.to_json(t0) for d in agent.decisions],
    }
    if json_path is not None:
        write_json_atomic(Path(json_path), result)
    return result
