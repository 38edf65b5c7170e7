"""Where the package finds its worlds and keeps its caches."""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["repo_root", "worlds_dir", "cache_dir"]


def repo_root() -> Path:
    """The repository (or installed source tree) that holds ``lab/`` and ``worlds/``."""
    return Path(__file__).resolve().parent.parent


def worlds_dir() -> Path:
    """The folder of scene files and textures: ``$LAB_WORLDS`` or ``<repo>/worlds``."""
    return Path(os.environ.get("LAB_WORLDS", repo_root() / "worlds"))


def cache_dir() -> Path:
    """Per-user cache (meshes, feature databases, lookup tables): ``$LAB_CACHE`` or ``~/.cache/lab``.

    ``$XDG_CACHE_HOME`` is honoured when set. An empty ``$LAB_CACHE`` counts as unset (it would
    otherwise put the cache in whatever folder the command runs from).
    """
    if os.environ.get("LAB_CACHE"):
        p = Path(os.environ["LAB_CACHE"])
    else:
        p = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "lab"
    p.mkdir(parents=True, exist_ok=True)
    return p
