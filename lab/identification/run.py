"""One identification episode, set up, run and scored: what ``lab identify`` and ``lab demo`` call.

The scene is the identification paper's: the observing robot in the open ``arena``, the box to identify
(``true_model``) on a carrier 1.2 m in front of it, turned so that the robot first faces a *shared* face
(the unique face points away), and moved by a mover (static, scripted, random, evasive, teleop).
Ground truth is used only to score the run (pose error) and by the mover, never by the agent.
"""

from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path

import numpy as np

from lab.errors import ConfigError
from lab.geometry import Pose2D, se3_inv
from lab.io import write_json_atomic

__all__ = ["floor_plan", "run_identify"]


def _pose_error(G_est: np.ndarray, G_true: np.ndarray) -> dict:
    t = float(np.linalg.norm(G_est[:3, 3] - G_true[:3, 3]))
    R = G_est[:3, :3].T @ G_true[:3, :3]
    return {
        "translation_m": t,
        "rotation_deg": math.degrees(math.acos(np.clip((np.trace(R) - 1) / 2, -1, 1))),
    }


def floor_plan(room_size_m: tuple[float, float], robot_radius_m: float, resolution_m: float = 0.1):
    """The known floor plan of a rectangular room centred on the origin, as A*'s cost grid: the walls
    grown by the robot's radius (a map the operator gives the robot, not the simulator's state).

    Parameters
    ----------
    room_size_m : (float, float) [m]
        The room's x and y extent.
    robot_radius_m : float [m]
        The robot's footprint radius.
    """
    from lab.navigation import Costmap, GridSpec

    sx, sy = (float(v) for v in room_size_m)
    if not (sx > 0 and sy > 0):
        raise ConfigError(f"room size must be positive, got {room_size_m}")
    spec = GridSpec.from_bounds(-sx / 2, -sy / 2, sx / 2, sy / 2, resolution_m)
    wall = np.zeros(spec.shape, dtype=bool)
    wall[0, :] = wall[-1, :] = wall[:, 0] = wall[:, -1] = True
    return Costmap.from_occupancy(spec, wall).inflated(robot_radius_m + resolution_m)


