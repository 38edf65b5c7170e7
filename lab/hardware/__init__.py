"""lab.hardware: the real robot's devices, their emulators, and the Robot adapter over them.

* :mod:`lab.hardware.ptu`: PTU-D46 pan-tilt unit (ASCII protocol);
* :mod:`lab.hardware.create2`: iRobot Create 2 base driver, over :mod:`lab.hardware.open_interface` (the
  Open Interface codec: opcodes, packets, stream parser) and :mod:`lab.hardware.odometry` (encoders, pose);
* :mod:`lab.hardware.camera`: stereo capture, calibration files, rectification, replay, calibration tool;
* :mod:`lab.hardware.emulators`: both devices on pseudo-terminals, with fault switches (the pty base,
  one module per device, and the pair);
* :mod:`lab.hardware.config`: the strict TOML loader (``hardware/robot.toml``, ``hardware/emulated.toml``);
* :mod:`lab.hardware.robot`: :class:`HardwareRobot`, the :class:`lab.robot.Robot` implementation, with
  :mod:`lab.hardware.frame_time` (head and odometry at a frame's time) and :mod:`lab.hardware.stop_hooks`
  (every live robot stopped at exit and on Ctrl-C);
* :mod:`lab.hardware.cli`: ``emulate()`` and ``check()`` for ``lab hardware ...``.

This package imports :mod:`lab`; nothing in :mod:`lab` imports it.
"""

from lab.hardware.camera import ReplayStereoSource, StereoCalibration, calibrate_stereo, load_calibration
from lab.hardware.config import HardwareConfig, load_config
from lab.hardware.create2 import Create2
from lab.hardware.emulators import Create2Emulator, EmulatorSet, PTUEmulator, start_emulators
from lab.hardware.ptu import PTUD46
from lab.hardware.robot import HardwareRobot, RobotEvent
from lab.hardware.serial_port import PortUnavailable

__all__ = [
    "PTUD46",
    "Create2",
    "Create2Emulator",
    "EmulatorSet",
    "HardwareConfig",
    "HardwareRobot",
    "PTUEmulator",
    "PortUnavailable",
    "ReplayStereoSource",
    "RobotEvent",
    "StereoCalibration",
    "calibrate_stereo",
    "load_calibration",
    "load_config",
    "start_emulators",
]
