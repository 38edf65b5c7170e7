"""Exceptions shared by the simulator, the hardware adapter and the command line.

Every error names what is wrong and what is allowed; the command line prints ``str(err)`` on one line
and exits non-zero.
"""

from __future__ import annotations

__all__ = [
    "LabError",
    "ConfigError",
    "AssetError",
    "LimitError",
    "NotEnabled",
    "EStopActive",
    "SafetyStop",
    "DeviceTimeout",
    "ConnectionLost",
    "CommandRejected",
    "ProtocolError",
]


class LabError(Exception):
    """Base class of the package's errors."""


class ConfigError(LabError, ValueError):
    """A configuration, scene file, option or argument is invalid (names the field and allowed values)."""


class AssetError(LabError, FileNotFoundError):
    """A file the package needs (scene, mesh, texture, cache) is missing or corrupt."""


class LimitError(LabError, ValueError):
    """A command is outside the device limits (pan/tilt range, speed); nothing was sent."""


class NotEnabled(LabError, RuntimeError):
    """A motion command arrived before ``enable()`` or after ``close()``."""


class EStopActive(LabError, RuntimeError):
    """The emergency stop is latched: call ``clear_estop()`` and then ``enable()``."""


class SafetyStop(LabError, RuntimeError):
    """The base stopped itself (bump, cliff, wheel drop); it stays disabled until ``enable()``."""


class DeviceTimeout(LabError, TimeoutError):
    """A device did not answer within its (bounded) timeout."""


class ConnectionLost(LabError, ConnectionError):
    """A device went away (unplugged, port closed)."""


class CommandRejected(LabError, RuntimeError):
    """A device answered a command with an error reply."""


class ProtocolError(LabError, RuntimeError):
    """A device's reply could not be parsed (garbage, wrong length, bad checksum)."""
