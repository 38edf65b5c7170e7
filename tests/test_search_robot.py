"""`lab search --robot`: the unchanged SearchAgent on HardwareRobot, in a rehearsal (the device emulators,
the lab room rendered from their true state, lab/runs/rehearsal.py), scored against the rendered world.

Peers: the rendered world's truth (the object's pose in PyBullet, the emulators' base pose), the
emulators' own record of what reached the devices (wheel speeds, drive commands, PTU commands), and the
matrix composition of the odometry into the room's frame. The time budget and Ctrl-C end a run on the
robot with the base stopped and the JSON written.
"""

from __future__ import annotations

import json
import math
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from hw_helpers import EMULATED_TOML, REPO, wait_until
from nav_fakes import KinematicRobot

import lab.runs.rehearsal as rehearsal_mod
from lab.cli import main
from lab.contract import problems
from lab.errors import ConfigError
from lab.geometry import Pose2D
from lab.hardware.open_interface import REQUIRED_STREAM, Op
from lab.runs.robots import PlacedRobot
from lab.runs.search import measured_pose, navigator_factory, run_search
from lab.scene import load_scene

REHEARSAL_TOML = REPO / "hardware" / "rehearsal.toml"
NEAR = (0.0, -1.6, 0.0, -90.0)  # the cereal box on the floor 1.4 m in front of the robot's start


def _keep_emulators(monkeypatch) -> list:
    """The emulator sets the rehearsals of this test start, for reading their truth afterwards."""
    kept = []
    start = rehearsal_mod.start_emulators

    def start_and_keep(link_dir, **kw):
        kept.append(start(link_dir, **kw))
        return kept[-1]

    monkeypatch.setattr(rehearsal_mod, "start_emulators", start_and_keep)
    return kept


def test_placed_robot_puts_the_odometry_in_the_rooms_frame():
    start = Pose2D(0.0, -3.0, math.pi / 2)
    base = KinematicRobot(Pose2D(0.0, 0.0, 0.0))
    robot = PlacedRobot(base, start)
    assert (robot.odometry().x, robot.odometry().y, robot.odometry().theta) == pytest.approx(
        (0.0, -3.0, math.pi / 2)
    )
    robot.enable()
    for _ in range(40):  # an arc
        robot.drive(0.3, 0.4)
        robot.step(0.05)
    G = start.G() @ base.odometry().G()  # G_W,odom = G_W,start G_start,odom
    p = robot.odometry()
    assert np.allclose(p.G(), G, atol=1e-12)
    assert math.hypot(base.odometry().x, base.odometry().y) > 0.3  # it moved
    assert robot.cmd_timeout_s == base.cmd_timeout_s and robot.bumps == base.bumps


def test_truth_is_for_the_real_robot_and_is_checked(tmp_path, capsys):
    scene = load_scene("lab_room")
    # the measured pose is the simulator's body frame: centre of the box, turned about z
    G = measured_pose(scene, "cereal_box", (0.5, 1.0, 0.75, 90.0))
    h = scene.body("cereal_box").height
    assert np.allclose(G[:3, 3], (0.5, 1.0, 0.75 + h / 2)) and np.allclose(G[:2, 0], (0.0, 1.0), atol=1e-12)
    for bad, what in (
        ((9.0, 0.0, 0.0, 0.0), "is not on the room's floor"),
        ((0.0, 0.0, -0.2, 0.0), "is not on the room's floor"),
        ((0.0, math.nan, 0.0, 0.0), "4 finite numbers"),
    ):
        with pytest.raises(ConfigError, match=what):
            measured_pose(scene, "cereal_box", bad)
    # the command line: one line each, before any port is opened
    cases = [
        (["--truth", "0,0,0,0"], "--truth is the object's measured pose on the real robot"),
        (
            ["--robot", str(EMULATED_TOML), "--truth", "9,0,0,0"],
            "--truth (9, 0, 0) is not on the room's floor",
        ),
        (["--robot", str(EMULATED_TOML), "--place", "0,-1.6,0,0"], "--place puts the object in a simulated"),
    ]
    for extra, message in cases:
        capsys.readouterr()
        assert main(["search", "--object", "cereal_box", *extra]) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1, err
    with pytest.raises(SystemExit):
        main(["search", "--object", "cereal_box", "--truth", "1,2,3"])
    assert "--truth must be 4 comma-separated numbers" in capsys.readouterr().err


