"""Process-wide stops for every live robot: close them all at interpreter exit, and on Ctrl-C (SIGINT, a
notebook's "interrupt kernel") ask each one to stop before the KeyboardInterrupt goes through.

``atexit`` and signal handlers belong to the process, not to one robot, so this module keeps the one
registry of live robots (a weak set: a robot that is garbage collected leaves it). The SIGINT handler
never writes to a port (the interrupted code may hold its lock): it asks each robot's servo thread to
send the zero. A previous handler is chained; ``SIG_IGN`` (a background job) is kept: then Ctrl-C only
stops the robot, it never raises.
"""

from __future__ import annotations

import atexit
import signal
import threading
import weakref

__all__ = ["close_all_at_exit", "register", "unregister"]

_LIVE: weakref.WeakSet = weakref.WeakSet()  # the robots to stop: HardwareRobot, or anything with close()
_HOOKS: dict = {"atexit": False, "sigint": False, "sigint_prev": None}


def close_all_at_exit() -> None:
    """Close every live robot (what ``atexit`` runs); a robot that fails to close does not stop the rest."""
    for r in list(_LIVE):
        try:
            r.close()
        except Exception:
            pass


def register(robot, *, sigint: bool) -> None:
    """Stop ``robot`` at interpreter exit and, with ``sigint``, on Ctrl-C (installs the hooks once).

    ``robot`` needs ``close()`` and ``request_stop()`` (no I/O: it runs inside a signal handler).
    """
    _LIVE.add(robot)
    _install_hooks(sigint)


def unregister(robot) -> None:
    """Forget ``robot`` (it closed itself)."""
    _LIVE.discard(robot)


def _install_hooks(sigint: bool) -> None:
    if not _HOOKS["atexit"]:
        atexit.register(close_all_at_exit)
        _HOOKS["atexit"] = True
    if sigint and not _HOOKS["sigint"] and threading.current_thread() is threading.main_thread():
        prev = signal.getsignal(signal.SIGINT)

        def _on_sigint(signum, frame):
            # never write to a port here: the interrupted code may hold its lock; the servo thread sends zero
            for r in list(_LIVE):
                r.request_stop()
            if callable(prev):
                prev(signum, frame)
            elif prev != signal.SIG_IGN:
                raise KeyboardInterrupt

        try:
            signal.signal(signal.SIGINT, _on_sigint)
            _HOOKS["sigint"] = True
            _HOOKS["sigint_prev"] = prev  # SIG_IGN in a background job: then Ctrl-C only stops, never raises
        except ValueError:  # not the main thread of the main interpreter
            pass
