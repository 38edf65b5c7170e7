"""The simulated robot: kinematics against ground truth, limits, watchdog, e-stop, collisions, odometry."""

import math

import numpy as np
import pytest

from lab.errors import EStopActive, LimitError, NotEnabled, SafetyStop
from lab.geometry import Pose2D
from lab.sim import OdometryNoise, SimRobot, SimWorld


@pytest.fixture
def robot():
    with SimWorld("arena") as w:
        r = SimRobot(w, start=Pose2D(0.0, 0.0, 0.0), odometry_noise=OdometryNoise.none())
        r.enable()
        yield r


def test_drives_a_circle_arc_exactly_without_noise(robot):
    v, omega = 0.3, 0.5
    for _ in range(10):  # let the velocity slew to the command (accel limits), inside the watchdog
        robot.drive(v, omega)
        robot.step(0.1)
    start = robot.world.truth.robot_pose()
    for _ in range(20):
        robot.drive(v, omega)
        robot.step(0.1)
    end = robot.world.truth.robot_pose()
    # on an arc of radius v/omega the heading advances by omega*T and the chord is 2R sin(omega T/2)
    T = 2.0
    assert end.theta - start.theta == pytest.approx(omega * T, abs=1e-9)
    chord = math.hypot(end.x - start.x, end.y - start.y)
    assert chord == pytest.approx(2 * v / omega * math.sin(omega * T / 2), rel=1e-9)
    assert robot.odometry() == end  # noiseless odometry is the truth


def test_velocity_is_clamped_and_slew_limited(robot):
    L = robot.base_limits
    robot.drive(10.0, 0.0)
    robot.step(0.1)
    p1 = robot.world.truth.robot_pose()
    # after 0.1 s at max_accel the speed is at most 0.05 m/s: distance <= a t^2 / 2
    assert p1.x <= 0.5 * L.max_accel * 0.1**2 + 1e-12
    for _ in range(30):
        robot.drive(10.0, 0.0)
        robot.step(0.1)
    p2 = robot.world.truth.robot_pose()
    robot.drive(10.0, 0.0)
    robot.step(0.1)
    assert (robot.world.truth.robot_pose().x - p2.x) == pytest.approx(L.max_speed * 0.1, rel=1e-9)


def test_watchdog_stops_the_base_after_half_a_second(robot):
    robot.drive(0.4, 0.0)
    robot.step(0.5)
    x_cmd = robot.world.truth.robot_pose().x
    robot.step(0.3)  # no new command; the watchdog fires at 0.5 s after the command and the base brakes
    robot.step(2.0)
    x1 = robot.world.truth.robot_pose().x
    robot.step(1.0)
    assert robot.world.truth.robot_pose().x == x1  # stopped
    # it kept going for at most the watchdog time plus the braking distance
    assert x1 - x_cmd < 0.4 * 0.5 + 0.4**2 / (2 * robot.base_limits.max_accel) + 1e-9


def test_bad_commands_are_refused_before_anything_moves(robot):
    for bad in (float("nan"), float("inf"), None, "1", True):
        with pytest.raises((ValueError, TypeError)):
            robot.drive(bad, 0.0)
        with pytest.raises((ValueError, TypeError)):
            robot.command_pan_tilt(0.0, bad)
    with pytest.raises(LimitError, match=r"pan 170.0 deg is outside \[-158.9, 158.9\]"):
        robot.command_pan_tilt(math.radians(170), 0.0)
    with pytest.raises(LimitError, match="tilt"):
        robot.command_pan_tilt(0.0, math.radians(-60))
    robot.step(1.0)
    assert robot.world.truth.robot_pose() == Pose2D(0.0, 0.0, 0.0)
    assert robot.pan_tilt().pan == 0.0


