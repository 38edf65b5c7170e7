"""An iRobot Create 2 emulator: the Open Interface (binary) with kinematics, encoders and a sensor stream.

The Create integrates its wheel speeds (an exact arc per tick), streams a frame every 15 ms and its
16-bit encoders wrap. Fault switches (thread-safe, besides those of
:class:`~lab.hardware.emulators.pty_device.PtyDevice`): ``mute_stream``, ``bad_checksum_next``,
``truncate_next``, ``garbage_before_next``, ``baud_mismatch``, ``mode32_quirk``,
``keeps_driving_when_unplugged``, and the world hooks :meth:`Create2Emulator.cliff`,
:meth:`~Create2Emulator.wheel_drop`, :meth:`~Create2Emulator.bump`, :meth:`~Create2Emulator.charger`.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

from lab.hardware.emulators.pty_device import PtyDevice
from lab.hardware.open_interface import PACKETS, OIMode, Op, encode_stream_frame

__all__ = ["Create2Emulator", "DriveRecord"]

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
        self.known_packets: set[int] | None = None  # a firmware that streams only these (None: all)
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

    def true_pose(self) -> tuple[float, float, float]:
        """The base's true pose (x [m], y [m], theta [rad]) in its start frame, read under the lock."""
        with self._lock:
            return self.x, self.y, self.theta

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
            return [_op_name(o) for t, o, _ in self.opcodes if t >= since]

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
            known = PACKETS if self.known_packets is None else self.known_packets
            self.stream_ids = tuple(i for i in ids if i in PACKETS and i in known)
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


def _op_name(o: int) -> str:
    """An opcode's name (``"DRIVE_DIRECT"``), or its number for one :class:`Op` does not name."""
    try:
        return Op(o).name
    except ValueError:
        return str(o)
