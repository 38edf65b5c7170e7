"""The iRobot Create 2's Open Interface (OI): opcodes, sensor packets, and the byte codec (no I/O).

The protocol (iRobot, *Create 2 Open Interface (OI) Specification based on the iRobot Roomba 600*, the
public 2016/2018 editions), binary, 115200 8N1:

* mode opcodes Start 128 (-> Passive), Safe 131, Full 132, Stop 173; leave >= 20 ms between them;
* Drive Direct 145: ``[145][right hi][right lo][left hi][left lo]``, big-endian int16 mm/s, **right wheel
  first**, +-500 mm/s (we clamp *before* packing, so an out-of-range float can never overflow int16);
* Stream 148 ``[148][n][id]...``: every 15 ms the robot sends ``[19][n][id][data]...[checksum]`` where the
  sum of all bytes, checksum included, is 0 mod 256;
* packets 43/44 are the left/right encoder counts, 16 bits, wrapping at 65535 <-> 0
  (:mod:`lab.hardware.odometry` unwraps them).

The driver (:mod:`lab.hardware.create2`) and the emulator (:mod:`lab.hardware.emulators.create2`) both
speak through this module.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Iterable, Sequence
from enum import IntEnum

__all__ = [
    "DEFAULT_STREAM",
    "HEADER",
    "MAX_MM_S",
    "MODE_GAP_S",
    "PACKETS",
    "OIMode",
    "Op",
    "StreamParser",
    "clamp_mm_s",
    "decode_frames",
    "drive_direct_bytes",
    "encode_stream_frame",
    "frame_checksum",
    "stream_request_bytes",
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
#: what safety and odometry need (bumps/wheel drops, cliffs, OI mode, encoders): the fallback stream
REQUIRED_STREAM: tuple[int, ...] = (7, 9, 10, 11, 12, 35, 43, 44)


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
        self.foreign_frames = 0  # frames that check out (checksum, packet ids) but carry other packets
        self.foreign_ids: tuple[int, ...] | None = None  # the packets the last such frame carried

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
            if n == 0:
                self._reject(buf)
                continue
            if self._n is not None and n != self._n:
                if len(buf) >= n + 3 and self._foreign(bytes(buf[: n + 3])):
                    del buf[: n + 3]
                    continue
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

    def _foreign(self, frame: bytes) -> bool:
        """A whole frame of another length that checks out: the device streams another packet set."""
        values = _decode_body(frame[2:-1]) if sum(frame) & 0xFF == 0 else None
        if not values:
            return False
        self.foreign_frames += 1
        self.foreign_ids = tuple(values)
        return True

    def _reject(self, buf: bytearray) -> None:
        self.corrupt_frames += 1
        self.discarded_bytes += 1
        del buf[:1]


def decode_frames(data: bytes, ids: Iterable[int] | None = None) -> list[dict[int, int]]:
    """Decode every valid frame in a byte string (convenience for tests and traces)."""
    return StreamParser(None if ids is None else tuple(ids)).feed(data)
