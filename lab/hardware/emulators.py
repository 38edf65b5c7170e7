"""Device emulators on pseudo-terminals: a PTU-D46 and an iRobot Create 2, with fault switches.

Each emulator owns a pty pair (``os.openpty()``, raw mode) and a thread that ``select``s on the master
side and on a stop pipe, so :meth:`PtyDevice.close` never hangs: the thread is woken and joined *before*
the master fd is closed (closing it while a thread blocks in ``os.read`` does not hang the pty up, see the
reference notes section 6.3). The drivers open the slave side with real pyserial I/O; with ``link`` set,
a stable symlink points at the current slave, and :meth:`PtyDevice.replug` re-points it at a fresh pty, as
a USB adapter that reappears under the same name.

Each emulator keeps its own clock (:meth:`PtyDevice.now`, seconds since it was created) and kinematics:
the PTU moves at its set speeds, the Create integrates its wheel speeds, streams a frame every 15 ms and
its 16-bit encoders wrap. Everything the host sends is logged with the emulator's time, so a test can
measure, for example, when the last non-zero and the first zero Drive Direct arrived.

Fault switches (attributes or methods, all thread-safe):

* both: ``silent``, ``delay_s``, :meth:`~PtyDevice.inject` (garbage bytes), :meth:`~PtyDevice.unplug` /
  :meth:`~PtyDevice.replug`;
* PTU: ``drop_next``, ``garbage_next``, ``corrupt_next``, ``truncate_next`` (counts of replies to spoil),
  ``stall`` (motors do not move: ``A`` never completes), ``unit_id``, ``banner``,
  :meth:`PTUEmulator.limit_hit`;
* Create: ``mute_stream``, ``bad_checksum_next``, ``truncate_next``, ``garbage_before_next``,
  ``baud_mismatch``, ``mode32_quirk``, ``keeps_driving_when_unplugged``, and the world hooks
  :meth:`Create2Emulator.cliff`, :meth:`~Create2Emulator.wheel_drop`, :meth:`~Create2Emulator.bump`,
  :meth:`~Create2Emulator.charger`.
"""

from __future__ import annotations

import heapq
import math
import os
import random
import re
import select
import struct
import threading
import time
import tty
from dataclasses import dataclass
from pathlib import Path

from lab.hardware.create2 import PACKETS, OIMode, Op, encode_stream_frame

__all__ = [
    "Create2Emulator",
    "DriveRecord",
    "EmulatorSet",
    "PTUEmulator",
    "PtyDevice",
    "start_emulators",
]


