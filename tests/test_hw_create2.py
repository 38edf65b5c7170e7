"""Create 2 driver against the Create 2 emulator on a pty (real pyserial I/O).

Ground truth comes from the emulator: the wheel speeds it runs, the opcodes it received (with its clock),
and its true pose.
"""

import math
import struct
import time

import pytest
from hw_helpers import wait_until

from lab.errors import ConnectionLost, DeviceTimeout, NotEnabled, SafetyStop
from lab.hardware.create2 import Create2
from lab.hardware.emulators import Create2Emulator


@pytest.fixture
def emu(tmp_path):
    e = Create2Emulator(tmp_path / "ttyCreate").start()
    yield e
    e.close()


def _frames_after_the_stop(b: Create2) -> None:
    """Wait for two stream frames received after now (the emulator has already stopped its wheels)."""
    for _ in range(2):
        assert b.wait_for_frame(timeout=2.0) is not None


def _make(port, **kw):
    events = []
    b = Create2(port, on_event=lambda k, m: events.append((k, m)), **kw)
    b.events = events
    return b


@pytest.fixture
def base(emu):
    b = _make(emu.port)
    b.connect()
    yield b
    b.close()


def test_connect_starts_and_streams(base, emu):
    names = emu.opcode_names()
    assert names[:3] == ["DRIVE_DIRECT", "START", "STREAM"]  # stop first, then Start, then the stream
    assert emu.mode == 1 and base.sensors().oi_mode == 1
    assert not base.enabled
    with pytest.raises(NotEnabled):
        base.drive_direct(100, 100)


def test_enable_is_confirmed_and_drive_direct_is_right_first(base, emu):
    base.enable()
    assert emu.mode == 2 and base.enabled
    base.drive_direct(right_mm_s=120, left_mm_s=-80)
    assert wait_until(lambda: emu.wheel_speeds() == (120, -80), 2.0)
    base.set_wheel_speeds(left=2.0, right=-3.0)  # beyond +-0.5 m/s: clamped before packing
    assert wait_until(lambda: emu.wheel_speeds() == (-500, 500), 2.0)
    d = emu.drives()[-1]
    assert (d.right, d.left) == (-500, 500)  # the bytes on the wire were in range


def test_odometry_across_encoder_wrap_matches_the_true_pose(tmp_path):
    # left starts just below 65535 and drives forward, right starts just above 0 and drives backward
    e = Create2Emulator(tmp_path / "c", encoder_start=(65400, 30)).start()
    b = _make(e.port)
    try:
        b.connect()
        b.enable()
        b.drive_direct(right_mm_s=-60, left_mm_s=200)
        # driven until both counters wrapped: waited for, not timed (a loaded machine runs the emulator
        # late; a starved host may even see the stream go stale, and the driver then stops: drive on)
        t_end = time.monotonic() + 10.0
        while not (e.encoder_counts()[0] < 65400 and e.encoder_counts()[1] > 30 and abs(e.theta) > 0.4):
            assert time.monotonic() < t_end, "the encoders did not wrap (or it did not turn) within 10 s"
            if e.wheel_speeds() == (0, 0) and not b.stale:
                b.drive_direct(right_mm_s=-60, left_mm_s=200)
            time.sleep(0.01)
        b.stop()
        assert wait_until(lambda: e.wheel_speeds() == (0, 0), 2.0)
        _frames_after_the_stop(b)
        left, right = e.encoder_counts()
        assert left < 65400 and right > 30  # both wrapped (forward and backward)
        s = b.sensors()
        assert s.left_ticks > 0 and s.right_ticks < 0
        o = b.odometry()
        # encoder quantisation (0.44 mm per tick) is the only difference from the emulator's true pose
        assert o.x == pytest.approx(e.x, abs=0.003) and o.y == pytest.approx(e.y, abs=0.003)
        assert o.theta == pytest.approx(e.theta, abs=0.01)
        assert abs(e.theta) > 0.3
    finally:
        b.close()
        e.close()


def test_garbage_and_bad_checksums_are_counted_without_false_alarms(base, emu):
    base.enable()
    base.drive_direct(100, 100)
    n0, c0 = base.frames, base.corrupt_frames
    # one fault after the other, each waited for until the emulator has sent it (two faults in one frame
    # would count as one corrupt frame)
    emu.garbage_before_next = bytes([19, 24, 1, 2, 3, 19, 200, 0xFF, 19])
    assert wait_until(lambda: emu.garbage_before_next == b"", 2.0)
    emu.bad_checksum_next = 3
    assert wait_until(lambda: emu.bad_checksum_next == 0, 2.0)
    emu.truncate_next = 2
    assert wait_until(lambda: emu.truncate_next == 0, 2.0)
    emu.inject(bytes(range(256)))  # every byte value, including 19, on the wire
    # each bad frame counted, and the good ones keep coming (waited for, not timed: a loaded CI machine
    # delivers the 15 ms stream late)
    assert wait_until(lambda: base.corrupt_frames - c0 >= 3 + 2, 2.0)
    assert wait_until(lambda: base.frames - n0 >= 8, 2.0)
    assert base.safety_trip is None and not base.stale and base.enabled
    assert base.sensors().oi_mode == 2 and not any(base.sensors().cliff)
    base.stop()


