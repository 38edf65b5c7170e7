"""Where the robot's pose comes from: the localization modes a run chooses between."""

from __future__ import annotations

from enum import Enum

from lab.errors import ConfigError

__all__ = ["LocalizationMode"]


class LocalizationMode(Enum):
    """Where the robot's pose comes from: wheel odometry alone, or odometry corrected by landmarks."""

    ODOMETRY = "odometry"
    LANDMARKS = "landmarks"

    @classmethod
    def parse(cls, v) -> LocalizationMode:
        if isinstance(v, cls):
            return v
        try:
            return cls(v)
        except ValueError:
            raise ConfigError(
                f"localization must be one of {', '.join(m.value for m in cls)}, got {v!r}"
            ) from None
