"""A child process for the rehearsal's Ctrl-C tests (not a test module): the ``lab`` command line, as a user
runs it, with the emulators it starts kept where this script can read them afterwards.

    python tests/rehearsal_child.py REPORT.json search --robot hardware/rehearsal.toml ...

It runs ``lab.cli.main(argv)`` unchanged. Around it: a SIGINT handler that stamps the emulator's clock
when the signal arrives and then raises KeyboardInterrupt (Python's default; a test's parent may have
started us with SIGINT ignored, as a shell does for background jobs), ``REPORT.json.moving`` written once
the emulated base's wheels turn (the parent's cue to interrupt while the base drives), and, once ``main``
has returned, ``REPORT.json``: the exit status and what the emulated base and head saw.
"""

from __future__ import annotations

import json
import signal
import sys
import threading
import time
from pathlib import Path

STATE: dict = {"emulators": None, "sigint_mono": None}


def _on_sigint(signum, frame):
    if STATE["sigint_mono"] is None:
        STATE["sigint_mono"] = time.monotonic()
    raise KeyboardInterrupt


def _watch_wheels(marker: Path, stop: threading.Event) -> None:
    while not stop.is_set():
        emu = STATE["emulators"]
        if emu is not None and emu.create.wheel_speeds() != (0, 0):
            marker.write_text(json.dumps({"t": emu.create.now()}))
            return
        time.sleep(0.02)


def main() -> int:
    report = Path(sys.argv[1])
    argv = sys.argv[2:]
    signal.signal(signal.SIGINT, _on_sigint)  # the robot's hook chains this one

    import lab.runs.rehearsal as rehearsal_mod

    start = rehearsal_mod.start_emulators

    def start_and_keep(link_dir, **kw):
        STATE["emulators"] = start(link_dir, **kw)
        return STATE["emulators"]

    rehearsal_mod.start_emulators = start_and_keep
    stop = threading.Event()
    threading.Thread(target=_watch_wheels, args=(report.with_suffix(".moving"), stop), daemon=True).start()
    from lab.cli import main as lab_main

    rc = lab_main(argv)
    stop.set()
    emu = STATE["emulators"]
    out: dict = {"rc": rc, "interrupted": STATE["sigint_mono"] is not None}
    if emu is not None:
        c, p, mono = emu.create, emu.ptu, STATE["sigint_mono"]
        t_c = None if mono is None else mono - time.monotonic() + c.now()  # on the emulators' clocks
        t_p = None if mono is None else mono - time.monotonic() + p.now()
        zero = None if t_c is None else c.first_zero_drive_after(t_c)
        moving = c.last_nonzero_drive()
        out.update(
            wheels=list(c.wheel_speeds()),
            sigint_t=t_c,
            last_nonzero_drive_t=None if moving is None else moving.t,
            first_zero_after_sigint_t=None if zero is None else zero.t,
            ptu_commands_after_sigint=[] if t_p is None else [n for when, n in p.commands if when >= t_p],
        )
    report.write_text(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
