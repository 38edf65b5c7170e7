"""A PTU-D46 emulator on a pty: the ASCII protocol (echo, verbose feedback, limits, speeds, A, R, H).

The head moves at its set speeds on the emulator's clock. Fault switches (thread-safe, besides those of
:class:`~lab.hardware.emulators.pty_device.PtyDevice`): ``drop_next``, ``garbage_next``,
``corrupt_next``, ``truncate_next`` (counts of replies to spoil), ``garbage_every`` (stray bytes before
every n-th reply, 0: never), ``stall`` (motors do not move: ``A``
never completes), ``unit_id``, ``banner``, :meth:`PTUEmulator.limit_hit`.
"""

from __future__ import annotations

import math
import random
import re

from lab.hardware.emulators.pty_device import PtyDevice

__all__ = ["PTUEmulator"]

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
        self.garbage_every = 0
        self._replies = 0
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

    def axis_positions(self) -> tuple[dict[str, float], dict[str, float]]:
        """Copies of the axes' true positions [steps] and resolutions [arc-seconds per step], by axis
        ``"P"``, ``"T"``, read together under the lock."""
        with self._lock:
            return dict(self.pos), dict(self.res)

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
        self._replies += 1
        every = self.garbage_every and self._replies % self.garbage_every == 0
        if self.garbage_next or every:
            if not every:
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
