"""Directed Perception / FLIR PTU-D46 pan-tilt unit driver: the ASCII protocol over a serial port.

The protocol (Directed Perception, *Pan-Tilt Unit-D46 Series User's Manual*, v2.14.0, section 4, "the
ASCII command protocol"; FLIR's D48E/E-series manuals use the same command set):

* a command is letters plus an optional signed integer, ended by a space or CR (``PP-500 ``);
* replies: ``*`` (done), ``* <value>`` (query), ``! <message>`` (refused), each ended by CR LF;
* with echo on (the factory default) the command comes back in front of its reply (``PP * 22``), and
  verbose feedback spells values out (``* Current Pan position is 22``); the driver sends ``ED`` and ``FT``
  at connect, and its parser tolerates both until then;
* ``!P`` / ``!T`` (an axis hit its limit) may arrive at any moment, mixed into other replies: they are
  stripped before parsing, counted and reported as a "limit_hit" event (the unit then needs ``home()``).

Positions are integer "positions" (steps). The resolution (``PR``/``TR``, arc-seconds per step), position
limits (``PN``/``PX``/``TN``/``TX``) and speed bounds (``PL``/``PU``/``TL``/``TU``) are read from the unit
at connect, never hard-coded. Angles follow ``docs/conventions.md`` (pan counter-clockwise from above,
tilt up) through a per-axis ``sign`` and ``zero_offset`` taken from the configuration::

    angle [rad] = sign * (steps * resolution - zero_offset)

Every read has a deadline; queries and the absolute commands (``PP<n>``, ``TP<n>``, ``PS<n>``, ``TS<n>``,
``I``, ``CI``, ``LE``, ``ED``, ``FT``: safe to repeat) are retried once on a garbled or missing
reply; one lock serialises the transactions on a port. A move that still fails halts the head and re-reads
its position as the targets, so ``targets`` never describe a move the unit may not be making.
"""

from __future__ import annotations

import math
import re
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import serial

from lab.errors import CommandRejected, ConnectionLost, DeviceTimeout, LimitError, ProtocolError
from lab.hardware.config import HardwareConfig, PTUConfig
from lab.hardware.serial_port import lost, open_port
from lab.robot import PanTiltLimits, check_finite

__all__ = ["ARCSEC", "PTUD46", "PTUReply", "parse_number", "parse_reply", "repeatable"]

ARCSEC = math.pi / (180.0 * 3600.0)  # one arc-second [rad]

_ASYNC = re.compile(r"!([PT])(?![A-Za-z])")  # "!P"/"!T" limit hits; an error reply is "! <message>"
_NUMBER = re.compile(r"[-+]?\d+(?:\.\d+)?")
# absolute commands: repeating one after a lost or garbled reply leaves the unit in the same state
_REPEATABLE = re.compile(r"^(?:[PT][PS][-+]?\d+|I|CI|LE|ED|FT)$")


def repeatable(command: str) -> bool:
    """True for commands whose repetition is harmless (absolute positions/speeds, modes)."""
    return bool(_REPEATABLE.match(command.strip().upper()))


@dataclass(frozen=True)
class PTUReply:
    """One parsed reply line.

    Attributes
    ----------
    kind : {"ok", "error", "none"}
        ``*``, ``!``, or nothing left after removing the echo and the asynchronous limit hits.
    body : str
        The value (``* <value>``) or the error message (``! <message>``), stripped.
    limit_hits : tuple of str
        "P" and/or "T" for every asynchronous ``!P``/``!T`` found in the line.
    """

    kind: str
    body: str
    limit_hits: tuple[str, ...] = ()