class PtyDevice:
    """A byte-level device on a pty: subclasses implement :meth:`on_bytes` and :meth:`on_tick`.

    Parameters
    ----------
    link : path, optional
        A symlink kept pointing at the current slave (``port`` then returns it).
    name : str
    """

    tick_s = 0.005

    def __init__(self, link: str | os.PathLike | None = None, name: str = "device"):
        self.name = name
        self.link = str(link) if link else None
        self._t0 = time.monotonic()
        self._lock = threading.RLock()
        self._out: list[tuple[float, int, bytes]] = []
        self._seq = 0
        self._master: int | None = None
        self._slave: int | None = None
        self._slave_name = ""
        self._thread: threading.Thread | None = None
        self._stop_r: int | None = None
        self._stop_w: int | None = None
        self.plugged = False
        self.silent = False
        self.delay_s = 0.0
        self.rx_log: list[tuple[float, bytes]] = []
        self.dropped_bytes = 0
        #: how much later than it asked for the device thread got the CPU back, at most [s] (since reset
        #: to 0 by a test): the emulator's clock stamps what it receives when it runs, so on a loaded
        #: machine its timings include this; a test can tell a late host from a late emulator with it
        self.max_lateness_s = 0.0

    # --- clock and port -------------------------------------------------------------------------
    def now(self) -> float:
        """The emulator's clock [s] (monotonic, zero when it was created)."""
        return time.monotonic() - self._t0

    @property
    def port(self) -> str:
        return self.link or self._slave_name

    @property
    def rx_bytes(self) -> bytes:
        """Everything the host sent since start (or since :meth:`clear_log`)."""
        with self._lock:
            return b"".join(d for _, d in self.rx_log)

    def clear_log(self) -> None:
        with self._lock:
            self.rx_log.clear()

    # --- lifecycle ------------------------------------------------------------------------------
    def start(self):
        """Create the pty and start the device thread; returns self."""
        with self._lock:
            if not self.plugged:
                self._open()
        return self

    def _open(self) -> None:
        m, s = os.openpty()
        tty.setraw(m)
        tty.setraw(s)
        os.set_blocking(m, False)  # a host that stops reading must never block the device thread
        self._master, self._slave = m, s
        self._slave_name = os.ttyname(s)
        if self.link:
            tmp = self.link + ".tmp"
            if os.path.lexists(tmp):
                os.unlink(tmp)
            os.symlink(self._slave_name, tmp)
            os.replace(tmp, self.link)
        self._stop_r, self._stop_w = os.pipe()
        self.plugged = True
        self._thread = threading.Thread(target=self._run, name=f"{self.name} emulator", daemon=True)
        self._thread.start()

    def _stop_thread(self) -> None:
        t = self._thread
        if t is not None:
            os.write(self._stop_w, b"x")
            if t is not threading.current_thread():
                t.join(timeout=2.0)
        self._thread = None
        for fd in (self._stop_r, self._stop_w):
            if fd is not None:
                os.close(fd)
        self._stop_r = self._stop_w = None

    def _close_fds(self) -> None:
        for fd in (self._master, self._slave):
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._master = self._slave = None
        if self.link and os.path.islink(self.link):
            os.unlink(self.link)
        self.plugged = False
        with self._lock:
            self._out.clear()

    def unplug(self) -> None:
        """Pull the cable: stop the thread, then close the pty (the host sees EIO) and remove the link."""
        if not self.plugged:
            return
        self._stop_thread()
        self._close_fds()
        self.on_unplug()

    def replug(self) -> None:
        """Plug back in: a fresh pty under the same link; the device keeps its state (it stayed powered)."""
        if self.plugged:
            return
        with self._lock:
            self._open()

    def close(self) -> None:
        """Stop and release everything. Safe to call twice."""
        if self._thread is not None:
            self._stop_thread()
        if self._master is not None or self.plugged:
            self._close_fds()

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.close()
        return False

    # --- I/O --------------------------------------------------------------------------------------
    def send(self, data: bytes, extra_delay: float = 0.0) -> None:
        """Queue bytes for the host, after ``delay_s + extra_delay`` on the device clock."""
        with self._lock:
            if self.silent or not data:
                return
            self._seq += 1
            heapq.heappush(self._out, (self.now() + self.delay_s + extra_delay, self._seq, bytes(data)))

    def inject(self, data: bytes) -> None:
        """Send raw bytes now (garbage on the line), whatever the protocol state."""
        self.send(data)

    def _flush_due(self) -> None:
        now = self.now()
        while self._out and self._out[0][0] <= now:
            _, _, data = heapq.heappop(self._out)
            try:
                n = os.write(self._master, data)
                self.dropped_bytes += len(data) - n
            except OSError:  # EAGAIN (host not reading: a UART would overrun too) or EIO
                self.dropped_bytes += len(data)

    def _run(self) -> None:
        m, sr = self._master, self._stop_r
        while True:
            with self._lock:
                timeout = self.tick_s
                if self._out:
                    timeout = min(timeout, max(0.0, self._out[0][0] - self.now()))
            t_ask = time.monotonic()
            r, _, _ = select.select([m, sr], [], [], timeout)
            if sr in r:
                return
            if not r:  # woken by the timeout: by how much late
                self.max_lateness_s = max(self.max_lateness_s, time.monotonic() - t_ask - timeout)
            if m in r:
                try:
                    data = os.read(m, 4096)
                except BlockingIOError:
                    data = b""
                except OSError:  # EIO: nobody has the slave open (we keep it open, so rare)
                    data = b""
                    time.sleep(self.tick_s)
                if data:
                    with self._lock:
                        self.rx_log.append((self.now(), data))
                        if not self.silent:
                            self.on_bytes(data)
            with self._lock:
                self.on_tick(self.now())
                self._flush_due()

    # --- subclass hooks ---------------------------------------------------------------------------
    def on_bytes(self, data: bytes) -> None:  # pragma: no cover - abstract
        pass

    def on_tick(self, now: float) -> None:  # pragma: no cover - abstract
        pass

    def on_unplug(self) -> None:
        pass