@pytest.mark.slow
def test_rehearsed_search_finds_the_object_through_ptu_garbage_and_a_short_stream(monkeypatch):
    """The acceptance's search on the emulators, with two faults of the table injected from the start:
    stray bytes before every third PTU reply, and a Create that streams only the packets it needs."""
    kept = _keep_emulators(monkeypatch)

    def faults(emu):
        emu.ptu.garbage_every = 3
        emu.create.known_packets = set(REQUIRED_STREAM)

    res = run_search(
        "cereal_box",
        0,
        place=NEAR,
        max_time=90.0,  # wall time: the search takes about 30 s of it
        navigate=navigator_factory,
        robot_config=REHEARSAL_TOML,
        emulator_setup=faults,
    )
    d = json.loads(json.dumps(res.to_json()))
    print({k: d[k] for k in ("found", "reason", "position_error_m", "orientation_error_deg", "sim_time_s")})
    (emu,) = kept
    assert res.found and res.success, res.reason
    assert res.position_error_m <= 0.05 and res.orientation_error_deg <= 10.0
    assert problems("search", d) == []  # lab/schemas/search.schema.json
    assert d["sensing"] == "realistic" and d["robot"] == str(REHEARSAL_TOML)  # run_search's default
    assert d["sensing_applies_to"] == ["camera"]  # the rendered camera; odometry and head: the emulators
    # the truth is the rendered world's: the object where --place put it (the --truth conversion agrees)
    G_true = measured_pose(load_scene("lab_room"), "cereal_box", NEAR)
    assert np.allclose(d["true_pose"]["position_m"], G_true[:3, 3], atol=1e-4)
    # the faults were there, and survived: the stream fell back to the required set, garbage was sent
    asked = [tuple(args[1:]) for _, op, args in emu.create.opcodes if op == Op.STREAM]
    assert len(asked[0]) > len(REQUIRED_STREAM) and asked[-1] == tuple(REQUIRED_STREAM), asked
    assert emu.ptu._replies >= 30
    # the base drove (the emulator's truth) and odometry followed it; it stopped at the end
    assert res.path_length_m > 0.2 and math.hypot(emu.create.x, emu.create.y) > 0.2
    assert d["odometry_error_m"] < 0.05
    assert wait_until(lambda: emu.create.wheel_speeds() == (0, 0), 2.0)
    assert d["events"][0]["t"] < 60.0 and d["sim_time_s"] <= 90.0  # times from the search's start


def test_rehearsed_search_ends_at_its_time_budget_with_the_base_stopped(monkeypatch, tmp_path, capsys):
    kept = _keep_emulators(monkeypatch)
    out = tmp_path / "r.json"
    budget = 6.0
    args = ["search", "--robot", str(REHEARSAL_TOML), "--object", "cereal_box", "--seed", "0"]
    assert main([*args, "--max-time", str(budget), "--json", str(out)]) == 0, capsys.readouterr().err
    d = json.loads(out.read_text())
    (emu,) = kept
    assert problems("search", d) == []
    assert not d["found"] and not d["success"] and "time budget of 6 s used up" in d["reason"]
    # it ended at its budget (the robot's clock; one step or frame past it at most)
    assert budget <= d["sim_time_s"] <= budget + 3.0, d["sim_time_s"]
    assert emu.create.wheel_speeds() == (0, 0)
    assert emu.ptu.commands, "the head never moved"
    assert d["events"][-1]["kind"] == "end"


def _child(tmp_path, *lab_args):
    report = tmp_path / "child.json"
    cmd = [sys.executable, str(REPO / "tests" / "rehearsal_child.py"), str(report), *lab_args]
    proc = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    return proc, report


