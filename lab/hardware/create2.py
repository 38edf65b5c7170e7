"""iRobot Create 2 driver: the Open Interface (OI), binary, 115200 8N1.

The protocol (iRobot, *Create 2 Open Interface (OI) Specification based on the iRobot Roomba 600*,
the public 2016/2018 editions):

* mode opcodes Start 128 (-> Passive), Safe 131, Full 132, Stop 173; leave >= 20 ms between them;
* Drive Direct 145: ``[145][right hi][right lo][left hi][left lo]``, big-endian int16 mm/s, **right wheel
  first**, +-500 mm/s (we clamp *before* packing, so an out-of-range float can never overflow int16);
* Stream 148 ``[148][n][id]...``: every 15 ms the robot sends ``[19][n][id][data]...[checksum]`` where the
  sum of all bytes, checksum included, is 0 mod 256;
* packets 43/44 are the left/right encoder counts, 16 bits, wrapping at 65535 <-> 0.

Threads: one background reader owns every read from the port; commands are write-only and take a write
lock (the reader also writes: a stop when the stream goes stale or a safety trip is seen).

Safety: in Safe mode the robot stops itself and falls back to Passive on a cliff while moving forward,
a wheel drop, or the charger. The driver notices (sensor bits or the OI-mode packet, including the
firmware's "mode 32" quirk), sends a zero Drive Direct, records the reason in :attr:`Create2.safety_trip`
and never re-enters Safe on its own: the user calls :meth:`Create2.enable` again.
"""

from __future__ import annotations

import math
import struct
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from enum import IntEnum

import serial

from lab.errors import ConnectionLost, DeviceTimeout, NotEnabled, SafetyStop
from lab.geometry import Pose2D, wrap_angle
from lab.hardware.serial_port import lost, open_port

__all__ = [
    "DEFAULT_STREAM",
    "HEADER",
    "PACKETS",
    "BaseSensors",
    "Create2",
    "DiffDriveOdometry",
    "EncoderUnwrapper",
    "OIMode",
    "Op",
    "StreamParser",
    "clamp_mm_s",
    "decode_frames",
    "drive_direct_bytes",
    "encode_stream_frame",
    "frame_checksum",
    "stream_request_bytes",
    "unwrap_delta",
]


class Op(IntEnum):
    """OI opcodes used here."""

    RESET = 7
    START = 128
    BAUD = 129
    SAFE = 131
    FULL = 132
    DRIVE = 137
    SENSORS = 142
    DRIVE_DIRECT = 145
    DRIVE_PWM = 146
    STREAM = 148
    QUERY_LIST = 149
    PAUSE_RESUME_STREAM = 150
    STOP = 173


class OIMode(IntEnum):
    """Packet 35. The firmware sometimes reports 32 after a Safe-mode trip (treated as Passive)."""

    OFF = 0
    PASSIVE = 1
    SAFE = 2
    FULL = 3


HEADER = 19  # first byte of every stream frame
MAX_MM_S = 500  # Drive Direct range
MODE_GAP_S = 0.02  # minimum time between mode-change commands (Hacking Roomba p.45)

#: packet id -> (name, data bytes, signed). Sizes and signedness from the OI spec / libcreate types.h.
PACKETS: dict[int, tuple[str, int, bool]] = {
    7: ("bumps_wheeldrops", 1, False),
    8: ("wall", 1, False),
    9: ("cliff_left", 1, False),
    10: ("cliff_front_left", 1, False),
    11: ("cliff_front_right", 1, False),
    12: ("cliff_right", 1, False),
    13: ("virtual_wall", 1, False),
    14: ("overcurrents", 1, False),
    15: ("dirt_detect", 1, False),
    17: ("ir_omni", 1, False),
    18: ("buttons", 1, False),
    19: ("distance", 2, True),
    20: ("angle", 2, True),
    21: ("charging_state", 1, False),
    22: ("voltage", 2, False),
    23: ("current", 2, True),
    24: ("temperature", 1, True),
    25: ("battery_charge", 2, False),
    26: ("battery_capacity", 2, False),
    27: ("wall_signal", 2, False),
    28: ("cliff_left_signal", 2, False),
    29: ("cliff_front_left_signal", 2, False),
    30: ("cliff_front_right_signal", 2, False),
    31: ("cliff_right_signal", 2, False),
    34: ("charging_sources", 1, False),
    35: ("oi_mode", 1, False),
    39: ("requested_velocity", 2, True),
    40: ("requested_radius", 2, True),
    41: ("requested_right_velocity", 2, True),
    42: ("requested_left_velocity", 2, True),
    43: ("left_encoder_counts", 2, False),
    44: ("right_encoder_counts", 2, False),
    45: ("light_bumper", 1, False),
}