def test_stale_stream_stops_the_base_and_rerequests(base, emu):
    base.enable()
    base.drive_direct(150, 150)
    assert wait_until(lambda: emu.wheel_speeds() == (150, 150), 2.0)
    requests0 = emu.opcode_names().count("STREAM")
    emu.mute_stream = True
    t_mute = emu.now()
    assert wait_until(lambda: base.stale, 2.0)
    assert wait_until(lambda: emu.wheel_speeds() == (0, 0), 2.0)
    stop = emu.first_zero_drive_after(t_mute)
    # stale_timeout 0.1 s after the last frame (one period before the mute at most) + a read slice
    assert stop is not None and 0.08 <= stop.t - t_mute <= 0.2
    with pytest.raises(DeviceTimeout, match="no sensor stream"):
        base.drive_direct(100, 100)
    assert wait_until(lambda: emu.opcode_names().count("STREAM") >= requests0 + 2, 2.0)  # re-requested
    emu.mute_stream = False
    assert wait_until(lambda: not base.stale, 2.0)
    assert [k for k, _ in base.events][-2:] == ["stale", "stream_resumed"]
    base.drive_direct(50, 50)  # driving is allowed again once the stream is back
    assert wait_until(lambda: emu.wheel_speeds() == (50, 50), 2.0)


@pytest.mark.parametrize("quirk", [False, True])
def test_cliff_trip_in_safe_mode_is_reported_and_not_rearmed(tmp_path, quirk):
    e = Create2Emulator(tmp_path / "c", mode32_quirk=quirk).start()
    b = _make(e.port)
    try:
        b.connect()
        b.enable()
        b.drive_direct(200, 200)
        assert wait_until(lambda: e.wheel_speeds() == (200, 200), 2.0)
        e.max_lateness_s = 0.0
        t_cliff = e.now()
        e.cliff(1)  # front-left cliff while moving forward: the robot stops itself, Passive
        assert wait_until(lambda: b.safety_trip is not None, 2.0)
        assert e.wheel_speeds() == (0, 0) and e.trips and e.trips[0][1] == "cliff"
        assert e.trips[0][0] - t_cliff < 0.02 + 2 * e.max_lateness_s  # its next tick, however late it ran
        assert "cliff front-left" in b.safety_trip and not b.enabled
        assert wait_until(lambda: ("safety_stop", b.safety_trip) in b.events, 2.0)
        with pytest.raises(SafetyStop, match="enable"):
            b.drive_direct(100, 100)
        time.sleep(0.2)
        assert "SAFE" not in e.opcode_names(since=t_cliff)  # never re-armed by the driver
        assert e.mode == 1 and b.sensors().oi_mode == (32 if quirk else 1)
        with pytest.raises(SafetyStop, match="cliff"):
            b.enable()  # the hazard is still there
        e.cliff(1, on=False)
        time.sleep(0.05)
        b.enable()
        b.drive_direct(50, 50)
        assert wait_until(lambda: e.wheel_speeds() == (50, 50), 2.0)
    finally:
        b.close()
        e.close()


def test_wheel_drop_trips_even_standing_still(base, emu):
    base.enable()
    emu.wheel_drop()
    assert wait_until(lambda: base.safety_trip == "wheel drop", 2.0)
    assert emu.mode == 1


def test_silent_robot_times_out_in_bounded_time(emu):
    emu.silent = True
    b = _make(emu.port, first_frame_timeout_s=0.1, connect_attempts=3)
    t0 = time.monotonic()
    with pytest.raises(DeviceTimeout, match="no sensor stream within 0.3 s; check that it is switched on"):
        b.connect()
    assert time.monotonic() - t0 < 0.3 + 2.0  # three attempts of 0.1 s; it gives up rather than hangs
    assert emu.rx_bytes.count(bytes([148])) >= 3  # the stream was re-requested on each attempt
    assert not b.connected


def test_wrong_baud_rate_is_named(emu):
    emu.baud_mismatch = True
    emu.stream_ids, emu.mode = (7, 35), 1  # it streams, but at the wrong rate the bytes are garbage
    b = _make(emu.port, first_frame_timeout_s=0.1, connect_attempts=2)
    with pytest.raises(DeviceTimeout, match="no valid frame: wrong baud rate"):
        b.connect()


