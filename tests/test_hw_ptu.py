"""PTU-D46 driver against the PTU emulator on a pty (real pyserial I/O).

The emulator starts in the unit's factory state (echo on, verbose feedback), so connect() has to cope with
both; what the driver knows about the unit (resolution, limits, speed bounds) must come from the unit.
"""

import math
import socket
import threading
import time

import pytest
import serial
from hw_helpers import wait_until

from lab.errors import CommandRejected, ConnectionLost, DeviceTimeout, LimitError, ProtocolError
from lab.hardware.emulators import PTUEmulator
from lab.hardware.ptu import ARCSEC, PTUD46
from lab.hardware.serial_port import PortUnavailable

TIMEOUT = 0.2


@pytest.fixture
def emu(tmp_path):
    e = PTUEmulator(tmp_path / "ttyPTU").start()
    yield e
    e.close()


@pytest.fixture
def ptu(emu):
    events = []
    p = PTUD46(emu.port, banner_wait_s=0.0, timeout_s=TIMEOUT, on_event=lambda k, m: events.append((k, m)))
    p.events = events
    p.connect()
    yield p
    p.close()


def _motion_commands(emu):
    return [c for c in emu.command_names() if c[:2].upper() in ("PP", "TP", "PS", "TS") and len(c) > 2]


def test_connect_reads_everything_from_the_unit(tmp_path):
    # a unit unlike the defaults: D300-like resolution, other limits and speed bounds
    e = PTUEmulator(
        tmp_path / "u",
        resolution_arcsec=92.5714,
        pan_limits=(-5000, 4000),
        tilt_limits=(-1500, 900),
        speed_bounds=(50, 4000),
    ).start()
    try:
        assert e.echo and e.verbose  # factory state
        p = PTUD46(e.port, banner_wait_s=0.0, timeout_s=TIMEOUT)
        p.connect()
        assert not e.echo and not e.verbose  # ED and FT were sent
        assert e.control == "CI" and e.exec_mode == "I" and e.limits_enforced
        assert p.res["P"] == pytest.approx(92.5714 * ARCSEC)
        lim = p.limits
        assert lim.pan_min == pytest.approx(-5000 * 92.5714 * ARCSEC)
        assert lim.pan_max == pytest.approx(4000 * 92.5714 * ARCSEC)
        assert lim.tilt_min == pytest.approx(-1500 * 92.5714 * ARCSEC)
        assert lim.min_speed == pytest.approx(50 * 92.5714 * ARCSEC)
        assert lim.max_speed == pytest.approx(4000 * 92.5714 * ARCSEC)
        assert "v2.14" in p.version
        p.close()
    finally:
        e.close()


def test_banner_and_leftovers_at_connect(tmp_path):
    e = PTUEmulator(tmp_path / "u", banner=True).start()
    try:
        e.inject(b"PP * Current pan position is 0\r\n!P")  # a previous session's leftovers
        p = PTUD46(e.port, banner_wait_s=0.05, timeout_s=TIMEOUT)
        p.connect()
        assert p.get_pan_tilt() == (0.0, 0.0)
        p.close()
        p.connect()  # init is idempotent
        p.close()
    finally:
        e.close()


def test_move_with_sign_and_zero_offset(tmp_path):
    e = PTUEmulator(tmp_path / "u").start()
    try:
        p = PTUD46(
            e.port,
            banner_wait_s=0.0,
            timeout_s=TIMEOUT,
            pan_sign=-1,
            tilt_sign=1,
            pan_zero_offset=math.radians(2.0),
            tilt_zero_offset=math.radians(-1.0),
        )
        p.connect()
        p.set_pan_tilt(math.radians(10.0), math.radians(5.0), wait=True)
        res = 185.1428 / 3600.0  # deg per position
        steps = e.position_steps()
        assert steps["P"] == round((-10.0 + 2.0) / res)  # the unit turned the other way, from its own zero
        assert steps["T"] == round((5.0 - 1.0) / res)
        pan, tilt = p.get_pan_tilt()
        assert math.degrees(pan) == pytest.approx(10.0, abs=res) and math.degrees(tilt) == pytest.approx(
            5.0, abs=res
        )
        p.close()
    finally:
        e.close()


