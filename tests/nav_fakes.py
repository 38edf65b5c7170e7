"""A minimal kinematic robot implementing ``lab.robot.Robot``, for the navigation tests.

A unicycle integrated exactly (arcs) at a fine internal step, with the interface's contract where the
follower meets it: speeds clamped to ``BaseLimits`` and slew-limited by its accelerations, a 0.5 s
command watchdog, ``enable()`` before motion, NaN commands refused. It records every ``drive`` call as
given (before clamping) so tests can check what the follower asked for, and the true trajectory.
"""

from __future__ import annotations

import math

import numpy as np

from lab.errors import NotEnabled
from lab.geometry import Pose2D, wrap_angle
from lab.robot import BaseLimits, PanTiltLimits, PanTiltState, Robot, StereoCamera, check_finite


class KinematicRobot(Robot):
    def __init__(self, pose: Pose2D, limits: BaseLimits | None = None, substeps: int = 5, on_move=None):
        self._limits = limits or BaseLimits()
        self._pose = np.array([pose.x, pose.y, pose.theta], dtype=float)
        self._t = 0.0
        self._v = 0.0
        self._w = 0.0
        self._cmd = (0.0, 0.0)
        self._t_cmd = -math.inf
        self._enabled = False
        self.substeps = substeps
        self.on_move = on_move  # called with the true pose after every substep
        self.commands: list[tuple[float, float, float]] = []  # (t, v, omega) as requested
        self.actual: list[tuple[float, float, float]] = []  # (t, v, omega) executed
        self.trajectory: list[tuple[float, float, float]] = [tuple(self._pose)]
        self.watchdog_trips = 0
        self.bump_count = 0  # a test raises it to make the robot bump

    # -- the interface ---------------------------------------------------------------------------
    @property
    def camera(self) -> StereoCamera:
        return StereoCamera.from_fov()

    @property
    def pan_tilt_limits(self) -> PanTiltLimits:
        return PanTiltLimits()

    @property
    def base_limits(self) -> BaseLimits:
        return self._limits

    def now(self) -> float:
        return self._t

    def enable(self) -> None:
        self._enabled = True

    def disable(self) -> None:
        self.stop()
        self._enabled = False

    @property
    def enabled(self) -> bool:
        return self._enabled

    def capture_stereo(self, after=None):
        raise NotImplementedError("no camera on the kinematic test robot")

    @property
    def bumps(self) -> int:
        return self.bump_count

    def odometry(self) -> Pose2D:
        x, y, th = self._pose
        return Pose2D(float(x), float(y), float(th))

    def pan_tilt(self) -> PanTiltState:
        return PanTiltState(0.0, 0.0, self._t)

    def command_pan_tilt(self, pan, tilt, speed=None) -> None:
        raise NotImplementedError

    def drive(self, v: float, omega: float) -> None:
        check_finite(v=v, omega=omega)
        if not self._enabled:
            raise NotEnabled("drive() before enable()")
        self.commands.append((self._t, float(v), float(omega)))
        lim = self._limits
        self._cmd = (
            min(max(v, -lim.max_speed), lim.max_speed),
            min(max(omega, -lim.max_turn_rate), lim.max_turn_rate),
        )
        self._t_cmd = self._t

    def stop(self) -> None:
        self._cmd = (0.0, 0.0)
        self._v = self._w = 0.0

    def step(self, dt: float) -> None:
        lim = self._limits
        h = dt / self.substeps
        for _ in range(self.substeps):
            if self._t - self._t_cmd > self.cmd_timeout_s:
                if self._cmd != (0.0, 0.0):
                    self.watchdog_trips += 1
                self._cmd = (0.0, 0.0)
            v_c, w_c = self._cmd
            self._v += min(max(v_c - self._v, -lim.max_accel * h), lim.max_accel * h)
            self._w += min(max(w_c - self._w, -lim.max_turn_accel * h), lim.max_turn_accel * h)
            x, y, th = self._pose
            if abs(self._w) > 1e-12:  # exact arc
                th2 = th + self._w * h
                x += self._v / self._w * (math.sin(th2) - math.sin(th))
                y -= self._v / self._w * (math.cos(th2) - math.cos(th))
            else:
                x += self._v * h * math.cos(th)
                y += self._v * h * math.sin(th)
                th2 = th
            self._pose = np.array([x, y, wrap_angle(th2)])
            self._t += h
            self.trajectory.append(tuple(self._pose))
            if self.on_move is not None:
                self.on_move(self.odometry())
        self.actual.append((self._t, self._v, self._w))

    def estop(self) -> None:
        self.stop()
        self._enabled = False

    def clear_estop(self) -> None:
        pass

    def close(self) -> None:
        self.stop()
        self._enabled = False
