"""Protocol codecs without I/O: Create 2 framing, checksum, resync, encoder unwrap, odometry; PTU replies.

Peers: the OI spec's byte layout written out by hand (struct), closed-form arc geometry for odometry,
and the manual's reply strings.
"""

import math
import struct

import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from lab.errors import ProtocolError
from lab.hardware.odometry import DiffDriveOdometry, EncoderUnwrapper, unwrap_delta
from lab.hardware.open_interface import (
    DEFAULT_STREAM,
    PACKETS,
    StreamParser,
    clamp_mm_s,
    drive_direct_bytes,
    encode_stream_frame,
    stream_request_bytes,
)
from lab.hardware.ptu import parse_number, parse_reply


def _packet_value(pid):
    _, size, signed = PACKETS[pid]
    bits = 8 * size
    lo, hi = (-(2 ** (bits - 1)), 2 ** (bits - 1) - 1) if signed else (0, 2**bits - 1)
    return st.integers(lo, hi)


stream_values = st.fixed_dictionaries({i: _packet_value(i) for i in DEFAULT_STREAM})


# --- Create 2: framing and checksum --------------------------------------------------------------
def test_frame_layout_matches_the_oi_spec_example():
    # OI spec: a stream of packets 29 (2 bytes) and 13 (1 byte) is [19][5][29][hi][lo][13][v][checksum];
    # n counts the ids and the data between itself and the checksum
    f = encode_stream_frame({29: 0x0219, 13: 0}, [29, 13])
    assert f[:7] == bytes([19, 5, 29, 0x02, 0x19, 13, 0])
    assert sum(f) % 256 == 0


@settings(max_examples=200, deadline=None)
@given(stream_values)
def test_frame_round_trip_and_checksum(values):
    f = encode_stream_frame(values, DEFAULT_STREAM)
    assert f[0] == 19 and f[1] == len(f) - 3
    assert sum(f) % 256 == 0  # the OI rule: all bytes including the checksum sum to 0 mod 256
    p = StreamParser(DEFAULT_STREAM)
    assert p.feed(f) == [values]
    assert p.corrupt_frames == 0


@settings(max_examples=200, deadline=None)
@given(stream_values, st.integers(0, 1000), st.integers(1, 255))
def test_any_single_byte_error_is_rejected(values, pos, flip):
    f = bytearray(encode_stream_frame(values, DEFAULT_STREAM))
    f[pos % len(f)] ^= flip
    p = StreamParser(DEFAULT_STREAM)
    assert p.feed(bytes(f)) == []


@settings(max_examples=150, deadline=None)
@given(
    st.lists(st.tuples(st.binary(max_size=40), stream_values), min_size=1, max_size=6),
    st.lists(st.integers(1, 30), min_size=1, max_size=20),
)
def test_parser_resyncs_after_garbage_in_any_chunking(parts, cuts):
    """Garbage (with header bytes 19) before frames, fed in any chunks: every real frame comes out."""
    stream = b""
    frames = []
    for garbage, values in parts:
        stream += garbage + encode_stream_frame(values, DEFAULT_STREAM)
        frames.append(values)
    p = StreamParser(DEFAULT_STREAM)
    got, k, i = [], 0, 0
    while k < len(stream):
        n = cuts[i % len(cuts)]
        got += p.feed(stream[k : k + n])
        k += n
        i += 1
    assert got == frames
    if any(19 in g for g, _ in parts):
        assert p.corrupt_frames + p.discarded_bytes > 0


def test_bad_checksum_and_truncated_frames_are_counted_and_skipped():
    v = {i: 0 for i in DEFAULT_STREAM}
    good = encode_stream_frame(v, DEFAULT_STREAM)
    bad = bytearray(good)
    bad[-1] ^= 0x5A
    p = StreamParser(DEFAULT_STREAM)
    out = p.feed(bytes(bad) + good[:9] + good + good)
    assert out == [v, v]
    assert p.corrupt_frames >= 2


# --- Create 2: commands --------------------------------------------------------------------------
def test_drive_direct_is_right_wheel_first_big_endian():
    assert drive_direct_bytes(-200, 300) == bytes([145, 0xFF, 0x38, 0x01, 0x2C])


@settings(max_examples=300, deadline=None)
@given(st.floats(-1e6, 1e6), st.floats(-1e6, 1e6))
def test_drive_direct_clamps_before_packing(r, l):
    op, rr, ll = struct.unpack(">Bhh", drive_direct_bytes(r, l))
    assert op == 145
    assert rr == max(-500, min(500, round(r))) and ll == max(-500, min(500, round(l)))


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_wheel_speed_is_refused(bad):
    with pytest.raises(ValueError):
        clamp_mm_s(bad)


def test_stream_request():
    assert stream_request_bytes([7, 43, 44]) == bytes([148, 3, 7, 43, 44])
    with pytest.raises(ValueError, match="unsupported"):
        stream_request_bytes([200])