def test_limits_and_speeds_are_checked_before_sending(ptu, emu):
    before = len(emu.commands)
    lim = ptu.limits
    for pan, tilt in ((lim.pan_max + 0.01, 0.0), (0.0, lim.tilt_min - 0.01)):
        with pytest.raises(LimitError, match="outside the unit's limits"):
            ptu.set_pan_tilt(pan, tilt)
    for speed in (lim.max_speed * 1.1, lim.min_speed * 0.5):
        with pytest.raises(LimitError, match="deg/s"):
            ptu.set_pan_tilt(0.1, 0.0, speed=speed)
    for bad in (math.nan, math.inf):
        with pytest.raises(ValueError):
            ptu.set_pan_tilt(bad, 0.0)
    with pytest.raises(TypeError):
        ptu.set_pan_tilt("0.1", 0.0)
    time.sleep(0.02)
    assert len(emu.commands) == before  # the unit saw nothing


def test_rejected_command_keeps_the_target(ptu, emu):
    ptu.set_pan_tilt(math.radians(5), 0.0, wait=True)
    emu.lim["P"] = (-1000, 1000)  # the unit's limits changed behind our back (e.g. user limits)
    with pytest.raises(CommandRejected, match="Maximum allowable Pan position is 1000"):
        ptu.set_pan_tilt(math.radians(100), 0.0)
    assert ptu.counters["rejected"] == 1
    assert math.degrees(ptu.targets[0]) == pytest.approx(5.0, abs=0.06)
    assert math.degrees(ptu.get_pan_tilt()[0]) == pytest.approx(5.0, abs=0.06)


def test_waited_move_takes_distance_over_speed(ptu, emu):
    speed = math.radians(50.0)
    t0 = time.monotonic()
    ptu.set_pan_tilt(math.radians(20.0), 0.0, speed=speed, wait=True)
    dt = time.monotonic() - t0
    # not before the move could have ended, and back when the unit says it arrived: at the target, one 'A'
    # (the upper bound is the driver's own deadline, distance / speed + margin: past it, it raises; a
    # loaded machine answers late, so a tighter wall-clock window only measures the load)
    assert 20.0 / 50.0 - 0.02 <= dt < 20.0 / 50.0 + ptu.move_margin_s
    assert emu.position_steps()["P"] == ptu.to_steps("P", math.radians(20.0))
    assert emu.command_names().count("A") == 1


def test_stalled_move_times_out_and_halts(ptu, emu):
    emu.stall = True
    ptu.move_margin_s = 0.3
    speed = math.radians(60.0)
    t0 = time.monotonic()
    with pytest.raises(DeviceTimeout, match="halted"):
        ptu.set_pan_tilt(math.radians(12.0), 0.0, speed=speed, wait=True)
    dt = time.monotonic() - t0
    expected = 1.5 * 12.0 / 60.0 + ptu.move_margin_s  # travel time scaled + margin
    assert expected - 0.02 <= dt <= expected + 2.0  # not before its deadline; late only by the load
    assert "H" in emu.command_names()[emu.command_names().index("A") :]
    emu.stall = False
    assert ptu.get_pan_tilt() == (0.0, 0.0)  # in sync afterwards


def test_async_limit_hits_are_stripped_and_reported(ptu, emu):
    ptu.set_pan_tilt(math.radians(3.0), 0.0, wait=True)
    emu.limit_hit("P")  # arrives between transactions
    time.sleep(0.02)
    pan, _ = ptu.get_pan_tilt()
    assert math.degrees(pan) == pytest.approx(3.0, abs=0.06)
    emu.delay_s = 0.01
    emu.limit_hit("T")  # mixed into the next reply's line
    pan, _ = ptu.get_pan_tilt()
    assert math.degrees(pan) == pytest.approx(3.0, abs=0.06)
    assert ptu.limit_hits == 2 and ptu.needs_home
    assert [k for k, _ in ptu.events] == ["limit_hit", "limit_hit"]
    ptu.home(timeout=2.0)  # the reset's own !T!T!P!P is expected, not a limit hit
    assert ptu.limit_hits == 2 and not ptu.needs_home
    assert ptu.get_pan_tilt() == (0.0, 0.0)


