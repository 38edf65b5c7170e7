"""Bring-up commands, as plain functions for the ``lab`` command line (``lab hardware emulate``,
``lab hardware check --config PATH``); ``python -m lab.hardware.cli`` runs them until that hook exists.

* :func:`emulate` starts a PTU-D46 and a Create 2 emulator, prints their ports, and blocks until Ctrl-C.
* :func:`check` walks through the bring-up: config, calibration, the head's mounts, ports, PTU version
  and limits, the Create's stream and odometry at rest, one stereo frame. Each line is ``PASS`` or
  ``FAIL`` with the fix. It never moves the robot.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from lab.errors import LabError
from lab.hardware.camera import StereoRectifier, load_camera_calibration, make_camera_source
from lab.hardware.config import load_config
from lab.hardware.create2 import Create2
from lab.hardware.emulators import start_emulators
from lab.hardware.ptu import PTUD46
from lab.hardware.serial_port import available_ports
from lab.mounts import load_mounts

__all__ = ["DEFAULT_LINK_DIR", "check", "check_mounts", "emulate", "main"]

DEFAULT_LINK_DIR = "/tmp/lab-emulators"  # hardware/emulated.toml points here


def emulate(
    link_dir: str | os.PathLike = DEFAULT_LINK_DIR,
    *,
    out: Callable[[str], None] = print,
    stop: threading.Event | None = None,
) -> int:
    """Run both emulators until Ctrl-C (or until ``stop`` is set); returns the exit code 0."""
    with start_emulators(link_dir) as emu:
        out(f"PTU-D46 emulator:  {emu.ptu_port}  -> {emu.ptu.slave_name}")
        out(f"Create 2 emulator: {emu.base_port}  -> {emu.create.slave_name}")
        out(
            "hardware/emulated.toml uses these ports; run: lab hardware check --config hardware/emulated.toml"
        )
        out("Ctrl-C stops the emulators.")
        try:
            while not (stop is not None and stop.is_set()):
                time.sleep(0.05)
        except KeyboardInterrupt:
            pass
    out("emulators stopped")
    return 0


def check(
    config_path: str | os.PathLike,
    *,
    out: Callable[[str], None] = print,
    emulate: bool = False,
    room_check: Callable | None = None,
) -> int:
    """Bring-up diagnostics for a config; returns 0 when every line passed, else 1.

    With ``emulate=True`` the emulators are started on the config's ports first (CI, a first try).
    ``room_check(cfg, line)`` adds the lines about the room (the landmark map, the start): ``lab hardware
    check`` passes :func:`lab.runs.room.check_room` (this layer reads no landmark map itself).
    """
    results: list[bool] = []

    def line(ok: bool, what: str, detail: str, fix: str = "") -> bool:
        results.append(ok)
        out(f"{'PASS' if ok else 'FAIL'}  {what}: {detail}" + ("" if ok or not fix else f"  -> fix: {fix}"))
        return ok

    try:
        cfg = load_config(config_path)
    except LabError as e:
        line(False, "config", str(e), "edit the file; hardware/README.md lists every key")
        return 1
    line(True, "config", str(cfg.path))

    emu = None
    if emulate:
        d = {Path(cfg.ptu.port).parent, Path(cfg.base.port).parent}
        if len(d) != 1:
            line(False, "emulators", "ptu and base ports must be in one folder to emulate them")
            return 1
        emu = start_emulators(d.pop())
        line(True, "emulators", f"started on {emu.ptu_port} and {emu.base_port}")
    try:
        c = cfg.camera
        calib = None
        try:
            calib = load_camera_calibration(cfg)
            line(
                True,
                "calibration",
                f"{c.calibration}: {c.width}x{c.height}, baseline {calib.baseline * 1000:.1f} mm, "
                f"fx {calib.P1[0, 0]:.1f} px" + (f", rms {calib.rms:.2f} px" if calib.rms else ""),
            )
        except LabError as e:
            line(
                False,
                "calibration",
                str(e),
                "calibrate (hardware/README.md step 6) or fix [camera] calibration",
            )

        ports = available_ports()
        for what, port, key in (
            ("base port", cfg.base.port, "[base] port"),
            ("PTU port", cfg.ptu.port, "[ptu] port"),
        ):
            if "://" in port or os.path.exists(port):
                line(True, what, port)
            else:
                line(
                    False,
                    what,
                    f"{port} not found (available: {', '.join(ports) or 'none'})",
                    f"plug the cable in, or set {key}",
                )

        _check_ptu(cfg, line)
        _check_base(cfg, line, in_process=emu is not None)
        _check_camera(cfg, calib, line)
        if room_check is not None:
            room_check(cfg, line)
    finally:
        if emu is not None:
            emu.close()
    ok = all(results)
    out(f"{'all checks passed' if ok else 'some checks FAILED'} ({sum(results)}/{len(results)})")
    return 0 if ok else 1


def check_mounts(cfg, line) -> None:
    """The head's mount calibration (``[camera] mounts``), when the config names one: read strictly (a
    corrupt file fails); not made yet is no failure (the robot then uses the nominal kinematics)."""
    path = cfg.camera.mounts
    if not path:
        return
    if not Path(path).exists():
        line(True, "mounts", f"{path} not made yet: the nominal kinematics (lab hardware calibrate makes it)")
        return
    try:
        m = load_mounts(path)
    except LabError as e:
        line(False, "mounts", str(e), f"lab hardware calibrate --config {cfg.path or 'CONFIG'}")
        return
    deg = [
        round(math.degrees(v), 3) for v in (*m.head_rpy[:2], m.tilt_zero, m.camera_rpy[0], m.camera_rpy[2])
    ]
    line(True, "mounts", f"{path} ({m.created}): head roll, pitch, tilt zero, camera roll, yaw {deg} deg")


def _check_ptu(cfg, line) -> None:
    ptu = PTUD46.from_config(cfg)
    try:
        ptu.connect()
    except LabError as e:
        line(
            False,
            "PTU",
            str(e),
            "power the PTU, check [ptu] port/baudrate; a silent unit may have a non-zero unit id",
        )
        return
    try:
        lim = ptu.limits
        line(True, "PTU", f"{ptu.version!r}, {math.degrees(ptu.res['P']) * 3600:.4f} arcsec/position")
        line(
            True,
            "PTU limits",
            f"pan [{math.degrees(lim.pan_min):.1f}, {math.degrees(lim.pan_max):.1f}] deg, "
            f"tilt [{math.degrees(lim.tilt_min):.1f}, {math.degrees(lim.tilt_max):.1f}] deg, "
            f"speed [{math.degrees(lim.min_speed):.1f}, {math.degrees(lim.max_speed):.1f}] deg/s",
        )
        pan, tilt = ptu.get_pan_tilt()
        line(True, "PTU position", f"pan {math.degrees(pan):.2f} deg, tilt {math.degrees(tilt):.2f} deg")
    except LabError as e:
        line(False, "PTU", str(e), "check the cable; see hardware/README.md")
    finally:
        ptu.close()


def _check_base(cfg, line, in_process: bool = False) -> None:
    """The Create's connect, stream, battery, sensors and odometry at rest.

    ``in_process``: the emulators run in this process (``--emulate``), so their stream shares the CPU with
    the check: on a loaded machine it arrives late, which says nothing about a cable; only a stream at
    under a third of its rate fails then.
    """
    base = Create2.from_config(
        dataclasses.replace(cfg.base, connect_attempts=min(cfg.base.connect_attempts, 4))
    )
    try:
        base.connect()
    except LabError as e:
        line(False, "Create 2", str(e), "switch it on (Clean button), check the cable and [base] baudrate")
        return
    try:
        # over a whole second: a short window reads a momentary stall of a busy host as a bad cable
        n0, t0 = base.frames, time.monotonic()
        time.sleep(1.0)
        s = base.sensors()
        rate = (base.frames - n0) / (time.monotonic() - t0)
        line(
            rate > (22 if in_process else 40),
            "Create 2 stream",
            f"{rate:.0f} frames/s (expect ~67), OI mode {s.oi_mode}, {base.corrupt_frames} corrupt frames",
            "check the cable (USB hub, loose connector)",
        )
        batt = f"{s.battery_charge_mah}/{s.battery_capacity_mah} mAh" if s.battery_capacity_mah else "unknown"
        line(True, "Create 2 battery", batt)
        hazard = Create2.hazard(s)
        line(
            not hazard, "Create 2 sensors", hazard or "no cliff, no wheel drop", "put the robot on the floor"
        )
        pose = base.odometry()
        still = abs(s.left_ticks) + abs(s.right_ticks)
        line(
            still == 0 and all(map(math.isfinite, (pose.x, pose.y, pose.theta))),
            "odometry at rest",
            f"{still} ticks moved in 1 s, pose ({pose.x:.3f}, {pose.y:.3f}, {pose.theta:.3f})",
            "the wheels turned while disabled: is it docked or being pushed?",
        )
    finally:
        base.close()


def _check_camera(cfg, calib, line) -> None:
    check_mounts(cfg, line)
    if cfg.camera.source == "sim":  # rendered from the emulators' state: only a rehearsal can make it
        line(
            True,
            "camera",
            f"rendered by the simulator (world {cfg.sim.world!r}) in a rehearsal: "
            f"lab identify --robot {cfg.path or 'CONFIG'} (or lab.runs.rehearsal.rehearsal())",
        )
        return
    try:
        src = make_camera_source(cfg)
    except LabError as e:
        line(False, "camera", str(e), "check [camera] source/device and the cable")
        return
    try:
        raw = src.read(timeout=2.0)
        h, w = raw.left.shape[:2]
        line(
            True,
            "camera",
            f"one stereo frame {w}x{h}, mean grey left {raw.left.mean():.0f}, right {raw.right.mean():.0f}",
        )
        if calib is not None:
            left, right = StereoRectifier(calib).rectify(raw.left, raw.right)
            line(bool(np.any(left)), "rectification", f"rectified {left.shape[1]}x{left.shape[0]}")
    except LabError as e:
        line(False, "camera", str(e), "check the camera mode ([camera] width/height) and the cable")
    finally:
        src.close()


def main(argv: list[str] | None = None) -> int:
    """``python -m lab.hardware.cli {emulate,check}``: the same as ``lab hardware ...``."""
    ap = argparse.ArgumentParser(prog="lab hardware", description="Hardware bring-up: emulators and checks.")
    sub = ap.add_subparsers(dest="cmd", required=True)
    e = sub.add_parser("emulate", help="run PTU-D46 and Create 2 emulators on ptys until Ctrl-C")
    e.add_argument(
        "--dir", default=DEFAULT_LINK_DIR, help=f"folder for the port symlinks (default {DEFAULT_LINK_DIR})"
    )
    c = sub.add_parser("check", help="bring-up diagnostics: one PASS/FAIL line per check")
    c.add_argument("--config", required=True, help="hardware TOML file, e.g. hardware/robot.toml")
    c.add_argument("--emulate", action="store_true", help="start the emulators on the config's ports first")
    a = ap.parse_args(argv)
    if a.cmd == "emulate":
        return emulate(a.dir)
    return check(a.config, emulate=a.emulate)


if __name__ == "__main__":
    sys.exit(main())