def test_unplug_while_driving(base, emu):
    base.enable()
    base.drive_direct(200, 200)
    assert wait_until(lambda: emu.wheel_speeds() == (200, 200), 2.0)
    t0 = time.monotonic()
    emu.unplug()
    assert wait_until(lambda: base.lost is not None, 2.0)
    detect = time.monotonic() - t0
    assert detect < 0.1
    assert ("connection_lost", str(base.lost)) in base.events
    with pytest.raises(ConnectionLost, match="went away.*reconnect"):
        base.drive_direct(100, 100)
    assert emu.wheel_speeds() == (200, 200)  # the real OI has no link watchdog: it keeps driving
    emu.replug()
    t_replug = emu.now()
    base.reconnect()
    # stop first, never replay the last velocity; then Start (Passive) and the stream
    # the emulator may still be working through the bytes (it streams on from before the unplug)
    assert wait_until(lambda: len(emu.opcode_names(since=t_replug)) >= 3, 2.0)
    assert emu.opcode_names(since=t_replug)[:3] == ["DRIVE_DIRECT", "START", "STREAM"]
    first = [d for d in emu.drives() if d.t >= t_replug][0]
    assert (first.right, first.left, first.accepted) == (0, 0, True)
    assert emu.wheel_speeds() == (0, 0) and not base.enabled


def test_close_sequence_and_twice(base, emu):
    base.enable()
    base.drive_direct(100, 100)
    assert wait_until(lambda: emu.wheel_speeds() == (100, 100), 2.0)
    t = emu.now()
    base.close()
    base.close()
    assert wait_until(lambda: "STOP" in emu.opcode_names(since=t), 2.0)
    assert emu.opcode_names(since=t) == ["DRIVE_DIRECT", "START", "STOP"]
    assert (emu.drives()[-1].right, emu.drives()[-1].left) == (0, 0) and emu.mode == 0
    with pytest.raises(ConnectionLost, match="not connected"):
        base.drive_direct(1, 1)


def test_drive_opcode_bytes_on_the_wire(base, emu):
    base.enable()
    emu.clear_log()
    base.drive_direct(-200, 300)
    assert wait_until(lambda: len(emu.rx_bytes) >= 5, 2.0)
    assert emu.rx_bytes[:5] == struct.pack(">Bhh", 145, -200, 300)


def test_odometry_sign_conventions(base, emu):
    base.enable()
    base.drive_direct(right_mm_s=100, left_mm_s=-100)  # right forward, left back: counter-clockwise
    assert wait_until(lambda: emu.theta > 0.15, 5.0)
    base.stop()
    assert wait_until(lambda: emu.wheel_speeds() == (0, 0), 2.0)
    _frames_after_the_stop(base)
    assert base.odometry().theta == pytest.approx(emu.theta, abs=0.01) and emu.theta > 0.15
    assert math.hypot(base.odometry().x, base.odometry().y) < 0.002


def test_a_stream_without_the_optional_packets_falls_back_to_the_required_set(emu):
    """A firmware (or emulator) that streams only the packets it knows sends valid frames of another
    length: bring-up asks again for the required set, and safety and odometry work on it."""
    from lab.hardware.open_interface import DEFAULT_STREAM, REQUIRED_STREAM

    emu.known_packets = set(REQUIRED_STREAM)
    b = _make(emu.port, first_frame_timeout_s=0.25, connect_attempts=4)
    b.connect()
    try:
        assert b.stream_ids == REQUIRED_STREAM and b.requested_stream_ids == DEFAULT_STREAM
        assert any(k == "stream_fallback" for k, _ in b.events)
        s = b.sensors()
        assert s.battery_charge_mah is None and not s.charging and s.oi_mode == 1
        b.enable()
        b.drive_direct(100, 100)
        assert wait_until(lambda: emu.wheel_speeds() == (100, 100), 2.0)
        x0 = b.odometry().x
        time.sleep(0.3)
        assert b.odometry().x - x0 > 0.01  # odometry from the fallback stream's encoders
        emu.cliff(1)
        assert wait_until(lambda: b.safety_trip is not None, 2.0)
        assert "cliff" in b.safety_trip and emu.wheel_speeds() == (0, 0)
    finally:
        b.close()


def test_frames_of_another_packet_set_are_named_in_the_error(emu):
    """Frames that check out but lack a required packet: the error names the packets, not the baud rate."""
    emu.known_packets = {7, 9, 10, 11, 12, 43, 44}  # no OI mode (35)
    b = _make(emu.port, first_frame_timeout_s=0.2, connect_attempts=3)
    with pytest.raises(
        DeviceTimeout, match=r"frames check out but carry packets \[7, 9, 10, 11, 12, 43, 44\], not"
    ):
        b.connect()
    assert not b.connected