@pytest.mark.parametrize("fault", ["garbage_next", "corrupt_next", "truncate_next", "drop_next"])
def test_bad_reply_is_retried_once_for_queries(ptu, emu, fault):
    ptu.set_pan_tilt(math.radians(4.0), 0.0, wait=True)
    setattr(emu, fault, 1)
    t0 = time.monotonic()
    pan, _ = ptu.get_pan_tilt()
    assert math.degrees(pan) == pytest.approx(4.0, abs=0.06)
    # one retry, not more: the retry count says so; the time only shows it did not hang (a loaded
    # machine answers late, so a tight wall-clock bound would measure the load)
    assert time.monotonic() - t0 < 2 * TIMEOUT + 2.0
    assert ptu.counters["retries"] == 1
    if fault in ("garbage_next", "corrupt_next"):
        assert ptu.counters["protocol_errors"] == 1
    else:
        assert ptu.counters["timeouts"] == 1


def test_repeated_bad_replies_raise(ptu, emu):
    emu.garbage_next = 5
    with pytest.raises(ProtocolError, match="unexpected reply"):
        ptu.get_pan_tilt()
    assert ptu.counters["protocol_errors"] == 2  # the query and its one retry


def test_silent_unit_times_out_in_bounded_time(emu):
    emu.silent = True
    p = PTUD46(emu.port, banner_wait_s=0.0, timeout_s=TIMEOUT)
    t0 = time.monotonic()
    with pytest.raises(DeviceTimeout, match="no reply to 'ED'.*unit id"):
        p.connect()
    assert time.monotonic() - t0 < 2 * TIMEOUT + 2.0  # one try and one retry, with room for a loaded machine
    assert not p.connected
    emu.silent = False
    p.connect()  # the port was released
    p.close()


def test_unit_with_nonzero_id_is_silent_until_selected(emu):
    emu.unit_id = 3
    emu._selected = False
    p = PTUD46(emu.port, banner_wait_s=0.0, timeout_s=TIMEOUT)
    with pytest.raises(DeviceTimeout):
        p.connect()
    with serial.Serial(emu.port, timeout=0.2) as s:  # the documented recovery string
        s.write(b" _0 u0 DS ")
        time.sleep(0.05)
    p.connect()
    p.close()


def test_unplug_and_reconnect(ptu, emu):
    ptu.set_pan_tilt(math.radians(2.0), 0.0, wait=True)
    emu.unplug()
    with pytest.raises(ConnectionLost, match="went away.*reconnect"):
        ptu.get_pan_tilt()
    n = len(emu.rx_log)
    with pytest.raises(ConnectionLost):
        ptu.set_pan_tilt(0.0, 0.0)  # refused at once, nothing written
    assert len(emu.rx_log) == n and ("connection_lost", str(ptu.lost)) in ptu.events
    emu.replug()
    ptu.reconnect()
    assert math.degrees(ptu.get_pan_tilt()[0]) == pytest.approx(2.0, abs=0.06)  # the unit kept its pose


def test_missing_and_busy_ports(emu, tmp_path):
    with pytest.raises(PortUnavailable, match=r"port .*nope not found \(available ports"):
        PTUD46(str(tmp_path / "nope")).connect()
    a = PTUD46(emu.port, banner_wait_s=0.0, timeout_s=TIMEOUT)
    a.connect()
    with pytest.raises(PortUnavailable, match="in use"):
        PTUD46(emu.port, banner_wait_s=0.0).connect()
    a.close()


