"""iRobot Create 2 driver: the Open Interface over a serial port, with a reader thread, odometry and safety.

The bytes on the wire are :mod:`lab.hardware.open_interface`'s (opcodes, Drive Direct, the sensor
stream and its resynchronising parser); the pose comes from :mod:`lab.hardware.odometry`.

Threads: one background reader owns every read from the port; commands are write-only and take a write
lock (the reader also writes: a stop when the stream goes stale or a safety trip is seen).

Safety: in Safe mode the robot stops itself and falls back to Passive on a cliff while moving forward,
a wheel drop, or the charger. The driver notices (sensor bits or the OI-mode packet, including the
firmware's "mode 32" quirk), sends a zero Drive Direct, records the reason in :attr:`Create2.safety_trip`
and never re-enters Safe on its own: the user calls :meth:`Create2.enable` again.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import serial

from lab.errors import ConnectionLost, DeviceTimeout, NotEnabled, SafetyStop
from lab.geometry import Pose2D
from lab.hardware.config import BaseConfig, HardwareConfig
from lab.hardware.odometry import DiffDriveOdometry, EncoderUnwrapper
from lab.hardware.open_interface import (
    DEFAULT_STREAM,
    MODE_GAP_S,
    REQUIRED_STREAM,
    OIMode,
    Op,
    StreamParser,
    clamp_mm_s,
    drive_direct_bytes,
    stream_request_bytes,
)
from lab.hardware.serial_port import lost, open_port

__all__ = ["BaseSensors", "Create2"]


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
        for i in REQUIRED_STREAM:
            if i not in self.stream_ids:
                raise ValueError(f"the stream must include packet {i} (safety and odometry need it)")
        self.requested_stream_ids = self.stream_ids
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
        self.bump_count = 0  # bumper presses (rising edges of packet 7's bump bits) since construction
        self.lost: ConnectionLost | None = None
        self._reader: threading.Thread | None = None
        self._stop_reader = threading.Event()
        self._last_sent = (0, 0)
        self.counters = {"stale_events": 0, "stream_requests": 0, "drive_commands": 0, "bytes_received": 0}

    @classmethod
    def from_config(
        cls, config: BaseConfig | HardwareConfig, *, on_event: EventCallback | None = None
    ) -> Create2:
        """The driver a ``[base]`` section describes: the one place that maps its keys onto parameters.

        Parameters
        ----------
        config : BaseConfig or HardwareConfig
            The ``[base]`` section, or a whole config (its ``base`` is used).
        on_event : callable(kind, message), optional
            As for the constructor.
        """
        b = config.base if isinstance(config, HardwareConfig) else config
        return cls(
            b.port,
            baudrate=b.baudrate,
            mode=b.mode,
            stream_ids=b.stream_packets,
            stale_timeout_s=b.stale_timeout_s,
            first_frame_timeout_s=b.first_frame_timeout_s,
            connect_attempts=b.connect_attempts,
            max_wheel_speed=b.max_speed,
            ticks_per_rev=b.ticks_per_rev,
            wheel_diameter=b.wheel_diameter,
            wheel_base=b.wheel_base,
            on_event=on_event,
        )

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
        self.stream_ids = self.requested_stream_ids
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
                if self._parser.foreign_frames and self.stream_ids != REQUIRED_STREAM:
                    # valid frames of another packet set: a device that streams only the packets it knows
                    self._emit(
                        "stream_fallback",
                        f"the Create 2 streams packets {list(self._parser.foreign_ids or ())} instead of "
                        f"{list(self.stream_ids)}; asking for the required set {list(REQUIRED_STREAM)}",
                    )
                    self.stream_ids = REQUIRED_STREAM
                    self._parser = StreamParser(self.stream_ids)
            got = self.counters["bytes_received"]
            if self._parser.foreign_frames:
                hint = (
                    f"its frames check out but carry packets {list(self._parser.foreign_ids or ())}, "
                    f"not the requested {list(self.stream_ids)} (set [base] stream_packets to packets "
                    f"it streams, including {list(REQUIRED_STREAM)})"
                )
            elif got:
                hint = (
                    f"received {got} bytes but no valid frame: wrong baud rate? (Create 2: 115200, or 19200)"
                )
            else:
                hint = "check that it is switched on (press Clean), the cable, and the port"
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
            raise SafetyStop(f"cannot enable the Create 2: {self.hazard(s)}; put it on the floor first")
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
        self._write(drive_direct_bytes(r, l))
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
                self.lost = lost(
                    "Create 2",
                    self.port,
                    err,
                    "it can no longer be told to stop and keeps its last wheel speeds "
                    "(the Open Interface has no link watchdog): press its power button",
                )
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
    def hazard(s: BaseSensors) -> str:
        """What keeps the base from driving in sensor frame ``s`` (wheel drop, cliff, charger), or ``""``."""
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
            self.bump_count += 1
            self._emit("bump", "left" if s.bump_left else "right")
        if self._enabled and self.safety_trip is None:
            reason = self.hazard(s)
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