# ================================================================================================
# PTU-D46
# ================================================================================================
_TOKEN = re.compile(r"([A-Za-z_?]+)([-+]?\d+)?")
_AXIS = {"P": "Pan", "T": "Tilt"}


class PTUEmulator(PtyDevice):
    """A PTU-D46 speaking the ASCII protocol (factory state: echo on, verbose feedback).

    Parameters
    ----------
    resolution_arcsec : float or (pan, tilt)
    pan_limits, tilt_limits : (int, int) [positions]
    speed_bounds : (int, int) [positions/s]
        ``PL``/``PU`` (and ``TL``/``TU``).
    speed : int [positions/s]
        Initial ``PS``/``TS``.
    reset_time_s : float [s]
        How long ``R`` takes before it answers ``!T!T!P!P*``.
    banner : bool
        Send a power-on banner whenever the port is (re)plugged.
    """

    def __init__(
        self,
        link=None,
        *,
        resolution_arcsec: float | tuple[float, float] = 185.1428,
        pan_limits: tuple[int, int] = (-3090, 3090),
        tilt_limits: tuple[int, int] = (-907, 604),
        speed_bounds: tuple[int, int] = (31, 2902),
        speed: int = 1000,
        reset_time_s: float = 0.2,
        banner: bool = False,
    ):
        super().__init__(link, "PTU-D46")
        r = resolution_arcsec if isinstance(resolution_arcsec, tuple) else (resolution_arcsec,) * 2
        self.res = {"P": float(r[0]), "T": float(r[1])}
        self.lim = {"P": tuple(pan_limits), "T": tuple(tilt_limits)}
        self.hard = {ax: (lo - 60, hi + 60) for ax, (lo, hi) in self.lim.items()}
        self.speed_lo = {"P": speed_bounds[0], "T": speed_bounds[0]}
        self.speed_hi = {"P": speed_bounds[1], "T": speed_bounds[1]}
        self.speed = {"P": int(speed), "T": int(speed)}
        self.accel = {"P": 2000, "T": 2000}
        self.base_speed = {"P": 1000, "T": 1000}
        self.pos = {"P": 0.0, "T": 0.0}
        self.target = {"P": 0, "T": 0}
        self._slaved_target: dict[str, int] = {}
        self.echo = True
        self.verbose = True
        self.limits_enforced = True
        self.exec_mode = "I"
        self.control = "CI"
        self.unit_id = 0
        self._selected = True
        self.reset_time_s = reset_time_s
        self.banner = banner
        self.stall = False
        self.drop_next = 0
        self.garbage_next = 0
        self.corrupt_next = 0
        self.truncate_next = 0
        self.commands: list[tuple[float, str]] = []
        self._token = bytearray()
        self._busy: str | None = None  # "A" or "R...": later commands wait, except halts
        self._busy_until = 0.0
        self._queue: list[str] = []
        self._last_tick: float | None = None
        self._rng = random.Random(1)

    def _open(self) -> None:
        super()._open()
        if self.banner:
            self.send(b"\r\nPan-Tilt Controller v2.14.0 (emulated), initializing...\r\n*\r\n")

    # --- world and faults -----------------------------------------------------------------------
    def limit_hit(self, axis: str = "P") -> None:
        """Send an asynchronous ``!P``/``!T`` now, as the unit does when an axis hits its limit."""
        self.send(f"!{axis.upper()}".encode())

    def position_steps(self) -> dict[str, int]:
        with self._lock:
            return {ax: int(round(v)) for ax, v in self.pos.items()}

    def command_names(self) -> list[str]:
        with self._lock:
            return [c for _, c in self.commands]

    # --- protocol -------------------------------------------------------------------------------
    def on_bytes(self, data: bytes) -> None:
        echo = bytearray()
        for b in data:
            if self.echo and self._selected:
                echo.append(b)
            if b in (32, 13, 10):
                if echo:
                    self.send(bytes(echo))
                    echo.clear()
                if self._token:
                    tok = self._token.decode("latin-1")
                    self._token.clear()
                    self._command(tok)
            else:
                self._token.append(b)
        if echo:
            self.send(bytes(echo))

    def _reply(self, text: str) -> None:
        if self.drop_next:
            self.drop_next -= 1
            return
        data = text.encode("latin-1") + b"\r\n"
        if self.garbage_next:
            self.garbage_next -= 1
            data = bytes(self._rng.choice(b"#%&@\x8f\xfe\x00\x13~") for _ in range(5)) + data
        if self.corrupt_next:
            self.corrupt_next -= 1
            data = data.replace(b"*", b"\xa4", 1)
        if self.truncate_next:
            self.truncate_next -= 1
            data = data[: max(1, len(text) // 2)]
        self.send(data)

    def _ok(self, value=None, verbose: str | None = None) -> None:
        if value is None:
            self._reply("*")
        elif self.verbose and verbose:
            self._reply(f"* {verbose}")
        else:
            self._reply(f"* {value}")

    def _err(self, msg: str) -> None:
        self._reply(f"! {msg}")

    def _command(self, tok: str) -> None:
        self.commands.append((self.now(), tok))
        m = _TOKEN.fullmatch(tok)
        if not m:
            if self._selected:
                self._err("Illegal Command")
            return
        name, arg = m.group(1).upper(), (int(m.group(2)) if m.group(2) else None)
        if name == "_":
            self._selected = arg in (0, self.unit_id)
            return
        if not self._selected:
            return
        if self._busy and name not in ("H", "HP", "HT"):
            self._queue.append(tok)
            return
        self._dispatch(name, arg)

    def _dispatch(self, name: str, arg: int | None) -> None:
        ax = name[0] if name[:1] in ("P", "T") and len(name) == 2 else None
        if ax is not None:
            self._axis_command(ax, name[1], arg)
            return
        if name in ("ED", "EE", "E"):
            if name != "E":
                self.echo = name == "EE"
            self._ok("ENABLED" if self.echo else "DISABLED") if name == "E" else self._ok()
        elif name in ("FT", "FV", "F"):
            if name != "F":
                self.verbose = name == "FV"
            self._ok("VERBOSE" if self.verbose else "TERSE") if name == "F" else self._ok()
        elif name in ("LE", "LD", "L"):
            if name != "L":
                self.limits_enforced = name == "LE"
            self._ok("ENABLED" if self.limits_enforced else "DISABLED") if name == "L" else self._ok()
        elif name in ("I", "S"):
            self.exec_mode = name
            self._ok()
        elif name in ("CI", "CV"):
            self.control = name
            self._ok()
        elif name == "A":
            for a, t in self._slaved_target.items():
                self.target[a] = t
            self._slaved_target.clear()
            if self._at_target():
                self._ok()
            else:
                self._busy = "A"
        elif name in ("H", "HP", "HT"):
            axes = "PT" if name == "H" else name[1]
            for a in axes:
                self.target[a] = int(round(self.pos[a]))
                self.pos[a] = float(self.target[a])
            if self._busy == "A" and self._at_target():
                self._finish_busy("*")
            self._ok()
        elif name in ("R", "RP", "RT"):
            self._busy = name
            self._busy_until = self.now() + self.reset_time_s
        elif name == "V":
            self._ok("Pan-Tilt Controller v2.14.0 (lab emulator)")
        elif name == "O":
            self._ok("Input 30 VDC @ 86 degF")
        elif name in ("DS", "DR", "DF"):
            self._ok()
        elif name == "U":
            if arg is not None:
                self.unit_id = arg
            self._ok(self.unit_id)
        elif name == "?":
            self._ok("PP TP PS TS PR TR PN PX TN TX PL PU TL TU A H R ED FT V")
        else:
            self._err("Illegal Command")

    def _axis_command(self, ax: str, op: str, arg: int | None) -> None:
        axis = _AXIS[ax]
        lo, hi = self.lim[ax]
        if op in ("P", "O"):
            if arg is None:
                if op == "P":
                    v = int(round(self.pos[ax]))
                    self._ok(v, f"Current {axis} position is {v}")
                else:
                    self._ok(self.target[ax], f"Desired {axis} position is {self.target[ax]}")
                return
            new = arg if op == "P" else self.target[ax] + arg
            if self.limits_enforced and new > hi:
                self._err(f"Maximum allowable {axis} position is {hi}")
            elif self.limits_enforced and new < lo:
                self._err(f"Minimum allowable {axis} position is {lo}")
            else:
                if self.exec_mode == "S":
                    self._slaved_target[ax] = new
                else:
                    self.target[ax] = new
                self._ok()
        elif op == "D":
            self._ok(self.target[ax], f"Desired {axis} position is {self.target[ax]}")
        elif op == "S":
            if arg is None:
                self._ok(self.speed[ax], f"Target {axis} speed is {self.speed[ax]} positions/sec")
            elif abs(arg) > self.speed_hi[ax]:
                self._err(f"{axis} speed cannot exceed {self.speed_hi[ax]} positions/sec")
            elif abs(arg) < self.speed_lo[ax]:
                self._err(f"Motor speed cannot be less than {self.speed_lo[ax]} pos/sec")
            else:
                self.speed[ax] = abs(arg)
                self._ok()
        elif op in ("A", "B"):
            store = self.accel if op == "A" else self.base_speed
            if arg is None:
                self._ok(store[ax])
            else:
                store[ax] = arg
                self._ok()
        elif op == "R":
            r = f"{self.res[ax]:.4f}"
            self._ok(r, f"{r} seconds arc per {axis} position")
        elif op == "N":
            self._ok(lo, f"Minimum {axis} position is {lo}")
        elif op == "X":
            self._ok(hi, f"Maximum {axis} position is {hi}")
        elif op in ("L", "U"):
            store = self.speed_lo if op == "L" else self.speed_hi
            if arg is None:
                word = "lower" if op == "L" else "upper"
                self._ok(store[ax], f"{axis} {word} speed limit is {store[ax]} positions/sec")
            else:
                store[ax] = arg
                self._ok()
        else:
            self._err("Illegal Command")

    def _at_target(self) -> bool:
        return all(abs(self.pos[a] - self.target[a]) < 1e-9 for a in "PT")

    def _finish_busy(self, reply: str) -> None:
        self._busy = None
        self._reply(reply)
        queued, self._queue = self._queue, []
        for tok in queued:
            self._command(tok)

    def on_tick(self, now: float) -> None:
        dt = 0.0 if self._last_tick is None else now - self._last_tick
        self._last_tick = now
        if self._busy and self._busy.startswith("R"):
            if now >= self._busy_until:
                axes = "PT" if self._busy == "R" else self._busy[1]
                for a in axes:
                    self.pos[a] = 0.0
                    self.target[a] = 0
                hits = "".join(f"!{a}!{a}" for a in reversed(axes))
                self._finish_busy(hits + "*")
            return
        if not self.stall:
            for a in "PT":
                step = self.speed[a] * dt
                d = self.target[a] - self.pos[a]
                self.pos[a] = (
                    float(self.target[a]) if abs(d) <= step else self.pos[a] + math.copysign(step, d)
                )
                h0, h1 = self.hard[a]
                if not h0 <= self.pos[a] <= h1:  # only reachable with limits disabled (LD)
                    self.pos[a] = min(max(self.pos[a], h0), h1)
                    self.target[a] = int(round(self.pos[a]))
                    self.send(f"!{a}".encode())
        if self._busy == "A" and self._at_target():
            self._finish_busy("*")


# ================================================================================================
# Create 2
# ================================================================================================
_ARGS = {
    7: 0,
    128: 0,
    129: 1,
    131: 0,
    132: 0,
    133: 0,
    134: 0,
    135: 0,
    136: 1,
    137: 4,
    138: 1,
    139: 3,
    141: 1,
    142: 1,
    143: 0,
    144: 3,
    145: 4,
    146: 4,
    147: 1,
    150: 1,
    162: 1,
    163: 4,
    164: 4,
    173: 0,
}


@dataclass(frozen=True)
class DriveRecord:
    """A drive command as the emulator received it: time on its clock, wheel speeds [mm/s], mode."""

    t: float
    right: int
    left: int
    mode: int
    accepted: bool


class Create2Emulator(PtyDevice):
    """An iRobot Create 2 speaking the Open Interface (binary) with kinematics, encoders and a stream.

    Parameters
    ----------
    encoder_start : (int, int)
        Initial left/right counts (e.g. near 65535 to make a test cross the wrap quickly).
    keeps_driving_when_unplugged : bool
        True, as the real robot: the OI has no link watchdog, so pulling the cable leaves the last
        Drive Direct running (the host can no longer stop it).
    mode32_quirk : bool
        After a Safe-mode trip report OI mode 32 instead of 1, as some firmware does.
    """

    STREAM_PERIOD_S = 0.015

    def __init__(
        self,
        link=None,
        *,
        encoder_start: tuple[int, int] = (0, 0),
        ticks_per_rev: float = 508.8,
        wheel_diameter: float = 0.072,
        wheel_base: float = 0.235,
        keeps_driving_when_unplugged: bool = True,
        mode32_quirk: bool = False,
    ):
        super().__init__(link, "Create 2")
        self.ticks_per_mm = ticks_per_rev / (math.pi * wheel_diameter * 1000.0)
        self.wheel_base_mm = wheel_base * 1000.0
        self.mode = OIMode.OFF
        self.reported_mode: int | None = None  # 32 after a trip with the quirk
        self.right_mm_s = 0
        self.left_mm_s = 0
        self.x = self.y = self.theta = 0.0  # true pose [m, m, rad]
        self.enc = [float(encoder_start[0]), float(encoder_start[1])]  # left, right [ticks]
        self.stream_ids: tuple[int, ...] = ()
        self.stream_paused = False
        self._next_frame_t = 0.0
        self.bumps = [False, False]  # left, right
        self.wheel_drops = [False, False]  # left, right
        self.cliffs = [False, False, False, False]
        self.charging = False
        self.battery = (2500, 3000)
        self.keeps_driving_when_unplugged = keeps_driving_when_unplugged
        self.mode32_quirk = mode32_quirk
        self.mute_stream = False
        self.bad_checksum_next = 0
        self.truncate_next = 0
        self.garbage_before_next = b""
        self.baud_mismatch = False
        self.drive_log: list[DriveRecord] = []
        self.opcodes: list[tuple[float, int, bytes]] = []
        self.trips: list[tuple[float, str]] = []
        self.frames_sent = 0
        self.unknown_bytes = 0
        self._rx = bytearray()
        self._last_tick: float | None = None

    # --- world hooks ----------------------------------------------------------------------------
    def cliff(self, which: int | None = 1, on: bool = True) -> None:
        """Set cliff sensor ``which`` (0 left, 1 front-left, 2 front-right, 3 right; None: all)."""
        with self._lock:
            for i in range(4) if which is None else (which,):
                self.cliffs[i] = on

    def wheel_drop(self, on: bool = True) -> None:
        """Lift the robot (both wheels drop) or put it back."""
        with self._lock:
            self.wheel_drops = [on, on]

    def bump(self, left: bool = True, right: bool = True) -> None:
        with self._lock:
            self.bumps = [left, right]

    def charger(self, on: bool = True) -> None:
        with self._lock:
            self.charging = on

    # --- observations for tests -------------------------------------------------------------------
    def wheel_speeds(self) -> tuple[int, int]:
        """The wheel speeds the robot is actually running (right, left) [mm/s]."""
        with self._lock:
            return self.right_mm_s, self.left_mm_s

    def drives(self) -> list[DriveRecord]:
        with self._lock:
            return list(self.drive_log)

    def last_nonzero_drive(self) -> DriveRecord | None:
        with self._lock:
            return next((d for d in reversed(self.drive_log) if d.right or d.left), None)

    def first_zero_drive_after(self, t: float) -> DriveRecord | None:
        with self._lock:
            return next((d for d in self.drive_log if d.t > t and not d.right and not d.left), None)

    def opcode_names(self, since: float = -math.inf) -> list[str]:
        with self._lock:
            return [
                Op(o).name if o in Op._value2member_map_ else str(o) for t, o, _ in self.opcodes if t >= since
            ]

    def encoder_counts(self) -> tuple[int, int]:
        """(left, right) as the robot reports them (16 bits)."""
        with self._lock:
            return int(math.floor(self.enc[0])) & 0xFFFF, int(math.floor(self.enc[1])) & 0xFFFF

    # --- protocol -------------------------------------------------------------------------------
    def on_bytes(self, data: bytes) -> None:
        if self.baud_mismatch:
            return  # at the wrong rate nothing the host sends makes sense to the robot
        self._rx += data
        rx = self._rx
        while rx:
            op = rx[0]
            if op in (Op.STREAM, Op.QUERY_LIST):
                if len(rx) < 2 or len(rx) < 2 + rx[1]:
                    return
                n = 2 + rx[1]
            elif op == 140:  # song: number, length, then 2 bytes per note
                if len(rx) < 3 or len(rx) < 3 + 2 * rx[2]:
                    return
                n = 3 + 2 * rx[2]
            elif op in _ARGS:
                n = 1 + _ARGS[op]
                if len(rx) < n:
                    return
            else:
                self.unknown_bytes += 1
                del rx[:1]
                continue
            args = bytes(rx[1:n])
            del rx[:n]
            self.opcodes.append((self.now(), op, args))
            self._execute(op, args)

    def _set_mode(self, mode: OIMode) -> None:
        self.mode = mode
        self.reported_mode = None
        if mode in (OIMode.OFF, OIMode.PASSIVE):
            self.right_mm_s = self.left_mm_s = 0

    def _drive(self, right: int, left: int) -> None:
        accepted = self.mode in (OIMode.SAFE, OIMode.FULL)
        self.drive_log.append(DriveRecord(self.now(), right, left, int(self.mode), accepted))
        if accepted:
            self.right_mm_s = max(-500, min(500, right))
            self.left_mm_s = max(-500, min(500, left))

    def _execute(self, op: int, args: bytes) -> None:
        if op == Op.START:
            self._set_mode(OIMode.PASSIVE)
        elif op == Op.SAFE and self.mode != OIMode.OFF:
            self._set_mode(OIMode.SAFE)
        elif op == Op.FULL and self.mode != OIMode.OFF:
            self._set_mode(OIMode.FULL)
        elif op == Op.STOP:
            self._set_mode(OIMode.OFF)
            self.stream_ids = ()
        elif op == Op.RESET:
            self._set_mode(OIMode.OFF)
            self.stream_ids = ()
            self.send(b"bl-start\r\nSTR730\r\nbootloader id: #x47135160 ...\r\n")
        elif self.mode == OIMode.OFF:
            return  # before Start the OI ignores everything else
        elif op == Op.DRIVE_DIRECT:
            r, l = struct.unpack(">hh", args)
            self._drive(r, l)
        elif op == Op.DRIVE:
            v, radius = struct.unpack(">hh", args)
            if radius in (-32768, 32767):
                self._drive(v, v)
            elif radius == -1:
                self._drive(-v, v)
            elif radius == 1:
                self._drive(v, -v)
            else:
                b = self.wheel_base_mm / 2.0
                self._drive(round(v * (radius + b) / radius), round(v * (radius - b) / radius))
        elif op == Op.DRIVE_PWM:
            r, l = struct.unpack(">hh", args)
            self._drive(round(r * 500 / 255), round(l * 500 / 255))
        elif op == Op.STREAM:
            ids = tuple(args[1:])
            self.stream_ids = tuple(i for i in ids if i in PACKETS)
            self.stream_paused = False
            self._next_frame_t = self.now()
        elif op == Op.PAUSE_RESUME_STREAM:
            self.stream_paused = args[0] == 0
        elif op == Op.SENSORS and args[0] in PACKETS:
            self.send(encode_stream_frame(self._values((args[0],)), (args[0],))[3:-1])
        elif op == Op.QUERY_LIST:
            ids = [i for i in args[1:] if i in PACKETS]
            self.send(b"".join(encode_stream_frame(self._values((i,)), (i,))[3:-1] for i in ids))

    def _values(self, ids) -> dict[int, int]:
        left, right = self.encoder_counts()
        mode = self.reported_mode if self.reported_mode is not None else int(self.mode)
        v = {
            7: (self.bumps[1] << 0)
            | (self.bumps[0] << 1)
            | (self.wheel_drops[1] << 2)
            | (self.wheel_drops[0] << 3),
            9: int(self.cliffs[0]),
            10: int(self.cliffs[1]),
            11: int(self.cliffs[2]),
            12: int(self.cliffs[3]),
            21: 2 if self.charging else 0,
            22: 15000,
            23: -200,
            24: 25,
            25: self.battery[0],
            26: self.battery[1],
            34: int(self.charging),
            35: mode,
            39: (self.right_mm_s + self.left_mm_s) // 2,
            40: 32767,
            41: self.right_mm_s,
            42: self.left_mm_s,
            43: left,
            44: right,
        }
        return {i: v.get(i, 0) for i in ids}

    def on_unplug(self) -> None:
        if not self.keeps_driving_when_unplugged:
            self.right_mm_s = self.left_mm_s = 0

    def on_tick(self, now: float) -> None:
        dt = 0.0 if self._last_tick is None else now - self._last_tick
        self._last_tick = now
        self._integrate(dt)  # after a replug this catches up on the time spent unplugged
        if self.mode == OIMode.SAFE:
            moving_forward = self.right_mm_s + self.left_mm_s > 0
            reason = None
            if any(self.wheel_drops):
                reason = "wheel drop"
            elif any(self.cliffs) and moving_forward:
                reason = "cliff"
            elif self.charging:
                reason = "charger"
            if reason:
                self._set_mode(OIMode.PASSIVE)
                if self.mode32_quirk:
                    self.reported_mode = 32
                self.trips.append((now, reason))
        if (
            self.stream_ids
            and not self.stream_paused
            and not self.mute_stream
            and self.mode != OIMode.OFF
            and now >= self._next_frame_t
        ):
            self._next_frame_t = max(self._next_frame_t + self.STREAM_PERIOD_S, now - self.STREAM_PERIOD_S)
            self._send_frame()

    def _send_frame(self) -> None:
        frame = bytearray(encode_stream_frame(self._values(self.stream_ids), self.stream_ids))
        if self.baud_mismatch:
            frame = bytearray((b * 7 + 0x55) & 0xFF for b in frame)  # bits read at the wrong rate
        if self.bad_checksum_next:
            self.bad_checksum_next -= 1
            frame[-1] ^= 0x5A
        if self.truncate_next:
            self.truncate_next -= 1
            frame = frame[: len(frame) // 2]
        if self.garbage_before_next:
            frame = bytearray(self.garbage_before_next) + frame
            self.garbage_before_next = b""
        self.frames_sent += 1
        self.send(bytes(frame))

    def _integrate(self, dt: float) -> None:
        if dt <= 0:
            return
        vr, vl = self.right_mm_s / 1000.0, self.left_mm_s / 1000.0
        self.enc[0] += self.left_mm_s * dt * self.ticks_per_mm
        self.enc[1] += self.right_mm_s * dt * self.ticks_per_mm
        v = 0.5 * (vr + vl)
        w = (vr - vl) / (self.wheel_base_mm / 1000.0)
        if abs(w) < 1e-12:
            self.x += v * dt * math.cos(self.theta)
            self.y += v * dt * math.sin(self.theta)
        else:  # exact arc
            th1 = self.theta + w * dt
            self.x += v / w * (math.sin(th1) - math.sin(self.theta))
            self.y -= v / w * (math.cos(th1) - math.cos(self.theta))
            self.theta = math.atan2(math.sin(th1), math.cos(th1))


# ================================================================================================
# both, for bring-up and tests
# ================================================================================================
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