def run_identify(
    true_model: int,
    seed: int = 0,
    mover: str = "evasive",
    planner: str = "lut",
    max_actions: int = 8,
    out: Path | None = None,
    json_path: Path | None = None,
    max_time_s: float = 240.0,
    figures: bool = True,
    record: Path | None = None,
    attach=None,
    keep_direction: float | None = None,
) -> dict:
    """Run one episode in the simulator and return the ``lab identify`` JSON (also written to ``json_path``).

    Parameters
    ----------
    true_model : int
        Index of the box on the carrier (0..3).
    seed : int
        Seeds the start poses' jitter, the odometry noise, RANSAC and the random movers/planners.
    mover : str
        static, scripted, random, evasive or teleop.
    planner : str
        lut, mc, random or circle.
    record : Path, optional
        Write an animation of the run there: the live view (:mod:`lab.viz.live`) at every step.
    keep_direction : float, optional
        :attr:`AgentConfig.keep_direction <lab.identification.agent.AgentConfig>` (default 0.5; 1.0 is
        the plain argmax of Eq. (6)).
    attach : callable, optional
        ``attach(agent, carrier)`` once the agent is built, before it runs: a notebook's live view
        and teleoperation panel, e.g. ``display(LiveView.for_identification(agent).widget)`` and
        ``display(TeleopPanel(carrier.mover).widget)`` (with ``mover="teleop"``).
    """
    from lab.identification.agent import AgentConfig, IdentificationAgent
    from lab.sim import SimRobot, SimWorld, box_model, load_box_models
    from lab.sim.movers import make_mover

    box_model(true_model)  # a clear error before anything starts
    config = AgentConfig(max_actions=max_actions, max_time_s=max_time_s)
    if keep_direction is not None:
        config = dataclasses.replace(config, keep_direction=keep_direction)
    models = load_box_models()
    rng = np.random.default_rng(seed)
    t_wall = time.perf_counter()
    t_cpu = time.process_time()  # this process's CPU time: the cost of the episode whatever the load
    with SimWorld("arena") as world:
        # the unique face (+X) points away from the robot: it sees shared faces first
        carrier = world.add_carrier(
            models[true_model], Pose2D(0.0, 0.0, 0.0), box_yaw=float(rng.uniform(-0.3, 0.3))
        )
        robot = SimRobot(world, start=Pose2D(-1.2, float(rng.uniform(-0.1, 0.1)), 0.0), seed=seed)
        carrier.mover = make_mover(mover, carrier, observer_pose=world.truth.robot_pose, seed=seed)
        agent = IdentificationAgent(
            robot,
            tuple(m.name for m in models),
            planner=planner,
            seed=seed,
            config=config,
            floor_plan=None
            if world.scene.room is None
            else floor_plan(world.scene.room.size, robot.base_limits.radius),
        )
        recorder = None
        if record is not None:
            from lab.viz.live import LiveView
            from lab.viz.recorder import Recorder

            recorder = Recorder(record)  # the live view drawn at every step: one frame per step
            LiveView.for_identification(agent, rate_hz=None, recorder=recorder, widget=False)
        if attach is not None:
            attach(agent, carrier)
        truth = []  # (G_WC, G_WO) true at each frame's capture: for scoring and figures only
        agent_step = agent.step

        def step_with_truth():
            truth.append((world.truth.G_WC(), carrier.G_WO.copy()))
            return agent_step()

        agent.step = step_with_truth
        sim_t0, loop_wall0, loop_cpu0 = world.t, time.perf_counter(), time.process_time()
        identified = agent.run()
        loop_sim = world.t - sim_t0  # the loop alone: no start-up (databases, tables, scene), no figures
        loop_wall, loop_cpu = time.perf_counter() - loop_wall0, time.process_time() - loop_cpu0
        est = agent.bank.estimates[true_model]
        pose_error = {"translation_m": None, "rotation_deg": None}
        if est is not None and truth:
            G_WC_true, G_WO_true = truth[-1]  # the last frame, which the estimate has taken in
            pose_error = _pose_error(est.G_CO, se3_inv(G_WC_true) @ G_WO_true)
        sim_time = world.t
        collisions = world.truth.collisions
        true_poses = [G_WO for _, G_WO in truth]
    wall = time.perf_counter() - t_wall
    cpu = time.process_time() - t_cpu
    steps = agent.steps
    result = {
        "true_model": true_model,
        "identified_model": identified,
        "success": identified == true_model,
        "actions": agent.n_actions,
        "sim_time_s": sim_time,
        "wall_time_s": wall,
        "final_posterior": [float(p) for p in (agent.P / agent.P.sum())],
        "history": [
            {
                "t": s.t,
                "posterior": [float(p) for p in s.posterior],
                "ptu_state": s.head_mode,
                "base_state": s.base_mode,
                "action": s.action,
            }
            for s in steps
        ],
        "pose_error": pose_error,
        "planner": planner,
        "seed": seed,
        "mover": mover,
        "collisions": collisions,
        "keep_direction": config.keep_direction,
        "decisions": [d.to_json() for d in agent.decisions],
        "real_time_factor": sim_time / wall if wall > 0 else None,
        "cpu_time_s": cpu,
        "real_time_factor_cpu": sim_time / cpu if cpu > 0 else None,  # on one free core
        # the loop alone (start-up and figures excluded): sim seconds per wall second, as it ran on this
        # machine's cores under its load, and per CPU second of this process (robust to the load)
        "loop_sim_time_s": loop_sim,
        "loop_wall_time_s": loop_wall,
        "loop_cpu_time_s": loop_cpu,
        "real_time_factor_wall": loop_sim / loop_wall if loop_wall > 0 else None,
        "real_time_factor_loop_cpu": loop_sim / loop_cpu if loop_cpu > 0 else None,
        "filter_reseats": agent.n_reseats,
        "ring_blocked": agent.n_blocked,
        "track_lost": agent.n_lost,
    }
    if recorder is not None:
        p = recorder.close()
        result["recording"] = None if p is None else str(p)
    if json_path is not None:
        write_json_atomic(Path(json_path), result)
    if out is not None and figures and steps:
        _figures(Path(out), agent, true_poses, true_model)
        write_json_atomic(Path(out) / "identify.json", result)
    return result


def _figures(out: Path, agent, true_poses, true_model: int) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from lab.viz.identification import fig5, fig6, fig7

    out.mkdir(parents=True, exist_ok=True)
    steps = agent.steps
    t = np.array([s.t for s in steps])
    P = np.array([s.posterior for s in steps])
    modes = [s.head_mode for s in steps]
    est = np.array(
        [
            [
                *s.estimates_W[true_model][:3, 3],
                math.atan2(s.estimates_W[true_model][1, 0], s.estimates_W[true_model][0, 0]),
            ]
            for s in steps
        ]
    )
    true = np.array([[*G[:3, 3], math.atan2(G[1, 0], G[0, 0])] for G in true_poses])
    names = list(agent.names)
    decisions = [d.t for d in agent.decisions]
    fig5(t, est, true, P, modes, decisions, names, true_model).savefig(
        out / "fig5_pose_and_probabilities.png", dpi=90
    )
    if agent.decisions:
        d = agent.decisions[-1]
        odom = np.array([s.odom for s in steps])
        gains = d.gains if np.isfinite(d.gains).any() else np.zeros(len(d.candidates))
        fig6(d.candidates, gains, d.chosen, odom[-1], d.centre_W[:2], path_xy=odom[:, :2]).savefig(
            out / "fig6_information_gain_ring.png", dpi=90
        )
    fig7(
        [{"t": t, "posteriors": P, "modes": modes, "decisions": decisions, "true_model": true_model}], names
    ).savefig(out / "fig7_probabilities.png", dpi=90)
    plt.close("all")
