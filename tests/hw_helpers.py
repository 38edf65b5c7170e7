"""Shared helpers for the hardware tests (not a test module): bounded waits and the emulated config."""

from __future__ import annotations

import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
EMULATED_TOML = REPO / "hardware" / "emulated.toml"


def wait_until(predicate, timeout: float, step: float = 0.002) -> bool:
    """Poll ``predicate`` until it is true or ``timeout`` [s] passed; returns its last value."""
    t_end = time.monotonic() + timeout
    while True:
        if predicate():
            return True
        if time.monotonic() >= t_end:
            return bool(predicate())
        time.sleep(step)