# --- encoders and odometry ------------------------------------------------------------------------
def test_unwrap_across_the_boundary_both_directions():
    assert unwrap_delta(65530, 5) == 11  # forward across 65535 -> 0
    assert unwrap_delta(5, 65530) == -11  # backward across 0 -> 65535
    assert unwrap_delta(100, 100) == 0
    assert unwrap_delta(0, 32767) == 32767 and unwrap_delta(0, 32768) == -32768


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 65535), st.lists(st.integers(-32767, 32767), max_size=50))
def test_unwrapper_recovers_the_true_count(start, steps):
    u = EncoderUnwrapper()
    u.update(start)
    true = 0
    for d in steps:
        true += d
        u.update((start + true) % 65536)
    assert u.total == true


def test_odometry_straight_and_spin():
    o = DiffDriveOdometry()
    o.update(5088, 5088)  # ten wheel turns
    assert o.x == pytest.approx(10 * math.pi * 0.072) and abs(o.y) < 1e-12 and o.theta == 0.0
    o = DiffDriveOdometry()
    n = 200
    for _ in range(n):
        o.update(-1, 1)
    assert o.theta == pytest.approx(2 * n * o.m_per_tick / 0.235)
    assert abs(o.x) < 1e-12 and abs(o.y) < 1e-12


@settings(max_examples=100, deadline=None)
@given(st.integers(-20, 20), st.integers(-20, 20), st.integers(1, 200))
def test_odometry_matches_the_exact_arc(dl, dr, n):
    """Constant wheel increments trace a circle: compare with the closed-form chord."""
    o = DiffDriveOdometry()
    for _ in range(n):
        o.update(dl, dr)
    m = o.m_per_tick
    ds, dth = 0.5 * (dl + dr) * m * n, (dr - dl) * m / 0.235 * n
    assume(abs(dth) < math.pi)
    if abs(dth) < 1e-12:
        x, y = ds, 0.0
    else:
        R = ds / dth
        x, y = R * math.sin(dth), R * (1 - math.cos(dth))
    assert o.x == pytest.approx(x, abs=1e-9) and o.y == pytest.approx(y, abs=1e-9)
    assert o.theta == pytest.approx(dth, abs=1e-12)


# --- PTU reply grammar ------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "line, cmd, kind, body, hits",
    [
        ("*", "PP100", "ok", "", ()),
        ("* 22", "PP", "ok", "22", ()),
        ("PP * 22", "PP", "ok", "22", ()),  # echo on: the command comes back first
        ("pp * 22", "PP", "ok", "22", ()),  # case-insensitive
        (
            "PP3200 ! Maximum allowable Pan position is 3090",
            "PP3200",
            "error",
            "Maximum allowable Pan position is 3090",
            (),
        ),
        ("!P* 100", "PP", "ok", "100", ("P",)),
        ("* !T100", "TP", "ok", "100", ("T",)),
        ("!T!T!P!P*", "R", "ok", "", ("T", "T", "P", "P")),  # reset reply
        ("!P", "PP", "none", "", ("P",)),  # an asynchronous limit hit on its own line
        ("PP", "PP", "none", "", ()),  # echo on its own line (CR delimiter)
        (
            "! Pan speed cannot exceed 2902 positions/sec",
            "PS3300",
            "error",
            "Pan speed cannot exceed 2902 positions/sec",
            (),
        ),
        ("* Current Pan position is -5", "PP", "ok", "Current Pan position is -5", ()),
    ],
)
def test_reply_grammar(line, cmd, kind, body, hits):
    r = parse_reply(line, cmd)
    assert (r.kind, r.body, r.limit_hits) == (kind, body, hits)


@pytest.mark.parametrize("line", ["#@\x8f* 100", "1234", "\xa4 100", "Current Pan"])
def test_garbage_reply_is_a_protocol_error(line):
    with pytest.raises(ProtocolError):
        parse_reply(line, "PP")


def test_numbers_are_never_invented():
    assert parse_number("-3090") == -3090
    assert parse_number("185.1428") == 185.1428
    assert parse_number("Minimum Pan position is -3090", terse=False) == -3090
    assert parse_number("185.1428 seconds arc per Pan position", terse=False) == 185.1428
    for body in ("", "1x2", "Current Pan position is 5"):  # empty is not 0 (flir_ptu's bug)
        with pytest.raises(ProtocolError):
            parse_number(body, terse=True)


@settings(max_examples=300, deadline=None)
@given(
    st.integers(-5000, 5000),
    st.booleans(),
    st.lists(st.sampled_from(["P", "T"]), max_size=3),
    st.integers(0, 2),
)
def test_reply_grammar_property(value, echo, hits, where):
    """Any value, with or without echo, with !P/!T inserted at a token boundary, parses back exactly."""
    cmd = "TP"
    tokens = "".join(f"!{h}" for h in hits)
    parts = ["*", f" {value}"]
    parts.insert(where, tokens)
    line = ("TP " if echo else "") + "".join(parts)
    r = parse_reply(line, cmd)
    assert r.kind == "ok" and parse_number(r.body) == value
    assert sorted(r.limit_hits) == sorted(hits)
