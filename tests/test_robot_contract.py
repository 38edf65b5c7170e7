"""The Robot contract (tests/robot_contract.py) run on every implementation listed in IMPLEMENTATIONS.

The simulator (SimRobot in the open arena) and the HardwareRobot on the PTU-D46 and Create 2 emulators
(real pyserial I/O on ptys, with a synthetic ReplayStereoSource camera): one suite, so a notebook behaves
the same on both. To add an implementation, write a factory (a generator taking ``tmp_path`` and
yielding a ContractSubject) and add it to IMPLEMENTATIONS.
"""

from __future__ import annotations

import dataclasses
import math
import re

import pytest
from hw_helpers import EMULATED_TOML, wait_until
from robot_contract import ContractSubject, RobotContract

from lab.hardware.camera import ReplayStereoSource
from lab.hardware.config import load_config
from lab.hardware.emulators import start_emulators
from lab.hardware.robot import HardwareRobot

_PTU_MOTION = re.compile(r"^[PT][PSO][-+]?\d+$", re.IGNORECASE)


def hardware_emulated(tmp_path):
    """HardwareRobot on the emulators; safety trips are a lifted robot (wheel drop)."""
    emu = start_emulators(tmp_path)
    cfg = load_config(EMULATED_TOML).with_ports(base=emu.base_port, ptu=emu.ptu_port)
    # the emulators share this process: on a loaded machine the stream arrives in bursts, and the 0.1 s
    # stale-stream stop (tested on its own in test_hw_faults) would stop the base in the middle of a contract
    # test; the contract is about the Robot interface, so give the stream more slack here
    cfg = dataclasses.replace(cfg, base=dataclasses.replace(cfg.base, stale_timeout_s=0.4))
    cam = ReplayStereoSource.synthetic(cfg.camera.width, cfg.camera.height)
    robot = HardwareRobot(cfg, camera_source=cam)

    def clear_hazard():
        """Put the robot back on the floor, and wait until the driver has seen it there (frames stamped
        on arrival: a backlog of lifted-robot frames read late would still say 'wheel drop')."""
        emu.create.wheel_drop(False)

        def on_floor():
            s = robot.base.sensors()
            return s is not None and not (s.wheel_drop_left or s.wheel_drop_right)

        assert wait_until(on_floor, 2.0)

    def commands_sent() -> int:
        ptu_moves = sum(1 for c in emu.ptu.command_names() if _PTU_MOTION.match(c))
        return len(emu.create.drives()) + ptu_moves

    try:
        yield ContractSubject(
            robot,
            trip_safety=lambda: emu.create.wheel_drop(True),
            clear_hazard=clear_hazard,
            commands_sent=commands_sent,
            put_obstacle_ahead=lambda: emu.create.bump(True, True),  # the bumper is pressed at once
            stale_sensors=lambda on: setattr(emu.create, "mute_stream", on),
        )
    finally:
        robot.close()
        emu.close()


def simulator(tmp_path):
    """SimRobot in the open arena (nothing to bump into); a safety trip is a simulated cliff."""
    from lab.sim import OdometryNoise, SimRobot, SimWorld

    world = SimWorld("arena")
    robot = SimRobot(world, odometry_noise=OdometryNoise.none())
    try:

        def put_obstacle_ahead():
            """A 0.1 m cube 0.1 m ahead of the base's front."""
            p = world.truth.robot_pose()
            d = robot.base_limits.radius + 0.1 + 0.05
            world.add_box(
                "contract_obstacle",
                (0.1, 0.1, 0.1),
                (p.x + d * math.cos(p.theta), p.y + d * math.sin(p.theta)),
            )

        yield ContractSubject(
            robot, trip_safety=lambda: robot.trip_safety("cliff"), put_obstacle_ahead=put_obstacle_ahead
        )
    finally:
        robot.close()
        world.close()


IMPLEMENTATIONS = {"hardware-emulated": hardware_emulated, "simulator": simulator}


@pytest.fixture(params=sorted(IMPLEMENTATIONS))
def subject(request, tmp_path):
    yield from IMPLEMENTATIONS[request.param](tmp_path)


class TestRobotContract(RobotContract):
    pass
