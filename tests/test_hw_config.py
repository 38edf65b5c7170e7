"""The drivers build themselves from the config, and the config agrees with its calibration file.

One place (``Create2.from_config``, ``PTUD46.from_config``) maps a section's keys onto a driver, so
``lab hardware check`` and :class:`HardwareRobot` see the same robot: here, the same head angle when the
pan/tilt zero offsets are not zero (on the emulators).
"""

from __future__ import annotations

import math
import re

import pytest
from hw_helpers import EMULATED_TOML

from lab.errors import ConfigError
from lab.hardware.camera import load_camera_calibration
from lab.hardware.cli import check
from lab.hardware.config import load_config
from lab.hardware.create2 import Create2
from lab.hardware.emulators import start_emulators
from lab.hardware.ptu import PTUD46
from lab.hardware.robot import HardwareRobot

CALIBRATION = EMULATED_TOML.parent / "calibration" / "example_stereo_320x240.yml"


def _emulated_toml(tmp_path, links, **replace):
    """hardware/emulated.toml with its ports in ``links`` and an absolute calibration path, edited."""
    text = EMULATED_TOML.read_text().replace("/tmp/lab-emulators", str(links))
    text = text.replace("calibration/", str(CALIBRATION.parent) + "/")
    for old, new in replace.items():
        assert old in text
        text = text.replace(old, new, 1)
    path = tmp_path / "emulated.toml"
    path.write_text(text)
    return path


OFFSETS = {"[ptu]": "[ptu]\npan_zero_offset_deg = 10.0\ntilt_zero_offset_deg = -5.0\npan_sign = -1"}


def test_drivers_take_every_field_of_their_section(tmp_path):
    cfg = load_config(_emulated_toml(tmp_path, tmp_path / "links", **OFFSETS))
    base, ptu = Create2.from_config(cfg), PTUD46.from_config(cfg.ptu)
    b, p = cfg.base, cfg.ptu
    assert (base.port, base.baudrate, base.mode) == (b.port, b.baudrate, b.mode)
    assert (base.stale_timeout_s, base.first_frame_timeout_s) == (b.stale_timeout_s, b.first_frame_timeout_s)
    assert (base.connect_attempts, base.max_wheel_speed) == (b.connect_attempts, b.max_speed)
    assert base.odom.m_per_tick == pytest.approx(math.pi * b.wheel_diameter / b.ticks_per_rev)
    assert base.odom.wheel_base == b.wheel_base
    assert (ptu.port, ptu.baudrate, ptu.timeout_s, ptu.banner_wait_s) == (
        p.port,
        p.baudrate,
        p.timeout_s,
        p.banner_wait_s,
    )
    assert ptu.sign == {"P": -1, "T": 1}
    assert ptu.zero == pytest.approx({"P": math.radians(10.0), "T": math.radians(-5.0)})
    assert ptu.default_speed == pytest.approx(math.radians(p.speed_deg_s))
    assert ptu.move_margin_s == p.move_margin_s


def test_check_and_the_robot_report_the_same_head_position_with_zero_offsets(tmp_path):
    links = tmp_path / "links"
    path = _emulated_toml(tmp_path, links, **OFFSETS)
    steps = {"P": 400, "T": -200}
    res_deg = 185.1428 / 3600.0  # the emulator's arc-seconds per position
    expected = (-(steps["P"] * res_deg - 10.0), steps["T"] * res_deg + 5.0)  # sign * (steps * res - zero)
    lines = []
    with start_emulators(links) as emu:
        for ax, n in steps.items():  # the head stands there (target first: it never moves towards 0)
            emu.ptu.target[ax] = n
            emu.ptu.pos[ax] = float(n)
        check(path, out=lines.append)
        robot = HardwareRobot(path)
        try:
            pt = robot.pan_tilt()
        finally:
            robot.close()
    line = next(x for x in lines if x.startswith("PASS  PTU position:"))
    m = re.search(r"pan (-?\d+\.\d+) deg, tilt (-?\d+\.\d+) deg", line)
    checked = (float(m.group(1)), float(m.group(2)))
    robot_deg = (round(math.degrees(pt.pan), 2), round(math.degrees(pt.tilt), 2))
    assert checked == robot_deg == (round(expected[0], 2), round(expected[1], 2))


def test_camera_section_disagreeing_with_the_calibration_is_one_clear_error(tmp_path):
    path = _emulated_toml(
        tmp_path, tmp_path / "links", **{"width = 320\nheight = 240": "width = 640\nheight = 480"}
    )
    cfg = load_config(path)
    with pytest.raises(ConfigError) as e:
        load_camera_calibration(cfg)
    msg = str(e.value)
    assert "\n" not in msg
    assert str(path) in msg and "[camera] width/height say 640x480" in msg  # the config: file, section, value
    assert str(CALIBRATION) in msg and "(image_width/image_height) is for 320x240" in msg  # the calibration
    with pytest.raises(ConfigError, match=re.escape(msg)):  # the robot refuses it, before opening a port
        HardwareRobot(cfg)
    lines = []
    assert check(path, out=lines.append) == 1
    assert any(x.startswith("FAIL  calibration: ") and msg in x for x in lines)


def test_the_stated_blur_reaches_the_robots_camera_and_a_wrong_one_is_refused(tmp_path):
    links = tmp_path / "links"
    path = _emulated_toml(tmp_path, links, **{"width = 320": "blur_sigma_px = 0.9\nwidth = 320"})
    with start_emulators(links):
        robot = HardwareRobot(path)
        try:
            assert robot.camera.blur_sigma_px == 0.9  # the stereo features sharpen by it
        finally:
            robot.close()
    bad = _emulated_toml(tmp_path, links, **{"width = 320": "blur_sigma_px = -1.0\nwidth = 320"})
    with pytest.raises(ConfigError, match=r"\[camera\] blur_sigma_px must be within \[0, 5\] px, got -1.0"):
        load_config(bad)
