"""The emulators themselves, seen by a plain pyserial client: shutdown, unplug, and protocol details."""

import errno
import math
import os
import struct
import threading
import time

import pytest
import serial
from hw_helpers import wait_until

from lab.hardware.emulators import Create2Emulator, PTUEmulator, start_emulators
from lab.hardware.open_interface import StreamParser


def _ask(s, cmd: bytes) -> bytes:
    """Send a command and read its reply up to the line end (bounded by the port's timeout)."""
    s.reset_input_buffer()
    s.write(cmd)
    return s.read_until(b"\r\n", 200)


def test_close_never_hangs_with_a_client_blocked_in_read(tmp_path):
    e = PTUEmulator(tmp_path / "p").start()
    s = serial.Serial(e.port, timeout=5.0)
    errors = []

    def reader():
        try:
            s.read(100)  # blocks: the device says nothing
        except serial.SerialException as err:
            errors.append(err)

    t = threading.Thread(target=reader, daemon=True)
    t.start()
    time.sleep(0.05)
    t0 = time.monotonic()
    e.close()
    e.close()  # twice is fine
    assert time.monotonic() - t0 < 2.0  # close does not wait for the blocked reader
    t.join(2.0)
    assert not t.is_alive() and errors  # the client saw the device go away
    s.close()


def test_unplug_and_replug_as_pyserial_sees_it(tmp_path):
    e = Create2Emulator(tmp_path / "c").start()
    try:
        s = serial.Serial(e.port, timeout=0.2)
        e.unplug()
        assert not os.path.lexists(e.port)
        with pytest.raises(OSError):  # SerialException (an OSError) or plain EIO from in_waiting
            s.read(s.in_waiting or 1)
        with pytest.raises(serial.SerialException) as ex:
            serial.Serial(e.port)
        assert ex.value.errno == errno.ENOENT
        s.close()
        e.replug()
        with serial.Serial(e.port, timeout=0.2) as s2:  # same path, fresh pty
            s2.write(bytes([128]))
            assert wait_until(lambda: e.mode == 1, 2.0)
    finally:
        e.close()


def test_ptu_factory_replies_match_the_manual(tmp_path):
    e = PTUEmulator(tmp_path / "p").start()
    try:
        with serial.Serial(e.port, timeout=2.0) as s:
            assert _ask(s, b"PP ") == b"PP * Current Pan position is 0\r\n"  # echo on, verbose
            assert _ask(s, b"PP3200 ") == b"PP3200 ! Maximum allowable Pan position is 3090\r\n"
            assert _ask(s, b"PS3300 ") == b"PS3300 ! Pan speed cannot exceed 2902 positions/sec\r\n"
            assert _ask(s, b"ED ") == b"ED *\r\n"
            assert _ask(s, b"FT ") == b"*\r\n"
            assert _ask(s, b"TX ") == b"* 604\r\n"
            assert _ask(s, b"PR ") == b"* 185.1428\r\n"
            assert _ask(s, b"XYZ ") == b"! Illegal Command\r\n"
            assert _ask(s, b"R ") == b"!T!T!P!P*\r\n"
    finally:
        e.close()


def test_ptu_moves_at_its_speed_on_its_clock(tmp_path):
    e = PTUEmulator(tmp_path / "p", speed=1000).start()
    try:
        with serial.Serial(e.port, timeout=1.0) as s:
            assert _ask(s, b"ED ") == b"ED *\r\n" and _ask(s, b"FT ") == b"*\r\n"
            t0 = time.monotonic()
            s.write(b"PP500 A ")
            line = s.read_until(b"*\r\n*\r\n", 100)
            assert line.endswith(b"*\r\n*\r\n")  # PP's '*', then A's '*' when the move ended
            # 500 steps at 1000 steps/s: not before 0.5 s; later only by how late the machine runs it
            assert 0.45 <= time.monotonic() - t0 < 2.0
    finally:
        e.close()


def test_create_modes_passive_ignores_drive(tmp_path):
    e = Create2Emulator(tmp_path / "c").start()
    try:
        with serial.Serial(e.port, timeout=0.2) as s:
            s.write(struct.pack(">Bhh", 145, 100, 100))  # before Start: ignored, not even logged as a drive
            s.write(bytes([128]) + struct.pack(">Bhh", 145, 100, 100))  # Passive: logged, not accepted
            assert wait_until(lambda: len(e.drives()) == 1, 2.0)
            assert not e.drives()[0].accepted and e.wheel_speeds() == (0, 0)
            time.sleep(0.02)
            s.write(bytes([131]) + struct.pack(">Bhh", 137, 200, -32768))  # Safe, Drive straight 200 mm/s
            assert wait_until(lambda: e.wheel_speeds() == (200, 200), 2.0)
            s.write(struct.pack(">Bhh", 137, 100, 1))  # turn in place counter-clockwise
            assert wait_until(lambda: e.wheel_speeds() == (100, -100), 2.0)
            s.reset_input_buffer()
            s.write(bytes([142, 35]))  # Sensors: OI mode, one data byte, no header
            assert s.read(1) == bytes([2])
    finally:
        e.close()


def test_create_streams_every_15_ms_and_encoders_wrap(tmp_path):
    e = Create2Emulator(tmp_path / "c", encoder_start=(65530, 3)).start()
    try:
        with serial.Serial(e.port, timeout=0.2) as s:
            e.max_lateness_s = 0.0
            t0 = time.monotonic()
            s.write(bytes([128, 131]) + bytes([148, 2, 43, 44]) + struct.pack(">Bhh", 145, -100, 100))
            time.sleep(0.3)
            s.write(struct.pack(">Bhh", 145, 0, 0))
            time.sleep(0.05)
            frames = StreamParser((43, 44)).feed(s.read(s.in_waiting))
            elapsed = time.monotonic() - t0  # 0.35 s, or longer when the machine is busy
            # one frame per 15 ms; a thread the machine ran late skips the frames it missed (as a UART's
            # would be lost), so the lower bound gives up those the measured lateness can explain
            missed = math.ceil(2 * e.max_lateness_s / Create2Emulator.STREAM_PERIOD_S)
            assert 18 - missed <= len(frames) <= elapsed / Create2Emulator.STREAM_PERIOD_S + 1
            lefts = [f[43] for f in frames]
            rights = [f[44] for f in frames]
            assert lefts[0] >= 65530 and lefts[-1] < 100  # forward through 65535 -> 0
            assert rights[0] <= 3 and rights[-1] > 65000  # backward through 0 -> 65535
    finally:
        e.close()


def test_start_emulators_with_links(tmp_path):
    with start_emulators(tmp_path / "links") as emu:
        assert emu.ports == {
            "ptu": str(tmp_path / "links" / "ttyPTU"),
            "base": str(tmp_path / "links" / "ttyCreate"),
        }
        assert os.path.realpath(emu.ptu_port).startswith("/dev/pts/")
    assert not os.path.lexists(tmp_path / "links" / "ttyPTU")