#: what the driver streams: bumps/wheel drops, 4 cliffs, charging sources, battery, OI mode, encoders
DEFAULT_STREAM: tuple[int, ...] = (7, 9, 10, 11, 12, 25, 26, 34, 35, 43, 44)


# --- codec ------------------------------------------------------------------------------------------
def clamp_mm_s(v: float) -> int:
    """Round a wheel speed [mm/s] to an int within the Drive Direct range +-500 (NaN is refused)."""
    if not math.isfinite(v):
        raise ValueError(f"wheel speed must be finite, got {v!r}")
    return int(max(-MAX_MM_S, min(MAX_MM_S, round(v))))


def drive_direct_bytes(right_mm_s: float, left_mm_s: float) -> bytes:
    """``[145][R hi][R lo][L hi][L lo]``: right wheel first, big-endian int16, clamped to +-500 mm/s."""
    return struct.pack(">Bhh", Op.DRIVE_DIRECT, clamp_mm_s(right_mm_s), clamp_mm_s(left_mm_s))


def stream_request_bytes(ids: Sequence[int]) -> bytes:
    """``[148][n][id]...``: ask for a stream frame every 15 ms."""
    for i in ids:
        if i not in PACKETS:
            raise ValueError(f"unsupported sensor packet {i}; supported: {sorted(PACKETS)}")
    return bytes([Op.STREAM, len(ids), *ids])


def frame_checksum(frame_without_checksum: bytes) -> int:
    """The byte that makes the sum of the whole frame (header to checksum) 0 mod 256."""
    return (-sum(frame_without_checksum)) & 0xFF


def encode_stream_frame(values: dict[int, int], ids: Sequence[int] | None = None) -> bytes:
    """A stream frame ``[19][n][id][data]...[checksum]`` of packet values (for the emulator and tests)."""
    ids = list(values) if ids is None else list(ids)
    body = bytearray()
    for i in ids:
        _, size, signed = PACKETS[i]
        fmt = (">b" if signed else ">B") if size == 1 else (">h" if signed else ">H")
        body += bytes([i]) + struct.pack(fmt, int(values[i]))
    head = bytes([HEADER, len(body)]) + bytes(body)
    return head + bytes([frame_checksum(head)])


def _decode_body(body: bytes) -> dict[int, int] | None:
    """Packet values of a frame body ``[id][data]...``, or None when its structure is not valid."""
    out: dict[int, int] = {}
    k = 0
    while k < len(body):
        pid = body[k]
        spec = PACKETS.get(pid)
        if spec is None or k + 1 + spec[1] > len(body):
            return None
        _, size, signed = spec
        raw = body[k + 1 : k + 1 + size]
        if size == 1:
            out[pid] = struct.unpack(">b" if signed else ">B", raw)[0]
        else:
            out[pid] = struct.unpack(">h" if signed else ">H", raw)[0]
        k += 1 + size
    return out