def _interrupt_once_driving(proc, report, timeout: float = 120.0) -> None:
    """SIGINT to the child as soon as its emulated base's wheels turn."""
    marker = report.with_suffix(".moving")
    t_end = time.monotonic() + timeout
    while not marker.exists():
        if proc.poll() is not None or time.monotonic() > t_end:
            proc.kill()
            out, err = proc.communicate()
            pytest.fail(f"the child never drove (rc {proc.returncode}): {err[-2000:]}")
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)


@pytest.mark.slow
def test_ctrl_c_during_a_rehearsed_search_stops_the_base_and_writes_the_result(tmp_path):
    out = tmp_path / "r.json"
    proc, report = _child(
        tmp_path,
        *("search", "--robot", str(REHEARSAL_TOML), "--object", "cereal_box", "--place", "0,-1.6,0,-90"),
        *("--max-time", "120", "--json", str(out)),
    )
    _interrupt_once_driving(proc, report)
    _, err = proc.communicate(timeout=60)
    r = json.loads(report.read_text())
    assert r["rc"] == 130 and r["interrupted"], err[-2000:]
    assert "lab search: interrupted, motors stopped: the result so far is in" in err
    # the base was driving when the signal came, and the zero reached it well within the watchdog's time
    assert r["last_nonzero_drive_t"] is not None and r["wheels"] == [0, 0]
    assert r["first_zero_after_sigint_t"] - r["sigint_t"] < 0.4
    d = json.loads(out.read_text())
    assert d["reason"] == "interrupted" and problems("search", d) == []
    assert d["global_searches"] >= 1  # the base had just set off: the path driven may still read 0


def test_ctrl_c_during_a_rehearsed_identification_writes_the_result(monkeypatch, tmp_path, capsys):
    """The same for `lab identify --robot`: the interrupt reaches the run (here raised from the agent's
    step once the base drives: the signal's path to KeyboardInterrupt is the search test's)."""
    from lab.identification.agent import IdentificationAgent

    kept = _keep_emulators(monkeypatch)
    step = IdentificationAgent.step

    def step_until_driving(agent):
        if kept and kept[0].create.last_nonzero_drive() is not None:
            raise KeyboardInterrupt
        return step(agent)

    monkeypatch.setattr(IdentificationAgent, "step", step_until_driving)
    out = tmp_path / "i.json"
    args = ["identify", "--robot", str(REHEARSAL_TOML), "--planner", "random", "--mover", "static"]
    assert main([*args, "--max-actions", "2", "--max-time", "60", "--json", str(out)]) == 130
    assert "lab identify: interrupted, motors stopped" in capsys.readouterr().err
    d = json.loads(out.read_text())
    assert d["reason"] == "interrupted" and problems("identify", d) == []
    assert d["actions"] >= 1
    (emu,) = kept
    assert emu.create.wheel_speeds() == (0, 0)


def _quick_search_parts():
    """A search that drives within seconds: one view for the global search and for the navigator's first
    scan (the same agent and navigator; the faults are about the robot's path, not about the search)."""
    from lab.navigation.navigator import NavigatorConfig
    from lab.search.config import SearchAgentConfig
    from lab.search.global_search import GlobalSearchConfig

    config = SearchAgentConfig(global_search=GlobalSearchConfig(pans_deg=(0.0,), tilts_deg=(-30.0,)))
    nav_config = NavigatorConfig(scan_pans=(0.0,))
    return config, lambda robot, spec: navigator_factory(robot, spec, config=nav_config)


def _hardware_robot(robot):
    while not hasattr(robot, "read_state"):  # BudgetedRobot -> LocalizedRobot -> PlacedRobot -> Hardware
        robot = robot.base
    return robot


FAULTS = {
    # fault: (inject it, the robot's state at the end, the reason, the base's wheels at the end)
    "cliff": (lambda e: e.create.cliff(2), "faulted", r"SafetyStop: safety stop \(cliff front-right\)", 0),
    "stream stop": (lambda e: setattr(e.create, "mute_stream", True), "stale", r"no sensor stream", 0),
    "PTU unplugged": (lambda e: e.ptu.unplug(), "disconnected", r"ConnectionLost: .*PTU", 0),
    # the Create's OI has no link watchdog: unplugged, it keeps its last Drive Direct (hardware/README.md)
    "base unplugged": (lambda e: e.create.unplug(), "disconnected", r"ConnectionLost: .*Create", None),
}