def test_enable_estop_and_safety_trip_are_latched(robot):
    robot.estop()
    with pytest.raises(EStopActive):
        robot.drive(0.1, 0.0)
    with pytest.raises(EStopActive):
        robot.enable()
    robot.clear_estop()
    with pytest.raises(NotEnabled):
        robot.drive(0.1, 0.0)
    robot.enable()
    robot.drive(0.1, 0.0)
    robot.trip_safety("cliff")
    with pytest.raises(SafetyStop, match="cliff"):
        robot.step(0.1)
    with pytest.raises(SafetyStop):
        robot.drive(0.1, 0.0)
    robot.enable()  # the user re-arms explicitly; nothing re-arms by itself
    robot.drive(0.1, 0.0)
    robot.close()
    robot.close()
    with pytest.raises(NotEnabled):
        robot.drive(0.1, 0.0)


def test_pan_tilt_moves_at_its_speed():
    with SimWorld("arena") as w:
        r = SimRobot(w, pan_tilt_speed=math.radians(60))
        r.enable()
        r.command_pan_tilt(math.radians(90), math.radians(-30))
        r.step(1.0)
        s = r.pan_tilt()
        assert s.pan == pytest.approx(math.radians(60)) and s.moving
        assert s.tilt == pytest.approx(math.radians(-30))
        s = r.wait_pan_tilt()
        assert s.pan == pytest.approx(math.radians(90)) and not s.moving


def test_a_swing_across_the_whole_pan_range_is_waited_for():
    """From one end of the pan range to the other at the default speed (5.3 s): the default wait covers
    it; a wait shorter than the swing is a DeviceTimeout, as on a stuck unit."""
    from lab.errors import DeviceTimeout

    with SimWorld("arena") as w:
        r = SimRobot(w)
        r.enable()
        lim = r.pan_tilt_limits
        r.command_pan_tilt(lim.pan_min, 0.0)
        r.wait_pan_tilt()
        r.command_pan_tilt(lim.pan_max, 0.0)
        t0 = r.now()
        s = r.wait_pan_tilt()
        assert s.pan == pytest.approx(lim.pan_max, abs=1e-3) and r.now() - t0 > 5.0
        r.command_pan_tilt(lim.pan_min, 0.0)
        with pytest.raises(DeviceTimeout, match="pan-tilt did not reach its target within 2.0 s"):
            r.wait_pan_tilt(timeout=2.0)


def test_collision_stops_the_base_and_is_counted():
    with SimWorld("lab_room") as w:
        crate = w.scene.body("crate")
        r = SimRobot(
            w, start=Pose2D(crate.pose[0] - 1.2, crate.pose[1], 0.0), odometry_noise=OdometryNoise.none()
        )
        r.enable()
        for _ in range(60):
            r.drive(0.3, 0.0)
            r.step(0.1)
        p = w.truth.robot_pose()
        assert r.collisions == 1 and w.truth.collisions == 1
        assert p.x < crate.pose[0] - 0.25  # never inside the crate (half-size 0.25 m, rotated)
        assert not w.p.getClosestPoints(w.body_id("robot"), w.body_id("crate"), 0.0)


def test_odometry_drifts_reproducibly_with_its_seed():
    def run(seed):
        with SimWorld("arena") as w:
            r = SimRobot(w, start=Pose2D(-3.0, 0.0, 0.0), seed=seed)
            r.enable()
            for _ in range(60):
                r.drive(0.4, 0.2)
                r.step(0.1)
            return r.odometry(), w.truth.robot_pose()

    (o1, t1), (o2, _), (o3, _) = run(1), run(1), run(2)
    assert o1 == o2 and o1 != o3
    err = math.hypot(o1.x - t1.x, o1.y - t1.y)
    assert 1e-4 < err < 0.15  # it drifts, and by a plausible amount over ~2 m


def test_carrier_moves_the_box_with_it():
    from lab.sim import load_box_models

    with SimWorld("arena") as w:
        c = w.add_carrier(load_box_models()[0], Pose2D(1.0, 0.0, 0.0), box_yaw=0.5)
        c.set_velocity(0.1, 0.0)
        w.step(2.0)
        G = w.truth.G_W("target")
        np.testing.assert_allclose(G[:3, 3], [1.2, 0.0, c.HEIGHT + 0.14], atol=1e-9)
        assert math.atan2(G[1, 0], G[0, 0]) == pytest.approx(0.5)
