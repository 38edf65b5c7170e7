"""The contract every :class:`lab.robot.Robot` implementation must keep (see ``lab/robot.py``).

These tests use only the Robot interface, plus a few optional hooks an implementation may provide through
:class:`ContractSubject`; a test that needs a missing hook is skipped. Time is the robot's own: every wait
is ``robot.step(dt)`` and every measurement uses ``robot.now()`` and ``robot.odometry()``, so the same test
runs in simulated time (the simulator) and in real time (the hardware on its emulators).

How to add an implementation
----------------------------
1. Write a factory: a generator function that takes pytest's ``tmp_path`` and yields a
   :class:`ContractSubject` whose robot is **connected but not enabled**, standing still, head at (0, 0)
   or anywhere within its limits, and closes it afterwards (closing twice must be fine)::

       def sim_subject(tmp_path):
           world = SimWorld(...)                      # an empty room: nothing to bump into
           robot = SimRobot(world, odometry_noise=OdometryNoise.none())
           yield ContractSubject(robot, trip_safety=lambda: robot.trip_safety("cliff"))
           robot.close()

2. Add it to ``IMPLEMENTATIONS`` in ``tests/test_hw_contract.py`` (the ``subject`` fixture there is
   parametrised over that dict), or define your own ``subject`` fixture and a
   ``class TestMyRobotContract(RobotContract)`` in your own test module. pytest collects the tests through
   the subclass; this module itself is not collected (its name does not start with ``test_``).

Tolerances are loose enough for odometry noise of a few percent and for real-time scheduling jitter, and
tight enough that a missing clamp, slew limit, watchdog or latch fails.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pytest

from lab.errors import EStopActive, LimitError, NotEnabled, SafetyStop
from lab.geometry import Pose2D
from lab.robot import PanTiltState, Robot, StereoFrame

__all__ = ["ContractSubject", "RobotContract"]


@dataclass
class ContractSubject:
    """A robot under test and optional hooks into its world.

    Attributes
    ----------
    robot : Robot
        Connected, not enabled, standing still.
    trip_safety : callable, optional
        Cause a safety trip (cliff or wheel drop) the way this robot meets one; it must stop the base and
        make the next command or step raise SafetyStop.
    clear_hazard : callable, optional
        Remove the cause of the trip (put the robot back on the floor) so that ``enable()`` can re-arm.
    commands_sent : callable, optional
        Number of motion commands that reached the devices so far ("nothing was sent" checks).
    put_obstacle_ahead : callable, optional
        Make the base run into something when it drives forward about 0.1 m from where it stands now
        (a box in the simulator; a pressed bumper on the emulated Create).
    stale_sensors : callable(bool), optional
        Stop (True) or resume (False) the base's sensor stream.
    """

    robot: Robot
    trip_safety: Callable[[], None] | None = None
    clear_hazard: Callable[[], None] | None = None
    commands_sent: Callable[[], int] | None = None
    put_obstacle_ahead: Callable[[], None] | None = None
    stale_sensors: Callable[[bool], None] | None = None


def _dist(a: Pose2D, b: Pose2D) -> float:
    return math.hypot(b.x - a.x, b.y - a.y)


def _hold(robot: Robot, v: float, omega: float, duration: float, dt: float = 0.1) -> None:
    """Keep commanding (v, omega) for ``duration`` [s] of robot time, as a control loop does."""
    t_end = robot.now() + duration
    while robot.now() < t_end - 1e-9:
        robot.drive(v, omega)
        robot.step(min(dt, t_end - robot.now()))


class RobotContract:
    """Subclass it in a ``test_*.py`` module that provides a ``subject`` fixture (a ContractSubject)."""

    @pytest.fixture
    def robot(self, subject) -> Robot:
        return subject.robot

    # --- arming ---------------------------------------------------------------------------------
    def test_motion_needs_enable(self, robot):
        assert not robot.enabled
        with pytest.raises(NotEnabled):
            robot.drive(0.1, 0.0)
        with pytest.raises(NotEnabled):
            robot.command_pan_tilt(0.1, 0.0)

    def test_disable_stops_and_refuses(self, robot):
        robot.enable()
        robot.drive(0.2, 0.0)
        robot.step(0.3)
        robot.disable()
        assert not robot.enabled
        p0 = robot.odometry()
        robot.step(0.3)
        assert _dist(p0, robot.odometry()) < 0.003
        with pytest.raises(NotEnabled):
            robot.drive(0.1, 0.0)

    # --- driving --------------------------------------------------------------------------------
    def test_drive_forward_and_turn_counter_clockwise(self, robot):
        robot.enable()
        p0 = robot.odometry()
        _hold(robot, 0.2, 0.0, 1.0)
        p1 = robot.odometry()
        # 0.4 s of ramp at 0.5 m/s^2 then 0.2 m/s: 0.16 m in 1 s (the hardware adds a frame of latency)
        assert 0.1 < p1.x - p0.x < 0.22
        assert abs(p1.y - p0.y) < 0.02 and abs(p1.theta - p0.theta) < 0.05
        _hold(robot, 0.0, 0.8, 0.8)
        assert robot.odometry().theta - p1.theta > 0.2  # positive omega is counter-clockwise
        robot.stop()

    def test_speed_is_clamped(self, robot):
        robot.enable()
        vmax = robot.base_limits.max_speed
        _hold(robot, 10.0, 0.0, vmax / robot.base_limits.max_accel + 0.2)  # clamped, not refused
        p0, t0 = robot.odometry(), robot.now()
        _hold(robot, 10.0, 0.0, 0.4)
        v = _dist(p0, robot.odometry()) / (robot.now() - t0)
        assert 0.8 * vmax < v < 1.05 * vmax
        robot.stop()

    def test_acceleration_is_limited(self, robot):
        robot.enable()
        a = robot.base_limits.max_accel
        p0, t0 = robot.odometry(), robot.now()
        robot.drive(robot.base_limits.max_speed, 0.0)  # a step in the command
        robot.step(0.3)
        T = robot.now() - t0
        d = _dist(p0, robot.odometry())
        assert 0.0 < d < 0.5 * a * T**2 * 1.3 + 0.005  # a ramp, not a jump to full speed
        robot.stop()

    def test_stop_is_immediate(self, robot):
        robot.enable()
        _hold(robot, 0.3, 0.0, 0.8)
        robot.stop()
        robot.step(0.05)
        p0 = robot.odometry()
        robot.step(0.3)
        assert _dist(p0, robot.odometry()) < 0.003

    def test_watchdog_stops_the_base(self, robot):
        robot.enable()
        L = robot.base_limits
        robot.drive(0.2, 0.0)
        robot.step(0.2)
        # no further command: stopped within the timeout (plus a slewed stop, where the robot slews)
        robot.step(robot.cmd_timeout_s + 0.2 / L.max_accel + 0.1)
        p0 = robot.odometry()
        robot.step(0.4)
        assert _dist(p0, robot.odometry()) < 0.003
        assert robot.enabled  # the watchdog stops, it does not disarm

    # --- refused commands -----------------------------------------------------------------------
    @pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
    def test_non_finite_values_are_refused_before_anything_moves(self, subject, robot, bad):
        robot.enable()
        sent = subject.commands_sent() if subject.commands_sent else None
        pt0 = robot.pan_tilt()
        p0 = robot.odometry()
        for call in (
            lambda: robot.drive(bad, 0.0),
            lambda: robot.drive(0.0, bad),
            lambda: robot.command_pan_tilt(bad, 0.0),
            lambda: robot.command_pan_tilt(0.0, bad),
            lambda: robot.command_pan_tilt(0.1, 0.0, speed=bad),
        ):
            with pytest.raises(ValueError):
                call()
        for bad_type in ("0.1", None, [0.1]):
            with pytest.raises(TypeError):
                robot.drive(bad_type, 0.0)
            with pytest.raises(TypeError):
                robot.command_pan_tilt(bad_type, 0.0)
        robot.step(0.2)
        assert _dist(p0, robot.odometry()) < 0.002
        pt = robot.pan_tilt()
        assert (pt.pan_target, pt.tilt_target) == (pt0.pan_target, pt0.tilt_target)
        if sent is not None:
            assert subject.commands_sent() == sent

    def test_pan_tilt_limits_are_checked_before_anything_moves(self, subject, robot):
        robot.enable()
        lim = robot.pan_tilt_limits
        sent = subject.commands_sent() if subject.commands_sent else None
        pt0 = robot.pan_tilt()
        for pan, tilt in (
            (lim.pan_max + 0.01, 0.0),
            (lim.pan_min - 0.01, 0.0),
            (0.0, lim.tilt_max + 0.01),
            (0.0, lim.tilt_min - 0.01),
        ):
            with pytest.raises(LimitError):
                robot.command_pan_tilt(pan, tilt)
        for speed in (lim.max_speed * 1.5, lim.min_speed * 0.5, 0.0, -0.1):
            with pytest.raises(LimitError):
                robot.command_pan_tilt(0.1, 0.0, speed=speed)
        robot.step(0.1)
        pt = robot.pan_tilt()
        assert (pt.pan_target, pt.tilt_target) == (pt0.pan_target, pt0.tilt_target) and not pt.moving
        if sent is not None:
            assert subject.commands_sent() == sent

    # --- pan-tilt -------------------------------------------------------------------------------
    def test_pan_tilt_reaches_its_target(self, robot):
        robot.enable()
        robot.command_pan_tilt(0.3, -0.1)
        s = robot.wait_pan_tilt(timeout=5.0)
        assert isinstance(s, PanTiltState) and not s.moving
        assert s.pan == pytest.approx(0.3, abs=0.002) and s.tilt == pytest.approx(-0.1, abs=0.002)
        lim = robot.pan_tilt_limits
        speed = 0.25 * (lim.min_speed + lim.max_speed) / 2  # slow enough for several samples on the way
        robot.command_pan_tilt(0.0, 0.0, speed=speed)
        samples = []  # (t, pan) while it moves: the slope is the speed (a late reply shifts, not tilts, it)
        t_end = robot.now() + 5.0
        while (s := robot.pan_tilt()).moving and robot.now() < t_end:
            if 0.03 < s.pan < 0.27:
                samples.append((s.t, s.pan))
            robot.step(0.01)
        assert not s.moving and len(samples) >= 3
        t, pan = np.array(samples).T
        assert -np.polyfit(t, pan, 1)[0] == pytest.approx(speed, rel=0.15)  # moved at that speed

    # --- latches --------------------------------------------------------------------------------
    def test_estop_latches_until_cleared_and_enabled(self, robot):
        robot.enable()
        robot.drive(0.2, 0.0)
        robot.step(0.3)
        robot.estop()
        p0 = robot.odometry()
        robot.step(0.3)
        assert _dist(p0, robot.odometry()) < 0.003
        with pytest.raises(EStopActive):
            robot.drive(0.1, 0.0)
        with pytest.raises(EStopActive):
            robot.command_pan_tilt(0.1, 0.0)
        with pytest.raises(EStopActive):
            robot.enable()
        robot.clear_estop()
        with pytest.raises(NotEnabled):  # cleared, but not re-armed
            robot.drive(0.1, 0.0)
        robot.enable()
        robot.drive(0.1, 0.0)
        robot.stop()

    def test_safety_trip_stops_and_is_never_rearmed_automatically(self, subject, robot):
        if subject.trip_safety is None:
            pytest.skip("this implementation has no way to cause a safety trip")
        robot.enable()
        robot.drive(0.2, 0.0)
        robot.step(0.4)
        subject.trip_safety()
        with pytest.raises(SafetyStop):
            for _ in range(50):  # raised by the next step or command (within 0.5 s)
                robot.step(0.01)
        assert not robot.enabled
        p0 = robot.odometry()
        for call in (
            lambda: robot.step(0.3),
            lambda: robot.drive(0.1, 0.0),
            lambda: robot.command_pan_tilt(0.1, 0),
        ):
            with pytest.raises(SafetyStop):
                call()
        assert not robot.enabled and _dist(p0, robot.odometry()) < 0.003  # stopped, and still not re-armed
        if subject.clear_hazard is not None:
            subject.clear_hazard()
        robot.enable()
        robot.drive(0.1, 0.0)
        robot.step(0.2)
        robot.stop()

    # --- bumps and stale sensors ----------------------------------------------------------------
    def test_a_bump_is_counted_once_and_does_not_disarm(self, subject, robot):
        if subject.put_obstacle_ahead is None:
            pytest.skip("this implementation has no way to put an obstacle in the base's way")
        robot.enable()
        b0 = robot.bumps
        assert b0 == 0
        subject.put_obstacle_ahead()
        _hold(robot, 0.15, 0.0, 2.0)  # about 0.25 m: into the obstacle and on pushing against it
        assert robot.bumps == b0 + 1  # one contact, one bump
        assert robot.enabled  # a bump stops nothing by itself: the navigator decides (BUMPED)
        robot.stop()

    def test_stale_sensors_stop_the_base_and_show_in_the_state(self, subject, robot):
        if subject.stale_sensors is None:
            pytest.skip("this implementation has no sensor stream that can go stale")
        from lab.errors import DeviceTimeout

        robot.enable()
        _hold(robot, 0.1, 0.0, 0.5)
        subject.stale_sensors(True)
        try:
            with pytest.raises(DeviceTimeout, match="no sensor stream"):
                _hold(robot, 0.1, 0.0, 3.0)  # refused once the stream is stale
            assert not robot.enabled and getattr(robot, "state", "stale") == "stale"
            p0 = robot.odometry()
            robot.step(0.3)
            assert _dist(p0, robot.odometry()) < 0.01
        finally:
            subject.stale_sensors(False)
        t_end = robot.now() + 3.0
        while not robot.enabled and robot.now() < t_end:
            robot.step(0.05)
        assert robot.enabled and getattr(robot, "state", "enabled") == "enabled"  # back by itself
        robot.drive(0.1, 0.0)
        robot.stop()

    # --- lifecycle ------------------------------------------------------------------------------
    def test_close_is_safe_twice_and_refuses_commands(self, robot):
        robot.enable()
        robot.drive(0.1, 0.0)
        robot.close()
        robot.close()
        assert not robot.enabled
        with pytest.raises(NotEnabled):
            robot.drive(0.1, 0.0)
        with pytest.raises(NotEnabled):
            robot.command_pan_tilt(0.0, 0.0)
        with pytest.raises(NotEnabled):
            robot.enable()

    def test_context_manager_closes_on_exception(self, robot):
        with pytest.raises(RuntimeError, match="boom"):
            with robot as r:
                r.enable()
                r.drive(0.1, 0.0)
                raise RuntimeError("boom")
        with pytest.raises(NotEnabled):
            robot.drive(0.1, 0.0)

    # --- sensing and time -----------------------------------------------------------------------
    def test_capture_stereo(self, robot):
        cam = robot.camera
        f = robot.capture_stereo()
        assert isinstance(f, StereoFrame)
        for img in (f.left, f.right):
            assert img.dtype == np.uint8 and img.shape == (cam.height, cam.width, 3)
        assert f.t <= robot.now() and f.camera == cam and isinstance(f.odom, Pose2D)
        np.testing.assert_allclose(f.G_RC, cam.G_RC(f.pan_tilt.pan, f.pan_tilt.tilt))
        g = robot.capture_stereo(after=f.t)
        assert g.t > f.t

    def test_capture_reports_the_head_state(self, robot):
        robot.enable()
        robot.command_pan_tilt(-0.2, 0.05)
        robot.wait_pan_tilt(timeout=5.0)
        f = robot.capture_stereo(after=robot.now())
        assert f.pan_tilt.pan == pytest.approx(-0.2, abs=0.002) and f.pan_tilt.tilt == pytest.approx(
            0.05, abs=0.002
        )

    def test_step_advances_the_clock(self, robot):
        t0 = robot.now()
        robot.step(0.2)
        assert 0.2 - 1e-9 <= robot.now() - t0 < 0.2 + 0.1
        for bad in (-0.1, math.nan):
            with pytest.raises(ValueError):
                robot.step(bad)