@pytest.mark.parametrize("fault", list(FAULTS))
def test_a_device_fault_while_the_search_drives_ends_it_in_the_documented_state(monkeypatch, fault):
    import re
    import threading

    inject, state, reason, wheels = FAULTS[fault]
    kept = _keep_emulators(monkeypatch)
    seen: dict = {}

    def attach(agent):
        hw = _hardware_robot(agent.robot)

        def on_event(a, event):
            if event.kind == "end":
                seen.update(state=hw.state, ptu=list(kept[0].ptu.commands))

        agent.observer = on_event

    def inject_once_driving():
        ok = wait_until(lambda: kept and kept[0].create.wheel_speeds() != (0, 0), 60.0, step=0.01)
        seen["t"] = kept[0].ptu.now() if ok else None
        if ok:
            inject(kept[0])

    threading.Thread(target=inject_once_driving, daemon=True).start()
    config, navigate = _quick_search_parts()
    res = run_search(
        "cereal_box",
        0,
        place=(0.0, 0.6, 0.0, -90.0),  # 3.6 m ahead: the base is driving when the fault comes
        max_time=60.0,
        navigate=navigate,
        config=config,
        robot_config=REHEARSAL_TOML,
        attach=attach,
    )
    (emu,) = kept
    print(f"\n{fault}: state {seen.get('state')!r}; reason {res.reason!r}")
    assert seen.get("t") is not None, f"the base never drove: {res.reason}"
    assert not res.found and re.search(f"^stopped by a fault: .*{reason}", res.reason), res.reason
    assert "\n" not in res.reason  # one clear message
    assert seen["state"] == state
    assert problems("search", json.loads(json.dumps(res.to_json()))) == []
    if wheels is not None:
        assert wait_until(lambda: emu.create.wheel_speeds() == (0, 0), 2.0), emu.create.wheel_speeds()
    else:  # what can still be reached is stopped: the head was halted after the cable was pulled
        assert emu.create.wheel_speeds() != (0, 0)
        assert any(c.upper() == "H" for t, c in seen["ptu"] if t >= seen["t"]), seen["ptu"][-5:]


def test_on_the_real_robot_path_the_scoring_is_null_without_a_measured_truth(tmp_path):
    """The real robot's path (a robot config whose camera is not the simulator's): here the emulators
    with the synthetic camera, in which there is nothing to find. No truth: the scoring fields are null
    and the JSON keeps the contract; with the operator's measured pose the run is scored against it."""
    import dataclasses

    from lab.hardware.config import load_config
    from lab.hardware.emulators import start_emulators

    with start_emulators(tmp_path / "links") as emu:
        cfg = load_config(EMULATED_TOML).with_ports(base=emu.base_port, ptu=emu.ptu_port)
        cfg = dataclasses.replace(cfg, base=dataclasses.replace(cfg.base, stale_timeout_s=0.5))  # shared GIL
        kw = {"max_time": 2.0, "navigate": navigator_factory, "robot_config": cfg}
        blind = run_search("book", 0, **kw).to_json()
        measured = run_search("book", 0, truth=(-2.6, 2.9, 1.2, 0.0), **kw).to_json()
        assert emu.create.wheel_speeds() == (0, 0)
    for d in (blind, measured):
        assert problems("search", json.loads(json.dumps(d))) == []
        assert d["sensing"] == "hardware" and not d["found"] and "time budget" in d["reason"]
        assert d["odometry_error_m"] is None and d["localization_error_m"] is None
        assert d["camera_frame_error"] is None and d["surface"] is None
    assert blind["true_pose"] is None and blind["success"] is None and blind["place"] is None
    G = measured_pose(load_scene("lab_room"), "book", (-2.6, 2.9, 1.2, 0.0))
    assert measured["true_pose"]["position_m"] == pytest.approx(list(G[:3, 3]), abs=1e-4)
    assert measured["success"] is False and measured["place"] == [-2.6, 2.9, 1.2, 0.0]