def parse_reply(line: str, command: str | None = None) -> PTUReply:
    """Parse one reply line (without its CR LF).

    Strips ``!P``/``!T`` wherever they appear, then an echoed ``command`` prefix (echo on), then reads
    ``*`` / ``!``. Anything else raises :class:`ProtocolError`; a missing value is never read as 0.
    """
    hits = tuple(_ASYNC.findall(line))
    text = _ASYNC.sub("", line).strip()
    if command:
        c = command.strip().upper()
        if text.upper().startswith(c):
            rest = text[len(c) :]
            if not rest or rest[0] in " \t*!":
                text = rest.strip()
    if not text:
        return PTUReply("none", "", hits)
    if text[0] == "*":
        return PTUReply("ok", text[1:].strip(), hits)
    if text[0] == "!":
        return PTUReply("error", text[1:].strip(), hits)
    raise ProtocolError(f"PTU-D46: unexpected reply {line!r}" + (f" to {command!r}" if command else ""))


def parse_number(body: str, terse: bool = True) -> float:
    """The number in a query reply's body: the whole body in terse mode, else the first number in it."""
    body = body.strip()
    if _NUMBER.fullmatch(body):
        return float(body)
    if not terse:
        m = _NUMBER.search(body)
        if m:
            return float(m.group())
    raise ProtocolError(f"PTU-D46: expected a number, got {body!r}")


EventCallback = Callable[[str, str], None]


