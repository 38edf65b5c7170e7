"""Safety latencies of the hardware adapter on the emulators, over repeated trials (not a test).

    PYTHONPATH=. python benchmarks/hw_latency.py [--trials 10]

Prints median / max of: watchdog stop after the last drive command (emulator clock), stop after the
sensor stream goes silent, unplug detection, cliff -> SafetyStop, one PTU query round trip, and the
stream parser's throughput.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from lab.errors import ConnectionLost, SafetyStop
from lab.hardware.camera import ReplayStereoSource
from lab.hardware.config import load_config
from lab.hardware.emulators import start_emulators
from lab.hardware.open_interface import DEFAULT_STREAM, StreamParser, encode_stream_frame
from lab.hardware.robot import HardwareRobot

CFG = Path(__file__).resolve().parents[1] / "hardware" / "emulated.toml"


def _wait(pred, timeout):
    t_end = time.monotonic() + timeout
    while not pred() and time.monotonic() < t_end:
        time.sleep(0.001)
    return pred()


def trial(tmp: Path) -> dict[str, float]:
    out = {}
    with start_emulators(tmp) as emu:
        cfg = load_config(CFG).with_ports(base=emu.base_port, ptu=emu.ptu_port)
        robot = HardwareRobot(cfg, camera_source=ReplayStereoSource.synthetic(320, 240))
        try:
            c = emu.create
            robot.enable()
            robot.drive(0.2, 0.0)
            t = c.now()
            _wait(lambda: c.first_zero_drive_after(t) is not None, 2.0)
            out["watchdog stop after last command [s]"] = c.first_zero_drive_after(t).t - t
            t0 = time.perf_counter()
            for _ in range(20):
                robot.ptu.get_steps()
            out["PTU query round trip (PP+TP) [ms]"] = (time.perf_counter() - t0) / 20 * 1000
            robot.drive(0.2, 0.0)
            _wait(lambda: c.wheel_speeds() != (0, 0), 0.5)
            c.mute_stream = True
            t = c.now()
            _wait(lambda: c.first_zero_drive_after(t) is not None, 1.0)
            out["stop after the stream went silent [s]"] = c.first_zero_drive_after(t).t - t
            c.mute_stream = False
            _wait(lambda: not robot.base.stale, 1.0)
            robot.drive(0.2, 0.0)
            robot.step(0.1)
            c.cliff(1)
            t0 = time.monotonic()
            try:
                while time.monotonic() - t0 < 1.0:
                    robot.step(0.002)
            except SafetyStop:
                out["cliff -> SafetyStop raised [s]"] = time.monotonic() - t0
            c.cliff(1, on=False)
            robot.enable()
            t0 = time.monotonic()
            c.unplug()
            try:
                while time.monotonic() - t0 < 1.0:
                    robot.step(0.002)
            except ConnectionLost:
                out["unplug -> ConnectionLost raised [s]"] = time.monotonic() - t0
        finally:
            robot.close()
    return out


def parser_throughput() -> float:
    frame = encode_stream_frame({i: 0 for i in DEFAULT_STREAM}, DEFAULT_STREAM)
    data = (b"\x13\x05garbage" + frame * 20) * 500
    p = StreamParser(DEFAULT_STREAM)
    t0 = time.perf_counter()
    p.feed(data)
    return len(data) / (time.perf_counter() - t0) / 1e6


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--trials", type=int, default=10)
    a = ap.parse_args()
    rows: dict[str, list[float]] = {}
    for k in range(a.trials):
        with tempfile.TemporaryDirectory() as d:
            for key, v in trial(Path(d) / f"t{k}").items():
                rows.setdefault(key, []).append(v)
    print(f"{'quantity':45s} {'median':>9s} {'max':>9s}  (n = {a.trials})")
    for key, vs in rows.items():
        print(f"{key:45s} {statistics.median(vs):9.4f} {max(vs):9.4f}")
    print(f"{'stream parser throughput [MB/s]':45s} {parser_throughput():9.2f}  (115200 baud = 0.0115 MB/s)")


if __name__ == "__main__":
    main()