class StreamParser:
    """Resynchronising parser of the OI stream: header 19 -> length -> body -> checksum.

    A candidate frame is accepted when its bytes sum to 0 mod 256, its body walks cleanly through known
    packet ids and sizes, and (when ``ids`` is given) it carries exactly the requested packets. Otherwise
    ``corrupt_frames`` is incremented, only the candidate's header byte is dropped, and the search resumes
    at the next 19: a real frame hidden behind garbage is never skipped.

    Parameters
    ----------
    ids : sequence of int, optional
        The requested packet ids, in order (a stronger check than the checksum alone).
    """

    def __init__(self, ids: Sequence[int] | None = None):
        self.ids = None if ids is None else tuple(ids)
        self._n = None if ids is None else sum(1 + PACKETS[i][1] for i in ids)
        self._buf = bytearray()
        self.frames = 0
        self.corrupt_frames = 0
        self.discarded_bytes = 0

    def reset(self) -> None:
        self._buf.clear()

    def feed(self, data: bytes) -> list[dict[int, int]]:
        """Add received bytes; return the packet values of every complete valid frame, in order."""
        self._buf += data
        out: list[dict[int, int]] = []
        buf = self._buf
        while True:
            start = buf.find(HEADER)
            if start < 0:
                self.discarded_bytes += len(buf)
                buf.clear()
                break
            if start:
                self.discarded_bytes += start
                del buf[:start]
            if len(buf) < 2:
                break
            n = buf[1]
            if n == 0 or (self._n is not None and n != self._n):
                self._reject(buf)
                continue
            if len(buf) < n + 3:
                break  # wait for the rest of the frame
            frame = bytes(buf[: n + 3])
            values = _decode_body(frame[2:-1]) if sum(frame) & 0xFF == 0 else None
            if values is None or (self.ids is not None and tuple(values) != self.ids):
                self._reject(buf)
                continue
            del buf[: n + 3]
            self.frames += 1
            out.append(values)
        return out

    def _reject(self, buf: bytearray) -> None:
        self.corrupt_frames += 1
        self.discarded_bytes += 1
        del buf[:1]


def unwrap_delta(old: int, new: int) -> int:
    """Signed change between two 16-bit encoder readings: ``((new - old + 32768) % 65536) - 32768``."""
    return ((int(new) - int(old) + 32768) % 65536) - 32768


class EncoderUnwrapper:
    """Turns a wrapping 16-bit count into an unbounded (Python int / int64) tick count."""

    def __init__(self):
        self._raw: int | None = None
        self.total = 0

    def rebase(self) -> None:
        """Forget the last raw reading (after a reconnect): the next one moves nothing."""
        self._raw = None

    def update(self, raw: int) -> int:
        """Feed a raw reading; return the change in ticks since the previous one."""
        d = 0 if self._raw is None else unwrap_delta(self._raw, raw)
        self._raw = int(raw) & 0xFFFF
        self.total += d
        return d


class DiffDriveOdometry:
    """Differential-drive dead reckoning from encoder ticks, exact for each constant-curvature step.

    ``ds = (dl + dr) / 2``, ``dtheta = (dr - dl) / wheel_base``, ``dl = ticks_l * pi * d / ticks_per_rev``;
    the robot moves the chord ``ds * sin(dtheta/2) / (dtheta/2)`` along the heading ``theta + dtheta/2``.
    Create 2: 508.8 ticks per revolution, 72 mm wheels, 235 mm axle.
    """

    def __init__(
        self, ticks_per_rev: float = 508.8, wheel_diameter: float = 0.072, wheel_base: float = 0.235
    ):
        self.m_per_tick = math.pi * wheel_diameter / ticks_per_rev
        self.wheel_base = wheel_base
        self.x = self.y = self.theta = 0.0

    def update(self, d_left_ticks: int, d_right_ticks: int) -> None:
        dl = d_left_ticks * self.m_per_tick
        dr = d_right_ticks * self.m_per_tick
        ds = 0.5 * (dl + dr)
        dth = (dr - dl) / self.wheel_base
        # exact for a constant-curvature step: the chord 2 R sin(dth/2) along the midpoint heading
        chord = ds if abs(dth) < 1e-9 else ds * math.sin(0.5 * dth) / (0.5 * dth)
        th_mid = self.theta + 0.5 * dth
        self.x += chord * math.cos(th_mid)
        self.y += chord * math.sin(th_mid)
        self.theta = wrap_angle(self.theta + dth)

    @property
    def pose(self) -> Pose2D:
        return Pose2D(self.x, self.y, self.theta)


