"""Both emulators at once, for bring-up (``lab hardware emulate``), rehearsals and tests."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from lab.hardware.emulators.create2 import Create2Emulator
from lab.hardware.emulators.ptu import PTUEmulator

__all__ = ["EmulatorSet", "start_emulators"]


@dataclass
class EmulatorSet:
    """A running PTU and Create emulator pair; ``ptu_port`` and ``base_port`` are what the drivers open."""

    ptu: PTUEmulator
    create: Create2Emulator

    @property
    def ptu_port(self) -> str:
        return self.ptu.port

    @property
    def base_port(self) -> str:
        return self.create.port

    @property
    def ports(self) -> dict[str, str]:
        return {"ptu": self.ptu_port, "base": self.base_port}

    def close(self) -> None:
        self.ptu.close()
        self.create.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False


def start_emulators(
    link_dir: str | os.PathLike | None = None, *, ptu: dict | None = None, create: dict | None = None
) -> EmulatorSet:
    """Start a PTU-D46 and a Create 2 emulator.

    Parameters
    ----------
    link_dir : path, optional
        Where to put stable symlinks ``ttyPTU`` and ``ttyCreate`` (created if missing); without it the
        ports are the raw ``/dev/pts/N`` names.
    ptu, create : dict, optional
        Keyword arguments for :class:`PTUEmulator` and :class:`Create2Emulator`.

    Returns
    -------
    EmulatorSet
        With ``ports`` = ``{"ptu": ..., "base": ...}``; close it (or use ``with``) to stop both.
    """
    links = (None, None)
    if link_dir is not None:
        d = Path(link_dir)
        d.mkdir(parents=True, exist_ok=True)
        links = (d / "ttyPTU", d / "ttyCreate")
    p = PTUEmulator(links[0], **(ptu or {})).start()
    try:
        c = Create2Emulator(links[1], **(create or {})).start()
    except BaseException:
        p.close()
        raise
    return EmulatorSet(p, c)