class PTUD46:
    """A PTU-D46 on a serial port or ``socket://`` URL.

    Parameters
    ----------
    port : str
    baudrate : int
        9600 is the factory setting.
    timeout_s : float [s]
        Deadline for one reply (queries get one retry).
    banner_wait_s : float [s]
        How long to let a power-on banner drain before the handshake.
    pan_sign, tilt_sign : {+1, -1}
        +1 when the unit's positive direction is ours (pan CCW from above, tilt up).
    pan_zero_offset, tilt_zero_offset : float [rad]
        The unit's own angle (its direction, ``steps * resolution``) at which our angle is zero.
    default_speed : float [rad/s], optional
        Speed set at connect and used when a move gives none; default: the unit's current ``PS``/``TS``.
    move_margin_s : float [s]
        Added to the expected travel time to get the deadline of a waited move.
    on_event : callable(kind, message), optional
        Called with ("limit_hit", "pan"/"tilt") and ("connection_lost", message).
    """

    def __init__(
        self,
        port: str,
        *,
        baudrate: int = 9600,
        timeout_s: float = 1.0,
        banner_wait_s: float = 0.6,
        pan_sign: int = 1,
        tilt_sign: int = 1,
        pan_zero_offset: float = 0.0,
        tilt_zero_offset: float = 0.0,
        default_speed: float | None = None,
        move_margin_s: float = 1.0,
        on_event: EventCallback | None = None,
    ):
        if pan_sign not in (1, -1) or tilt_sign not in (1, -1):
            raise ValueError(f"pan_sign and tilt_sign must be +1 or -1, got {pan_sign}, {tilt_sign}")
        self.port = port
        self.baudrate = baudrate
        self.timeout_s = timeout_s
        self.banner_wait_s = banner_wait_s
        self.sign = {"P": pan_sign, "T": tilt_sign}
        self.zero = {"P": float(pan_zero_offset), "T": float(tilt_zero_offset)}
        self.default_speed = default_speed
        self.move_margin_s = move_margin_s
        self.on_event = on_event
        self._ser: serial.SerialBase | None = None
        self._lock = threading.RLock()  # one transaction at a time on this port
        self._rx = bytearray()
        self._terse = False
        self.lost: ConnectionLost | None = None
        self.version = ""
        self.res: dict[str, float] = {}  # rad per step
        self.step_limits: dict[str, tuple[int, int]] = {}
        self.speed_bounds: dict[str, tuple[int, int]] = {}  # steps/s
        self.speed_steps: dict[str, int] = {}
        self.target_steps: dict[str, int] = {"P": 0, "T": 0}
        self.limit_hits = 0
        self.needs_home = False
        self.counters = {"protocol_errors": 0, "timeouts": 0, "retries": 0, "rejected": 0, "stray_bytes": 0}

    @classmethod
    def from_config(
        cls, config: PTUConfig | HardwareConfig, *, on_event: EventCallback | None = None
    ) -> PTUD46:
        """The driver a ``[ptu]`` section describes: the one place that maps its keys onto parameters.

        The section's degrees (``pan_zero_offset_deg``, ``tilt_zero_offset_deg``, ``speed_deg_s``) become
        the driver's radians here.

        Parameters
        ----------
        config : PTUConfig or HardwareConfig
            The ``[ptu]`` section, or a whole config (its ``ptu`` is used).
        on_event : callable(kind, message), optional
            As for the constructor.
        """
        p = config.ptu if isinstance(config, HardwareConfig) else config
        return cls(
            p.port,
            baudrate=p.baudrate,
            timeout_s=p.timeout_s,
            banner_wait_s=p.banner_wait_s,
            pan_sign=p.pan_sign,
            tilt_sign=p.tilt_sign,
            pan_zero_offset=math.radians(p.pan_zero_offset_deg),
            tilt_zero_offset=math.radians(p.tilt_zero_offset_deg),
            default_speed=math.radians(p.speed_deg_s),
            move_margin_s=p.move_margin_s,
            on_event=on_event,
        )

    # --- lifecycle ------------------------------------------------------------------------------
    @property
    def connected(self) -> bool:
        return self._ser is not None and self.lost is None

    def connect(self) -> None:
        """Open the port, drain the banner, echo off, terse, read resolution/limits/speeds, ``CI``, ``I``.

        Raises PortUnavailable, DeviceTimeout or ProtocolError (the port is closed again).
        """
        if self._ser is not None:
            return
        self._ser = open_port(self.port, self.baudrate, what="PTU-D46", config_key="[ptu] port")
        self.lost = None
        self._rx.clear()
        self._terse = False
        try:
            if self.banner_wait_s > 0:
                time.sleep(self.banner_wait_s)
            self._drain()
            self._transact("ED", retry=True)  # echo off (the parser tolerates the echo until then)
            self._transact("FT", retry=True)  # terse feedback
            self._terse = True
            self.version = self._transact("V", retry=True)
            for ax in "PT":
                arcsec = self._query_number(f"{ax}R")
                if not 0.1 < arcsec < 3600:
                    raise ProtocolError(
                        f"PTU-D46: implausible {ax}R resolution {arcsec} arc-seconds per position"
                    )
                self.res[ax] = arcsec * ARCSEC
                lo, hi = int(self._query_number(f"{ax}N")), int(self._query_number(f"{ax}X"))
                if not lo < hi:
                    raise ProtocolError(f"PTU-D46: implausible {ax} limits [{lo}, {hi}]")
                self.step_limits[ax] = (lo, hi)
                sl, su = int(self._query_number(f"{ax}L")), int(self._query_number(f"{ax}U"))
                if not 0 <= sl < su:
                    raise ProtocolError(f"PTU-D46: implausible {ax} speed bounds [{sl}, {su}] positions/s")
                self.speed_bounds[ax] = (sl, su)
                self.speed_steps[ax] = int(self._query_number(f"{ax}S"))
            self._transact("CI")  # independent speed control
            self._transact("I")  # immediate execution
            self._transact("LE")  # enforce the position limits
            if self.default_speed is not None:
                self.limits.check_speed(self.default_speed)
                self._set_speed(self.default_speed)
            else:
                s = min(self.speed_steps["P"] * self.res["P"], self.speed_steps["T"] * self.res["T"])
                self.default_speed = min(max(s, self.limits.min_speed), self.limits.max_speed)
            for ax in "PT":
                self.target_steps[ax] = int(self._query_number(f"{ax}P"))
        except BaseException:
            self.release_port()
            raise

    def reconnect(self) -> None:
        """Release the port and connect again (re-reads everything from the unit)."""
        self.release_port()
        self.connect()

    def close(self) -> None:
        """Halt both axes (best effort) and release the port. Safe to call twice."""
        if self.connected:
            try:
                self._transact("H", timeout=min(self.timeout_s, 0.5))
            except (DeviceTimeout, ProtocolError, CommandRejected, ConnectionLost):
                pass
        self.release_port()

    def release_port(self) -> None:
        """Release the serial port without a word to the unit (:meth:`close` halts the axes first)."""
        with self._lock:
            if self._ser is not None:
                try:
                    self._ser.close()
                except OSError:
                    pass
            self._ser = None

    # --- conversions and limits -----------------------------------------------------------------
    def to_steps(self, axis: str, angle: float) -> int:
        """Our angle [rad] -> the unit's position for axis "P" or "T"."""
        return int(round((self.sign[axis] * angle + self.zero[axis]) / self.res[axis]))

    def to_rad(self, axis: str, steps: float) -> float:
        """The unit's position -> our angle [rad]."""
        return self.sign[axis] * (steps * self.res[axis] - self.zero[axis])

    @property
    def limits(self) -> PanTiltLimits:
        """Range [rad] and common speed bounds [rad/s] from the values read at connect."""
        if not self.res:
            raise ConnectionLost(f"PTU-D46 on {self.port} is not connected: call connect()")
        (p0, p1), (t0, t1) = (
            sorted((self.to_rad(ax, self.step_limits[ax][0]), self.to_rad(ax, self.step_limits[ax][1])))
            for ax in "PT"
        )
        lo = max(self.speed_bounds[ax][0] * self.res[ax] for ax in "PT")
        hi = min(self.speed_bounds[ax][1] * self.res[ax] for ax in "PT")
        return PanTiltLimits(p0, p1, t0, t1, max_speed=hi, min_speed=lo)

    def _check_target(self, axis: str, angle: float) -> int:
        steps = self.to_steps(axis, angle)
        lo, hi = self.step_limits[axis]
        if not lo <= steps <= hi:
            a, b = sorted((self.to_rad(axis, lo), self.to_rad(axis, hi)))
            name = "pan" if axis == "P" else "tilt"
            raise LimitError(
                f"{name} {math.degrees(angle):.2f} deg is outside the unit's limits "
                f"[{math.degrees(a):.2f}, {math.degrees(b):.2f}] deg (positions [{lo}, {hi}])"
            )
        return steps

    def _speed_steps(self, speed: float) -> dict[str, int]:
        lim = self.limits
        if not lim.min_speed - 1e-12 <= speed <= lim.max_speed + 1e-12:
            lim.check_speed(speed)  # raises LimitError with the range in deg/s
        out = {}
        for ax in "PT":
            lo, hi = self.speed_bounds[ax]
            out[ax] = min(max(int(round(speed / self.res[ax])), lo), hi)
        return out

    # --- motion ---------------------------------------------------------------------------------
    def set_pan_tilt(
        self,
        pan: float,
        tilt: float,
        speed: float | None = None,
        wait: bool = False,
        timeout: float | None = None,
    ) -> None:
        """Move to ``(pan, tilt)`` [rad] at ``speed`` [rad/s] (None: the default speed).

        Limits are checked before anything is sent (:class:`LimitError`). With ``wait=True`` the unit's
        ``A`` (await) command blocks until the move ends; its deadline is the travel time at the set speed
        plus ``move_margin_s`` (or ``timeout``). On expiry both axes are halted and DeviceTimeout raised.
        A ``!`` reply raises CommandRejected and leaves that axis's target unchanged.
        """
        check_finite(pan=pan, tilt=tilt, **({} if speed is None else {"speed": speed}))
        if timeout is not None:
            check_finite(timeout=timeout)
        self._check_link()
        p = self._check_target("P", float(pan))
        t = self._check_target("T", float(tilt))
        sp = self._speed_steps(float(self.default_speed if speed is None else speed))
        with self._lock:
            for ax in "PT":
                if sp[ax] != self.speed_steps.get(ax):
                    self._transact(f"{ax}S{sp[ax]}")
                    self.speed_steps[ax] = sp[ax]
            try:
                self._transact(f"PP{p}")
                self.target_steps["P"] = p
                self._transact(f"TP{t}")
                self.target_steps["T"] = t
            except (DeviceTimeout, ProtocolError):
                self._resync_after_failed_move()
                raise
            if wait:
                self.await_motion(timeout)

    def _resync_after_failed_move(self) -> None:
        """A move command failed even on its retry: the unit may or may not have taken it. Halt (best
        effort) and take the positions read back as the targets, so no stale target reads as motion."""
        try:
            self._transact("H", timeout=min(self.timeout_s, 1.0))
        except (DeviceTimeout, ProtocolError, CommandRejected, ConnectionLost):
            pass
        try:
            self.target_steps = self.get_steps()
        except (DeviceTimeout, ProtocolError, ConnectionLost):
            pass

    def _set_speed(self, speed: float) -> None:
        sp = self._speed_steps(speed)
        for ax in "PT":
            self._transact(f"{ax}S{sp[ax]}")
            self.speed_steps[ax] = sp[ax]

    def await_motion(self, timeout: float | None = None) -> None:
        """Block in ``A`` until both axes stop; halt and raise DeviceTimeout after the deadline."""
        with self._lock:
            if timeout is None:
                pos = self.get_steps()
                travel = max(
                    abs(self.target_steps[ax] - pos[ax]) / max(self.speed_steps.get(ax, 1), 1) for ax in "PT"
                )
                timeout = 1.5 * travel + self.move_margin_s
            try:
                try:
                    self._transact("A", timeout=timeout)
                except ProtocolError:  # garbled "*": asking again is harmless (it answers when still)
                    self.counters["retries"] += 1
                    self._transact("A", timeout=timeout)
            except DeviceTimeout as e:
                self.halt()
                raise DeviceTimeout(
                    f"PTU-D46 on {self.port} did not finish its move within {timeout:.2f} s; "
                    "both axes halted (blocked or stalled?)"
                ) from e

    def halt(self) -> None:
        """Stop both axes where they are (``H``); the targets become the current positions."""
        with self._lock:
            self._drain()
            self._transact("H", timeout=min(self.timeout_s, 1.0))
            try:
                self.target_steps = self.get_steps()
            except (DeviceTimeout, ProtocolError):
                pass

    def home(self, timeout: float = 30.0) -> None:
        """Reset (``R``): both axes run to their limits and back to 0 (its ``!T!T!P!P`` is expected)."""
        with self._lock:
            self._transact("R", timeout=timeout, expect_limit_hits=True)
            self.needs_home = False
            self.target_steps = self.get_steps()

    # --- state ----------------------------------------------------------------------------------
    def get_steps(self) -> dict[str, int]:
        with self._lock:
            return {ax: int(self._query_number(f"{ax}P")) for ax in "PT"}

    def get_pan_tilt(self) -> tuple[float, float]:
        """Current angles [rad] read from the unit."""
        s = self.get_steps()
        return self.to_rad("P", s["P"]), self.to_rad("T", s["T"])

    @property
    def targets(self) -> tuple[float, float]:
        return self.to_rad("P", self.target_steps["P"]), self.to_rad("T", self.target_steps["T"])

    def query(self, command: str) -> str:
        """Send an idempotent query (e.g. "V", "PP", "O") and return its value (retried once)."""
        return self._transact(command, retry=True)

    # --- transport ------------------------------------------------------------------------------
    def _check_link(self) -> None:
        if self.lost is not None:
            raise self.lost
        if self._ser is None:
            raise ConnectionLost(f"PTU-D46 on {self.port} is not connected: call connect()")

    def _query_number(self, command: str) -> float:
        return parse_number(self._transact(command, retry=True), self._terse)

    def _transact(
        self,
        command: str,
        timeout: float | None = None,
        *,
        retry: bool | None = None,
        expect_limit_hits: bool = False,
    ) -> str:
        """Write ``command`` and return the body of its ``*`` reply; ``!`` -> CommandRejected.

        ``retry`` (default: :func:`repeatable`) sends it once more after a timeout or a garbled reply."""
        timeout = self.timeout_s if timeout is None else timeout
        if retry is None:
            retry = repeatable(command)
        with self._lock:
            for attempt in (0, 1) if retry else (0,):
                try:
                    return self._transact_once(command, timeout, expect_limit_hits)
                except (DeviceTimeout, ProtocolError):
                    if attempt == 1 or not retry:
                        raise
                    self.counters["retries"] += 1
        raise AssertionError("unreachable")

    def _transact_once(self, command: str, timeout: float, expect_limit_hits: bool) -> str:
        self._check_link()
        self._drain()
        self._write((command + " ").encode("ascii"))
        deadline = time.monotonic() + timeout
        while True:
            line = self._read_line(deadline, command, timeout)
            try:
                reply = parse_reply(line, command)
            except ProtocolError:
                self.counters["protocol_errors"] += 1
                self._drain()
                raise
            if reply.limit_hits and not expect_limit_hits:
                self._record_limit_hits(reply.limit_hits)
            if reply.kind == "ok":
                return reply.body
            if reply.kind == "error":
                self.counters["rejected"] += 1
                raise CommandRejected(f"PTU-D46 refused {command!r}: {reply.body}")

    def _write(self, data: bytes) -> None:
        try:
            self._ser.write(data)
        except serial.SerialTimeoutException as e:
            raise DeviceTimeout(f"PTU-D46 on {self.port}: write timed out") from e
        except OSError as e:
            self._mark_lost(e)
            raise self.lost from e

    def _read_some(self) -> bytes:
        try:
            n = self._ser.in_waiting
            return self._ser.read(n if n else 1)
        except OSError as e:
            self._mark_lost(e)
            raise self.lost from e

    def _read_line(self, deadline: float, command: str, timeout: float) -> str:
        """The next non-empty line (CR or LF ends it) before ``deadline``; DeviceTimeout otherwise."""
        while True:
            while True:
                i = next((k for k, b in enumerate(self._rx) if b in (10, 13)), -1)
                if i < 0:
                    break
                raw = bytes(self._rx[:i])
                del self._rx[: i + 1]
                if raw.strip():
                    return raw.decode("latin-1")
            if time.monotonic() >= deadline:
                partial = bytes(self._rx)
                self._rx.clear()
                self.counters["timeouts"] += 1
                got = f" (got only {partial!r})" if partial else ""
                raise DeviceTimeout(
                    f"PTU-D46 on {self.port}: no reply to {command!r} within {timeout:.2f} s{got}; "
                    f"check power, cable, baudrate {self.baudrate} and unit id 0 (hardware/README.md)"
                )
            self._rx += self._read_some()

    def _drain(self) -> None:
        """Discard bytes that arrived outside a transaction, keeping any ``!P``/``!T`` they carry."""
        if self._ser is None:
            return
        try:
            n = self._ser.in_waiting
            data = bytes(self._rx) + (self._ser.read(n) if n else b"")
        except OSError as e:
            self._mark_lost(e)
            raise self.lost from e
        self._rx.clear()
        if data:
            text = data.decode("latin-1")
            hits = _ASYNC.findall(text)
            if hits:
                self._record_limit_hits(tuple(hits))
            self.counters["stray_bytes"] += len(_ASYNC.sub("", text).strip())

    def _record_limit_hits(self, hits: tuple[str, ...]) -> None:
        self.limit_hits += len(hits)
        self.needs_home = True
        for h in hits:
            if self.on_event is not None:
                try:
                    self.on_event("limit_hit", "pan" if h == "P" else "tilt")
                except Exception:
                    pass

    def _mark_lost(self, err: BaseException) -> None:
        if self.lost is None:
            self.lost = lost("PTU-D46", self.port, err, "the head stops at its last target")
            if self.on_event is not None:
                try:
                    self.on_event("connection_lost", str(self.lost))
                except Exception:
                    pass