def test_socket_url(emu):
    """serial_for_url: a networked unit (socket://host:port) works like a serial one."""
    srv = socket.create_server(("127.0.0.1", 0))
    port = srv.getsockname()[1]
    stop = threading.Event()

    def bridge():
        conn, _ = srv.accept()
        conn.settimeout(0.01)
        with conn, serial.Serial(emu.port, timeout=0.01) as s:
            while not stop.is_set():
                try:
                    d = conn.recv(4096)
                    if not d:
                        return
                    s.write(d)
                except TimeoutError:
                    pass
                d = s.read(s.in_waiting or 1)
                if d:
                    conn.sendall(d)

    t = threading.Thread(target=bridge, daemon=True)
    t.start()
    try:
        p = PTUD46(f"socket://127.0.0.1:{port}", banner_wait_s=0.0, timeout_s=0.5)
        p.connect()
        p.set_pan_tilt(math.radians(-3.0), math.radians(1.0), wait=True)
        assert wait_until(lambda: emu.position_steps()["P"] == round(-3.0 * 3600 / 185.1428), 1.0)
        p.close()
    finally:
        stop.set()
        t.join(1.0)
        srv.close()


def test_threads_share_the_port_without_mixing_replies(ptu, emu):
    """One lock per port: concurrent queries and moves never read each other's replies."""
    errors, results = [], []

    def poll():
        try:
            for _ in range(15):
                s = ptu.get_steps()
                results.append(s)
        except Exception as e:  # any failure is a test failure
            errors.append(e)

    threads = [threading.Thread(target=poll) for _ in range(4)]
    for t in threads:
        t.start()
    for deg in (3.0, -3.0, 1.0):
        ptu.set_pan_tilt(math.radians(deg), math.radians(deg / 2), wait=True)
    for t in threads:
        t.join(5.0)
    assert not errors and len(results) == 60
    lo, hi = ptu.step_limits["P"]
    assert all(lo <= r["P"] <= hi and abs(r["T"]) <= 60 for r in results)
    assert ptu.counters["protocol_errors"] == 0 and ptu.counters["retries"] == 0
    assert math.degrees(ptu.get_pan_tilt()[0]) == pytest.approx(1.0, abs=0.06)


def test_garbage_before_every_third_reply_connects_and_moves(emu):
    """Stray bytes before every third reply (a noisy line): the absolute commands are retried once like the
    queries, so connect() and the moves succeed and the head ends where it was sent."""
    emu.garbage_every = 3
    p = PTUD46(emu.port, banner_wait_s=0.0, timeout_s=TIMEOUT)
    p.connect()
    try:
        for pan_deg, tilt_deg in ((10.0, -5.0), (-20.0, 8.0), (3.0, 0.0)):
            p.set_pan_tilt(math.radians(pan_deg), math.radians(tilt_deg), wait=True)
            assert p.counters["protocol_errors"] > 0
            steps = emu.position_steps()
            assert p.to_rad("P", steps["P"]) == pytest.approx(math.radians(pan_deg), abs=math.radians(0.06))
            assert p.to_rad("T", steps["T"]) == pytest.approx(math.radians(tilt_deg), abs=math.radians(0.06))
            assert (p.target_steps["P"], p.target_steps["T"]) == (steps["P"], steps["T"])
        assert p.counters["retries"] >= p.counters["protocol_errors"] > 0
    finally:
        p.close()


def test_garbled_move_reply_is_retried_once(ptu, emu):
    emu.garbage_next = 1
    ptu.set_pan_tilt(math.radians(6.0), 0.0, wait=True)
    assert ptu.counters["retries"] == 1 and ptu.counters["protocol_errors"] == 1
    assert math.degrees(ptu.targets[0]) == pytest.approx(6.0, abs=0.06)
    assert math.degrees(ptu.to_rad("P", emu.position_steps()["P"])) == pytest.approx(6.0, abs=0.06)


def test_failed_move_re_reads_the_position_as_the_target(ptu, emu):
    """PP garbled on its try and its retry: the unit may have taken it. The driver halts the head and takes
    the position it reads back as the target, so the state never reports motion towards a stale target."""
    ptu.set_pan_tilt(math.radians(2.0), 0.0, wait=True)
    emu.garbage_next = 2
    with pytest.raises(ProtocolError, match="unexpected reply"):
        ptu.set_pan_tilt(math.radians(30.0), 0.0)
    time.sleep(0.1)
    steps = ptu.get_steps()
    assert ptu.target_steps == steps == emu.position_steps()
