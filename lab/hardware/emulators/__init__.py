"""Device emulators on pseudo-terminals: a PTU-D46 and an iRobot Create 2, with fault switches.

* :mod:`~lab.hardware.emulators.pty_device`: :class:`PtyDevice`, a byte-level device on a pty with its
  own thread and clock, unplug/replug and the faults every device has;
* :mod:`~lab.hardware.emulators.ptu`: :class:`PTUEmulator`, the PTU-D46's ASCII protocol;
* :mod:`~lab.hardware.emulators.create2`: :class:`Create2Emulator`, the Create 2's Open Interface,
  kinematics, encoders and sensor stream;
* :mod:`~lab.hardware.emulators.pair`: :func:`start_emulators` and :class:`EmulatorSet`, both at once.

The drivers open the emulators' ports with real pyserial I/O, so a test exercises the same code as the
robot.
"""

from lab.hardware.emulators.create2 import Create2Emulator, DriveRecord
from lab.hardware.emulators.pair import EmulatorSet, start_emulators
from lab.hardware.emulators.ptu import PTUEmulator
from lab.hardware.emulators.pty_device import PtyDevice

__all__ = [
    "Create2Emulator",
    "DriveRecord",
    "EmulatorSet",
    "PTUEmulator",
    "PtyDevice",
    "start_emulators",
]
