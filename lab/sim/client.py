"""The one import of pybullet: quiet (pybullet prints a build banner and plugin chatter from C).

Every other module of :mod:`lab.sim` takes ``pybullet`` and ``BulletClient`` from here.
"""

from __future__ import annotations

import os
import sys
from contextlib import contextmanager

__all__ = ["BulletClient", "pybullet", "quiet_stdout"]


@contextmanager
def quiet_stdout():
    """Silence C-level stdout and stderr (pybullet prints a build banner and plugin chatter from C)."""
    fds = []
    for stream in (sys.stdout, sys.stderr):
        try:
            fds.append(stream.fileno())
        except (AttributeError, ValueError, OSError):  # notebooks: no real fd
            pass
    if not fds:
        yield
        return
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(fd) for fd in fds]
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        for fd in fds:
            os.dup2(devnull, fd)
        yield
    finally:
        for fd, sv in zip(fds, saved, strict=True):
            os.dup2(sv, fd)
            os.close(sv)
        os.close(devnull)


with quiet_stdout():
    import pybullet  # noqa: E402
    from pybullet_utils.bullet_client import BulletClient  # noqa: E402