# --- driver -----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class BaseSensors:
    """One decoded stream frame.

    Attributes
    ----------
    t : float [s]
        Host monotonic time when the frame arrived.
    cliff : tuple of 4 bool
        Left, front-left, front-right, right.
    oi_mode : int
        Packet 35 (0 off, 1 passive, 2 safe, 3 full; 32 seen after trips on some firmware).
    left_ticks, right_ticks : int
        Unwrapped encoder counts since connect.
    charging : bool
        A charger (home base or plug) is connected (packet 34).
    """

    t: float
    bump_left: bool
    bump_right: bool
    wheel_drop_left: bool
    wheel_drop_right: bool
    cliff: tuple[bool, bool, bool, bool]
    oi_mode: int
    left_ticks: int
    right_ticks: int
    charging: bool = False
    battery_charge_mah: int | None = None
    battery_capacity_mah: int | None = None


EventCallback = Callable[[str, str], None]


class Create2:
    """An iRobot Create 2 base on a serial port (see the module docstring for the protocol and threads).

    Parameters
    ----------
    port : str
        Device path or pyserial URL.
    baudrate : int
        115200 (the Create 2's default) or 19200.
    mode : {"safe", "full"}
        The mode :meth:`enable` enters. "full" turns off the robot's own cliff and wheel-drop stop.
    stale_timeout_s : float [s]
        Without a valid frame for this long the base is stopped and the stream re-requested.
    first_frame_timeout_s, connect_attempts :
        The handshake waits ``connect_attempts`` times for the first frame, re-requesting the stream.
    on_event : callable(kind, message), optional
        Called from the reader thread on "bump", "safety_stop", "stale", "stream_resumed", "connection_lost".

    Attributes
    ----------
    safety_trip : str or None
        Why the base stopped itself; cleared only by :meth:`enable`.
    lost : ConnectionLost or None
        Set when the port went away; every command then raises it until :meth:`reconnect`.
    """

    def __init__(
        self,
        port: str,
        *,
        baudrate: int = 115200,
        mode: str = "safe",
        stream_ids: Sequence[int] = DEFAULT_STREAM,
        stale_timeout_s: float = 0.1,
        first_frame_timeout_s: float = 0.5,
        connect_attempts: int = 10,
        max_wheel_speed: float = 0.5,
        ticks_per_rev: float = 508.8,
        wheel_diameter: float = 0.072,
        wheel_base: float = 0.235,
        on_event: EventCallback | None = None,
    ):
        if mode not in ("safe", "full"):
            raise ValueError(f"Create 2 mode must be 'safe' or 'full', got {mode!r}")
        self.port = port
        self.baudrate = baudrate
        self.mode = mode
        self.stream_ids = tuple(stream_ids)
        for i in (7, 9, 10, 11, 12, 35, 43, 44):
            if i not in self.stream_ids:
                raise ValueError(f"the stream must include packet {i} (safety and odometry need it)")
        self.stale_timeout_s = stale_timeout_s
        self.first_frame_timeout_s = first_frame_timeout_s
        self.connect_attempts = connect_attempts
        self.max_wheel_speed = max_wheel_speed
        self.on_event = on_event
        self.odom = DiffDriveOdometry(ticks_per_rev, wheel_diameter, wheel_base)
        self._left = EncoderUnwrapper()
        self._right = EncoderUnwrapper()
        self._ser: serial.SerialBase | None = None
        self._parser = StreamParser(self.stream_ids)
        self._wlock = threading.Lock()  # one writer at a time (user, watchdog, reader)
        self._cond = threading.Condition()  # guards the fields below; notified on every frame
        self._sensors: BaseSensors | None = None
        self._last_frame_t = -math.inf
        self._last_request_t = -math.inf
        self._last_mode_t = -math.inf
        self._stale = False
        self._stale_stop_pending = False
        self._enabled = False
        self._safe_confirmed = False
        self.safety_trip: str | None = None
        self.lost: ConnectionLost | None = None
        self._reader: threading.Thread | None = None
        self._stop_reader = threading.Event()
        self._last_sent = (0, 0)
        self.counters = {"stale_events": 0, "stream_requests": 0, "drive_commands": 0, "bytes_received": 0}

    # --- lifecycle ------------------------------------------------------------------------------
    @property
    def connected(self) -> bool:
        return self._ser is not None and self.lost is None

    @property
    def enabled(self) -> bool:
        return self._enabled and self.connected and self.safety_trip is None

    @property
    def stale(self) -> bool:
        return self._stale

    def connect(self) -> None:
        """Open the port, stop the wheels, Start (-> Passive), request the stream, wait for a first frame.

        Raises PortUnavailable (nothing sent) or DeviceTimeout (port closed again).
        """
        if self._ser is not None:
            return
        self._ser = open_port(self.port, self.baudrate, what="Create 2", config_key="[base] port")
        self.lost = None
        self._stale = False
        self._enabled = False
        self._safe_confirmed = False
        self._parser = StreamParser(self.stream_ids)
        self._left.rebase()
        self._right.rebase()
        with self._cond:
            self._sensors = None
        try:
            self._ser.reset_input_buffer()
            # stop first: a previous session may have left it driving in Safe/Full (never replay a velocity)
            self._write(drive_direct_bytes(0, 0))
            self._mode_command(Op.START)
            self._stop_reader.clear()
            self._reader = threading.Thread(
                target=self._read_loop, name=f"create2-reader {self.port}", daemon=True
            )
            self._reader.start()
            for _ in range(self.connect_attempts):
                self._request_stream()
                if self.wait_for_frame(self.first_frame_timeout_s) is not None:
                    self._last_sent = (0, 0)
                    return
                if self.lost is not None:
                    raise self.lost
            got = self.counters["bytes_received"]
            hint = (
                f"received {got} bytes but no valid frame: wrong baud rate? (Create 2: 115200, or 19200)"
                if got
                else "check that it is switched on (press Clean), the cable, and the port"
            )
            raise DeviceTimeout(
                f"Create 2 on {self.port}: no sensor stream within "
                f"{self.connect_attempts * self.first_frame_timeout_s:.1f} s; {hint}"
            )
        except BaseException:
            self._shutdown(send=False)
            raise

    def reconnect(self) -> None:
        """Close whatever is left and connect again; the base comes back disabled, standing still."""
        self._shutdown(send=self.connected)
        self.safety_trip = None
        self.connect()

    def close(self) -> None:
        """Drive Direct 0 -> Start -> Stop (as libcreate does), then release the port. Safe to call twice."""
        self._shutdown(send=True)

    def _shutdown(self, send: bool) -> None:
        ser = self._ser
        if ser is None:
            return
        self._enabled = False  # first: Start drops the OI to Passive, which must not read as a trip
        self._safe_confirmed = False
        if send and self.lost is None:
            try:
                self._write(drive_direct_bytes(0, 0))
                self._mode_command(Op.START)
                self._mode_command(Op.STOP)
            except (ConnectionLost, DeviceTimeout):
                pass
        self._stop_reader.set()
        if self._reader is not None and self._reader is not threading.current_thread():
            self._reader.join(timeout=1.0)
        self._reader = None
        try:
            ser.close()
        except OSError:
            pass
        self._ser = None

    # --- modes ----------------------------------------------------------------------------------
    def enable(self, timeout: float = 0.5) -> None:
        """Enter Safe (or Full, if configured) and wait until the stream confirms it.

        Raises SafetyStop when a cliff or wheel drop is reported right now (put the robot on the floor),
        DeviceTimeout when the robot does not confirm the mode.
        """
        self._check_link()
        s = self.wait_for_frame(timeout)  # a frame from now, not one from before the robot was put down
        if s is None:
            self._check_link()
            raise DeviceTimeout(f"no sensor stream from the Create 2 on {self.port} within {timeout:.1f} s")
        if s.wheel_drop_left or s.wheel_drop_right or any(s.cliff):
            raise SafetyStop(f"cannot enable the Create 2: {self._hazard(s)}; put it on the floor first")
        self.safety_trip = None
        self._safe_confirmed = False
        want = OIMode.SAFE if self.mode == "safe" else OIMode.FULL
        self._write(drive_direct_bytes(0, 0))
        self._last_sent = (0, 0)
        self._mode_command(Op.SAFE if want == OIMode.SAFE else Op.FULL)
        t_end = time.monotonic() + timeout
        with self._cond:
            while True:
                s = self._sensors
                if s is not None and s.oi_mode == want:
                    break
                if self.lost is not None:
                    raise self.lost
                left = t_end - time.monotonic()
                if left <= 0:
                    mode = "none" if s is None else s.oi_mode
                    raise DeviceTimeout(
                        f"Create 2 on {self.port} did not enter {want.name} mode within {timeout:.1f} s "
                        f"(OI mode {mode}); is it on the charger?"
                    )
                self._cond.wait(left)
            self._safe_confirmed = True
            self._enabled = True

    def disable(self) -> None:
        """Zero the wheels and go back to Passive (Start)."""
        self._enabled = False
        self._safe_confirmed = False
        if self.connected:
            self._write(drive_direct_bytes(0, 0))
            self._last_sent = (0, 0)
            self._mode_command(Op.START)

    # --- motion ---------------------------------------------------------------------------------
    def drive_direct(self, right_mm_s: float, left_mm_s: float) -> tuple[int, int]:
        """Send wheel speeds [mm/s] (clamped to +-500, right first); returns what was sent (right, left)."""
        self._check_link()
        if self.safety_trip is not None:
            raise SafetyStop(f"Create 2 safety stop ({self.safety_trip}): call enable() to re-arm")
        if not self._enabled:
            raise NotEnabled("Create 2 is not enabled: call enable() first")
        if self._stale:
            raise DeviceTimeout(f"no sensor stream from the Create 2 on {self.port}: base stopped")
        r, l = clamp_mm_s(right_mm_s), clamp_mm_s(left_mm_s)
        self._write(struct.pack(">Bhh", Op.DRIVE_DIRECT, r, l))
        self._last_sent = (r, l)
        self.counters["drive_commands"] += 1
        return r, l

    def set_wheel_speeds(self, left: float, right: float) -> tuple[float, float]:
        """Wheel speeds [m/s]; returns the (left, right) speeds actually sent after clamping."""
        r, l = self.drive_direct(right * 1000.0, left * 1000.0)
        return l / 1000.0, r / 1000.0

    def stop(self) -> None:
        """Zero the wheels now (allowed in any state while the port is up; never raises on a trip)."""
        if self.connected:
            self._write(drive_direct_bytes(0, 0))
            self._last_sent = (0, 0)

    @property
    def last_sent_mm_s(self) -> tuple[int, int]:
        """The last (right, left) Drive Direct values written."""
        return self._last_sent

    # --- sensing --------------------------------------------------------------------------------
    def sensors(self) -> BaseSensors | None:
        with self._cond:
            return self._sensors

    def odometry(self) -> Pose2D:
        with self._cond:
            return self.odom.pose

    def wait_for_frame(self, timeout: float, after: float | None = None) -> BaseSensors | None:
        """The first frame received after ``after`` (default: now), or None after ``timeout`` [s]."""
        after = time.monotonic() if after is None else after
        t_end = time.monotonic() + timeout
        with self._cond:
            while self._sensors is None or self._sensors.t <= after:
                left = t_end - time.monotonic()
                if left <= 0 or self.lost is not None:
                    return None
                self._cond.wait(left)
            return self._sensors

    @property
    def corrupt_frames(self) -> int:
        return self._parser.corrupt_frames

    @property
    def frames(self) -> int:
        return self._parser.frames

    # --- internals ------------------------------------------------------------------------------
    def _check_link(self) -> None:
        if self.lost is not None:
            raise self.lost
        if self._ser is None:
            raise ConnectionLost(f"Create 2 on {self.port} is not connected: call connect()")

    def _write(self, data: bytes) -> None:
        with self._wlock:
            if self.lost is not None:
                raise self.lost
            ser = self._ser
            if ser is None:
                raise ConnectionLost(f"Create 2 on {self.port} is not connected: call connect()")
            try:
                ser.write(data)
            except serial.SerialTimeoutException as e:
                raise DeviceTimeout(f"Create 2 on {self.port}: write timed out (flow control?)") from e
            except OSError as e:
                self._mark_lost(e)
                raise self.lost from e

    def _mode_command(self, op: int) -> None:
        wait = self._last_mode_t + MODE_GAP_S - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        self._write(bytes([op]))
        self._last_mode_t = time.monotonic()

    def _request_stream(self) -> None:
        self._write(stream_request_bytes(self.stream_ids))
        self._last_request_t = time.monotonic()
        self.counters["stream_requests"] += 1

    def _mark_lost(self, err: BaseException) -> None:
        with self._cond:
            if self.lost is None:
                self.lost = lost("Create 2", self.port, err)
                self._enabled = False
            self._cond.notify_all()
        self._emit("connection_lost", str(self.lost))

    def _emit(self, kind: str, message: str) -> None:
        if self.on_event is not None:
            try:
                self.on_event(kind, message)
            except Exception:  # a user callback must never kill the reader thread
                pass

    def _read_loop(self) -> None:
        ser = self._ser
        while not self._stop_reader.is_set():
            try:
                n = ser.in_waiting
                data = ser.read(n if n else 1)
            except OSError as e:  # SerialException, and plain EIO from in_waiting
                if not self._stop_reader.is_set():
                    self._mark_lost(e)
                return
            except (TypeError, AttributeError):  # port closed under us during shutdown
                return
            now = time.monotonic()
            if data:
                self.counters["bytes_received"] += len(data)
                for values in self._parser.feed(data):
                    self._on_frame(values, now)
            try:
                self._check_stale(now)
            except ConnectionLost:
                return  # _write has recorded it
            except DeviceTimeout:
                pass  # a write timed out: keep reading, the stale check runs again next slice

    def _check_stale(self, now: float) -> None:
        if self._sensors is None or now - self._last_frame_t <= self.stale_timeout_s:
            return
        if not self._stale:
            self._stale = True
            self._stale_stop_pending = True
            self.counters["stale_events"] += 1
            self._emit("stale", f"no valid frame from the Create 2 for {now - self._last_frame_t:.2f} s")
        if (
            self._stale_stop_pending
        ):  # no sensor stream = no cliff detection: stop the wheels (until it worked)
            self.stop()
            self._stale_stop_pending = False
        if now - self._last_request_t > self.stale_timeout_s:
            self._request_stream()

    @staticmethod
    def _hazard(s: BaseSensors) -> str:
        names = ("left", "front-left", "front-right", "right")
        parts = []
        if s.wheel_drop_left or s.wheel_drop_right:
            parts.append("wheel drop")
        if any(s.cliff):
            parts.append("cliff " + "+".join(n for n, c in zip(names, s.cliff, strict=True) if c))
        if s.charging:
            parts.append("charger connected")
        return ", ".join(parts)

    def _on_frame(self, v: dict[int, int], now: float) -> None:
        bw = v[7]
        with self._cond:
            dl = self._left.update(v[43])
            dr = self._right.update(v[44])
            self.odom.update(dl, dr)
            prev = self._sensors
            s = BaseSensors(
                t=now,
                bump_right=bool(bw & 1),
                bump_left=bool(bw & 2),
                wheel_drop_right=bool(bw & 4),
                wheel_drop_left=bool(bw & 8),
                cliff=(bool(v[9]), bool(v[10]), bool(v[11]), bool(v[12])),
                oi_mode=v[35],
                left_ticks=self._left.total,
                right_ticks=self._right.total,
                charging=bool(v.get(34, 0)),
                battery_charge_mah=v.get(25),
                battery_capacity_mah=v.get(26),
            )
            self._sensors = s
            self._last_frame_t = now
            was_stale, self._stale = self._stale, False
            self._cond.notify_all()
        if was_stale:
            self._emit("stream_resumed", "sensor stream from the Create 2 is back")
        if (s.bump_left or s.bump_right) and not (prev and (prev.bump_left or prev.bump_right)):
            self._emit("bump", "left" if s.bump_left else "right")
        if self._enabled and self.safety_trip is None:
            reason = self._hazard(s)
            if not reason and self._safe_confirmed and s.oi_mode not in (OIMode.SAFE, OIMode.FULL):
                reason = f"the robot left {self.mode} mode by itself (OI mode {s.oi_mode})"
            if reason:
                self.safety_trip = reason
                self._enabled = False
                try:
                    self.stop()
                except (ConnectionLost, DeviceTimeout):
                    pass
                self._emit("safety_stop", reason)


def decode_frames(data: bytes, ids: Iterable[int] | None = None) -> list[dict[int, int]]:
    """Decode every valid frame in a byte string (convenience for tests and traces)."""
    return StreamParser(None if ids is None else tuple(ids)).feed(data)
