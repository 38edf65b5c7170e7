"""The real robot: :class:`HardwareRobot` implements :class:`lab.robot.Robot` on a Create 2, a PTU-D46
and a stereo camera, with the same safety contract as the simulator.

Threads and timing (the simulator's sub-step, done in real time):

* the user's thread calls ``drive``, which only checks the values and stores a *target* velocity;
* a servo thread (``[robot] servo_rate_hz``, 50 Hz) slews the sent velocity towards the target within the
  acceleration limits (``BaseLimits.max_accel``, ``max_turn_accel``), converts it to wheel speeds (scaled
  together so neither wheel exceeds ``max_speed``) and writes Drive Direct when it changes;
* the same thread is the **watchdog**: it sleeps until ``last drive + cmd_timeout_s - watchdog_lead_s``
  (0.1 s early, so that the zero reaches the base within the contract's 0.5 s with a margin for the
  thread's wake-up and the serial line) and then sends a zero Drive Direct at once (no slew: it is a
  stop, not a manoeuvre), and it turns device events (a safety trip seen in the Create's stream, a lost
  port) into robot state;
* ``step(dt)`` sleeps to a monotonic deadline and raises as soon as a trip or a lost device is seen.

States (``state``): "disconnected" -> ``connect()`` -> "connected" -> ``enable()`` -> "enabled";
"faulted" after a safety trip (until ``enable()``); "estopped" while the e-stop is latched; "stale" while
the Create's sensor stream is stale (no cliff detection: the base is stopped and ``drive`` refused; it
comes back by itself when the stream does); a lost
device makes it "disconnected" until ``reconnect()``, after which it is "connected" (disabled).

Stops happen on ``stop()``, ``disable()``, ``estop()``, ``close()``, ``with``-block exit (also on an
exception), interpreter exit (``atexit``), Ctrl-C / a notebook's "interrupt kernel" (a SIGINT hook that
asks the servo thread to send zero, then lets the KeyboardInterrupt through), and the watchdog.
"""

from __future__ import annotations

import collections
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from lab.errors import (
    CommandRejected,
    ConfigError,
    ConnectionLost,
    DeviceTimeout,
    EStopActive,
    NotEnabled,
    ProtocolError,
    SafetyStop,
)
from lab.geometry import Pose2D
from lab.hardware import stop_hooks
from lab.hardware.camera import StereoRectifier, StereoSource, load_camera_calibration, make_camera_source
from lab.hardware.config import HardwareConfig, load_config
from lab.hardware.create2 import BaseSensors, Create2
from lab.hardware.frame_time import pan_tilt_at, pose_at
from lab.hardware.ptu import PTUD46
from lab.robot import BaseLimits, PanTiltLimits, PanTiltState, Robot, StereoCamera, StereoFrame, check_finite

__all__ = ["HardwareRobot", "HardwareState", "RobotEvent"]


@dataclass(frozen=True)
class RobotEvent:
    """Something the robot reports: ``kind`` in bump, safety_stop, limit_hit, watchdog, stale,
    stream_resumed, connection_lost, estop; ``t`` on the robot's clock."""

    t: float
    kind: str
    message: str


@dataclass(frozen=True)
class HardwareState:
    """A snapshot for diagnostics (``read_state()``); it never blocks on a device."""

    t: float
    state: str
    base: BaseSensors | None
    odom: Pose2D
    v_target: float
    omega_target: float
    v_sent: float
    omega_sent: float
    stale: bool
    safety_trip: str | None
    faults: frozenset[str] = frozenset()
    counters: dict = field(default_factory=dict)


class HardwareRobot(Robot):
    """The real robot (or the emulators) behind the :class:`lab.robot.Robot` interface.

    Parameters
    ----------
    config : HardwareConfig or path to a TOML file
    camera_source : StereoSource, optional
        Replaces the camera the config describes (tests use a :class:`ReplayStereoSource`). Its images must
        have the calibration's size. The robot closes it on ``close()``.
    connect : bool
        Connect at once (default) or leave it to :meth:`connect`.
    on_event : callable(RobotEvent), optional
        Called from a driver or servo thread; keep it short.

    Raises
    ------
    ConfigError
        Bad configuration or calibration (before any port is opened).
    PortUnavailable, DeviceTimeout, ProtocolError
        From ``connect()``.
    """

    is_simulated = False
    #: the watchdog fires this long before ``cmd_timeout_s`` [s], so that its stop arrives within it
    watchdog_lead_s = 0.1

    def __init__(
        self,
        config: HardwareConfig | str | Path,
        *,
        camera_source: StereoSource | None = None,
        connect: bool = True,
        on_event: Callable[[RobotEvent], None] | None = None,
    ):
        cfg = config if isinstance(config, HardwareConfig) else load_config(config)
        self.config = cfg
        self.cmd_timeout_s = cfg.robot.cmd_timeout_s
        self.on_event = on_event
        self.events: collections.deque[RobotEvent] = collections.deque(maxlen=1000)
        c = cfg.camera
        size = (c.width, c.height)
        calib = load_camera_calibration(cfg)
        if camera_source is not None and tuple(camera_source.image_size) != size:
            raise ConfigError(
                f"camera source delivers {camera_source.image_size[0]}x{camera_source.image_size[1]} images "
                f"but [camera] width/height and the calibration say {size[0]}x{size[1]}"
            )
        self.calibration = calib
        self._rectifier = StereoRectifier(calib)
        cam = calib.camera_model(c.mount_R, c.camera_offset_P)  # pointing: the pan-tilt's step
        pointing = math.hypot(cam.pointing_std_deg, c.mount_sigma_deg)  # and the brackets, as stated
        self._camera = replace(cam, pointing_std_deg=pointing, blur_sigma_px=c.blur_sigma_px)
        self._given_source = camera_source
        self._source: StereoSource | None = None
        b = cfg.base
        self._base_limits = BaseLimits(
            b.max_speed, b.max_turn_rate, b.max_accel, b.max_turn_accel, b.wheel_base, b.radius
        )
        self.base = Create2.from_config(b, on_event=self._device_event)
        self.ptu = PTUD46.from_config(cfg.ptu, on_event=self._device_event)
        self._pt_limits: PanTiltLimits | None = None
        self._lock = threading.RLock()
        self._wake = threading.Event()
        self._servo_stop = threading.Event()
        self._servo: threading.Thread | None = None
        self._connected = False
        self._closed = False
        self._enabled = False
        self._estop = False
        self._trip: str | None = None
        self._lost: ConnectionLost | None = None
        self._v_target = self._w_target = 0.0
        self._v_out = self._w_out = 0.0
        self._last_cmd_t = -math.inf
        self._stop_requested = False
        self.watchdog_stops = 0
        stop_hooks.register(self, sigint=cfg.robot.install_sigint_handler)
        if connect:
            self.connect()

    @classmethod
    def from_config(
        cls, path: str | Path, *, base_port: str | None = None, ptu_port: str | None = None, **kw
    ):
        """Load a TOML config, optionally pointing it at other ports (e.g. the emulators')."""
        return cls(load_config(path).with_ports(base=base_port, ptu=ptu_port), **kw)

    # --- lifecycle ------------------------------------------------------------------------------
    def connect(self) -> None:
        """Open the camera, the PTU and the base; start the servo thread. The robot comes up disabled."""
        if self._closed:
            raise NotEnabled("the robot is closed; create a new one")
        if self._connected:
            return
        try:
            if self._source is None:
                self._source = self._given_source or make_camera_source(self.config)
            self.ptu.connect()
            self._pt_limits = self.ptu.limits
            self.base.connect()
        except BaseException:
            self._release_devices(send=True)
            raise
        with self._lock:
            self._connected = True
            self._lost = None
            self._trip = None
            self._enabled = False
            self._v_target = self._w_target = self._v_out = self._w_out = 0.0
        self._servo_stop.clear()
        self._servo = threading.Thread(target=self._servo_loop, name="robot servo/watchdog", daemon=True)
        self._servo.start()

    def reconnect(self) -> None:
        """After a lost device: close what is left, connect everything again; comes back disabled."""
        if self._closed:
            raise NotEnabled("the robot is closed; create a new one")
        self._stop_servo()
        self._release_devices(send=True, camera=False)
        with self._lock:
            self._connected = False
        self.connect()

    def close(self) -> None:
        """Stop the base and the head, release the ports and the camera. Safe to call twice."""
        if self._closed:
            return
        with self._lock:
            self._closed = True
            self._enabled = False
            self._v_target = self._w_target = self._v_out = self._w_out = 0.0
        self._stop_servo()
        self._release_devices(send=True)
        self._connected = False
        stop_hooks.unregister(self)

    def _stop_servo(self) -> None:
        self._servo_stop.set()
        self._wake.set()
        if self._servo is not None and self._servo is not threading.current_thread():
            self._servo.join(timeout=2.0)
        self._servo = None

    def _release_devices(self, send: bool, camera: bool = True) -> None:
        for dev in (self.base, self.ptu):
            try:
                dev.close() if send else dev.release_port()
            except Exception:
                pass
        if camera and self._source is not None:
            try:
                self._source.close()
            except Exception:
                pass
            self._source = None

    # --- Robot: description -----------------------------------------------------------------------
    @property
    def camera(self) -> StereoCamera:
        return self._camera

    @property
    def pan_tilt_limits(self) -> PanTiltLimits:
        if self._pt_limits is None:
            raise NotEnabled("pan-tilt limits are read from the unit at connect(); connect first")
        return self._pt_limits

    @property
    def base_limits(self) -> BaseLimits:
        return self._base_limits

    def now(self) -> float:
        return time.monotonic()

    @property
    def state(self) -> str:
        """ "disconnected", "connected", "enabled", "stale", "faulted" or "estopped"."""
        with self._lock:
            if self._closed or self._lost is not None or not self._connected:
                return "disconnected"
            if self._estop:
                return "estopped"
            if self._trip is not None:
                return "faulted"
            if self.base.stale:
                return "stale"
            return "enabled" if self._enabled else "connected"

    @property
    def enabled(self) -> bool:
        return self.state == "enabled"

    # --- Robot: arming ----------------------------------------------------------------------------
    def _check_open(self) -> None:
        if self._closed:
            raise NotEnabled("the robot is closed; create a new one")
        if self._lost is not None:
            raise self._lost
        if not self._connected:
            raise NotEnabled("the robot is not connected: call connect()")

    def _check_motion_allowed(self) -> None:
        self._check_open()
        self._poll_devices()
        if self._lost is not None:
            raise self._lost
        if self._trip is not None:
            raise SafetyStop(f"safety stop ({self._trip}): the base stopped itself; call enable() to re-arm")
        if self._estop:
            raise EStopActive("emergency stop is latched: call clear_estop() and then enable()")
        if not self._enabled:
            raise NotEnabled("motors are disabled: call enable() first")

    def enable(self) -> None:
        """Arm: Create to Safe mode (Full only if configured), confirmed by its stream."""
        self._check_open()
        if self._estop:
            raise EStopActive("emergency stop is latched: call clear_estop() before enable()")
        try:
            self.base.enable()
        except ConnectionLost as e:
            self._on_lost(e)
            raise
        with self._lock:
            self._trip = None
            self._v_target = self._w_target = self._v_out = self._w_out = 0.0
            self._last_cmd_t = -math.inf
            self._enabled = True

    def disable(self) -> None:
        """Stop and disarm (Create back to Passive). Motion commands then raise NotEnabled."""
        with self._lock:
            self._enabled = False
        self.stop()
        if self.base.connected:
            try:
                self.base.disable()
            except (ConnectionLost, DeviceTimeout):
                pass

    # --- Robot: motion ----------------------------------------------------------------------------
    def drive(self, v: float, omega: float) -> None:
        """Target ``v`` [m/s], ``omega`` [rad/s]; clamped, slewed, and held until the watchdog expires."""
        check_finite(v=v, omega=omega)
        self._check_motion_allowed()
        if self.base.stale:
            raise DeviceTimeout(
                f"no sensor stream from the Create 2 on {self.base.port}: base stopped; check the cable"
            )
        L = self._base_limits
        with self._lock:
            self._v_target = float(np.clip(v, -L.max_speed, L.max_speed))
            self._w_target = float(np.clip(omega, -L.max_turn_rate, L.max_turn_rate))
            self._last_cmd_t = time.monotonic()
        self._wake.set()

    def set_wheel_speeds(self, left: float, right: float) -> None:
        """Wheel speeds [m/s] (converted to ``drive(v, omega)``; same clamps, slew and watchdog)."""
        check_finite(left=left, right=right)
        b = self._base_limits.wheel_base
        self.drive(0.5 * (left + right), (right - left) / b)

    def stop(self) -> None:
        """Zero the base at once (no slew) and halt the head where it is. Never raises for state."""
        with self._lock:
            self._v_target = self._w_target = self._v_out = self._w_out = 0.0
        if self._closed:
            return
        self._halt_devices()

    def _halt_devices(self) -> None:
        """Best effort: zero the base and halt the head on whichever device is still connected."""
        if self.base.connected:
            try:
                self.base.stop()
            except (ConnectionLost, DeviceTimeout):
                pass
        if self.ptu.connected:
            try:
                self.ptu.halt()
            except (ConnectionLost, DeviceTimeout, ProtocolError, CommandRejected):
                pass

    def estop(self) -> None:
        """Stop everything and latch: Create zero + Passive (it then ignores drive commands), PTU halted."""
        with self._lock:
            self._estop = True
            self._enabled = False
        self.stop()
        if self.base.connected:
            try:
                self.base.disable()
            except (ConnectionLost, DeviceTimeout):
                pass
        self._emit("estop", "emergency stop latched")

    def clear_estop(self) -> None:
        """Release the latch; the robot stays disabled until ``enable()``."""
        with self._lock:
            self._estop = False

    def step(self, dt: float) -> None:
        """Wait ``dt`` [s] (monotonic deadline); raises SafetyStop/ConnectionLost as soon as one happens."""
        check_finite(dt=dt)
        if dt < 0:
            raise ValueError(f"dt must be >= 0 s, got {dt}")
        self._check_open()
        t_end = time.monotonic() + float(dt)
        while True:
            self._poll_devices()
            if self._lost is not None:
                raise self._lost
            if self._trip is not None:
                raise SafetyStop(
                    f"safety stop ({self._trip}): the base stopped itself; call enable() to re-arm"
                )
            left = t_end - time.monotonic()
            if left <= 0:
                return
            time.sleep(min(left, 0.01))

    # --- Robot: pan-tilt --------------------------------------------------------------------------
    def pan_tilt(self) -> PanTiltState:
        self._check_open()
        try:
            steps = self.ptu.get_steps()
        except ConnectionLost as e:
            self._on_lost(e)
            raise
        tp, tt = self.ptu.target_steps["P"], self.ptu.target_steps["T"]
        return PanTiltState(
            self.ptu.to_rad("P", steps["P"]),
            self.ptu.to_rad("T", steps["T"]),
            time.monotonic(),
            self.ptu.to_rad("P", tp),
            self.ptu.to_rad("T", tt),
            steps["P"] != tp or steps["T"] != tt,
        )

    def command_pan_tilt(self, pan: float, tilt: float, speed: float | None = None) -> None:
        self.set_pan_tilt(pan, tilt, speed=speed)

    def set_pan_tilt(
        self,
        pan: float,
        tilt: float,
        *,
        speed: float | None = None,
        wait: bool = False,
        timeout: float | None = None,
    ) -> None:
        """Move the head; with ``wait``, block (bounded) until it arrives. LimitError: nothing is sent."""
        check_finite(pan=pan, tilt=tilt, **({} if speed is None else {"speed": speed}))
        self.pan_tilt_limits.check(float(pan), float(tilt))
        if speed is not None:
            self.pan_tilt_limits.check_speed(float(speed))
        self._check_motion_allowed()
        try:
            self.ptu.set_pan_tilt(pan, tilt, speed=speed, wait=wait, timeout=timeout)
        except ConnectionLost as e:
            self._on_lost(e)
            raise

    def home_pan_tilt(self, timeout: float = 30.0) -> None:
        """Reset the PTU (both axes run to their limits and back to 0); clears ``needs_home``."""
        self._check_motion_allowed()
        self.ptu.home(timeout)

    # --- Robot: sensing ---------------------------------------------------------------------------
    def capture_stereo(self, after: float | None = None) -> StereoFrame:
        """A rectified RGB pair with the pan-tilt state and odometry at capture.

        A camera failure raises ConnectionLost/DeviceTimeout for the camera only; base and head keep working.
        """
        self._check_open()
        if after is not None:
            check_finite(after=after)
        pt0, odom0 = self.pan_tilt(), (time.monotonic(), self.odometry())
        raw = self._source.read(after=after)
        pt1, odom1 = self.pan_tilt(), (time.monotonic(), self.odometry())
        left, right = self._rectifier.rectify(raw.left, raw.right)
        return StereoFrame(
            raw.t, left, right, self._camera, pan_tilt_at(raw.t, pt0, pt1), pose_at(raw.t, odom0, odom1)
        )

    @property
    def bumps(self) -> int:
        """Bumper presses (packet 7, left or right, counted on the rising edge) since the robot was made."""
        return self.base.bump_count

    def odometry(self) -> Pose2D:
        """Wheel odometry since the first connect (kept across reconnects; motion while unplugged is lost)."""
        return self.base.odometry()

    def read_state(self) -> HardwareState:
        with self._lock:
            faults = set()
            if self._trip:
                faults.add(f"safety_stop: {self._trip}")
            if self._lost:
                faults.add(f"connection_lost: {self._lost}")
            if self.base.stale:
                faults.add("stale_stream")
            if self.ptu.needs_home:
                faults.add("ptu_needs_home")
            return HardwareState(
                time.monotonic(),
                self.state,
                self.base.sensors(),
                self.base.odometry(),
                self._v_target,
                self._w_target,
                self._v_out,
                self._w_out,
                self.base.stale,
                self._trip,
                frozenset(faults),
                {
                    "watchdog_stops": self.watchdog_stops,
                    "corrupt_frames": self.base.corrupt_frames,
                    "frames": self.base.frames,
                    **self.base.counters,
                    **{f"ptu_{k}": v for k, v in self.ptu.counters.items()},
                    "ptu_limit_hits": self.ptu.limit_hits,
                },
            )

    # --- internals --------------------------------------------------------------------------------
    def _emit(self, kind: str, message: str) -> None:
        ev = RobotEvent(time.monotonic(), kind, message)
        self.events.append(ev)
        if self.on_event is not None:
            try:
                self.on_event(ev)
            except Exception:
                pass

    def _device_event(self, kind: str, message: str) -> None:
        self._emit(kind, message)
        if kind in ("safety_stop", "connection_lost"):
            self._wake.set()

    def request_stop(self) -> None:
        """Zero the velocity targets and wake the servo thread, which sends the zero: safe from a signal
        handler (no I/O here)."""
        self._v_target = self._w_target = self._v_out = self._w_out = 0.0
        self._stop_requested = True
        self._wake.set()

    def _poll_devices(self) -> None:
        if self.base.lost is not None and self._lost is None:
            self._on_lost(self.base.lost)
        trip = self.base.safety_trip
        if trip is not None and self._trip is None and self._connected and not self._closed:
            with self._lock:
                self._trip = trip
                self._enabled = False
                self._v_target = self._w_target = self._v_out = self._w_out = 0.0

    def _on_lost(self, err: ConnectionLost) -> None:
        """A device went away: stop what can still be reached, refuse commands until reconnect()."""
        with self._lock:
            if self._lost is not None:
                return
            self._lost = err
            self._enabled = False
            self._v_target = self._w_target = self._v_out = self._w_out = 0.0
        self._halt_devices()

    def _servo_loop(self) -> None:
        period = 1.0 / self.config.robot.servo_rate_hz
        last = time.monotonic()
        while not self._servo_stop.is_set():
            now = time.monotonic()
            try:
                self._servo_once(now, now - last)
            except Exception as e:  # the watchdog must survive anything
                self._emit("servo_error", repr(e))
            last = now
            with self._lock:
                wait = period
                if self._v_target or self._w_target or self._v_out or self._w_out:
                    wait = min(wait, max(0.0, self._last_cmd_t + self._watchdog_s - time.monotonic()))
            self._wake.wait(wait)
            self._wake.clear()

    @property
    def _watchdog_s(self) -> float:
        return max(self.cmd_timeout_s - self.watchdog_lead_s, 0.5 * self.cmd_timeout_s)

    def _servo_once(self, now: float, dt: float) -> None:
        self._poll_devices()
        if self._lost is not None:
            return
        with self._lock:
            if self._stop_requested:
                self._stop_requested = False
                self._send(0.0, 0.0, force=True)
                return
            if not self._enabled or self._trip is not None or self._estop:
                self._v_out = self._w_out = 0.0
                return
            moving = self._v_target or self._w_target or self._v_out or self._w_out
            if moving and now - self._last_cmd_t >= self._watchdog_s:
                self._v_target = self._w_target = self._v_out = self._w_out = 0.0
                self.watchdog_stops += 1
                self._send(0.0, 0.0, force=True)
                self._emit("watchdog", f"no drive command for {self.cmd_timeout_s:.2f} s: base stopped")
                return
            if self.base.stale:
                self._v_target = self._w_target = self._v_out = self._w_out = 0.0
                return
            L = self._base_limits
            self._v_out += float(np.clip(self._v_target - self._v_out, -L.max_accel * dt, L.max_accel * dt))
            self._w_out += float(
                np.clip(self._w_target - self._w_out, -L.max_turn_accel * dt, L.max_turn_accel * dt)
            )
            self._send(self._v_out, self._w_out)

    def _send(self, v: float, w: float, force: bool = False) -> None:
        b = self._base_limits.wheel_base
        left, right = v - 0.5 * w * b, v + 0.5 * w * b
        m = max(abs(left), abs(right))
        vmax = self._base_limits.max_speed
        if m > vmax:  # scale both wheels: keeps the curvature, never exceeds a wheel's limit
            left, right = left * vmax / m, right * vmax / m
        r_mm, l_mm = round(right * 1000.0), round(left * 1000.0)
        if not force and (r_mm, l_mm) == self.base.last_sent_mm_s:
            return
        try:
            if r_mm == 0 and l_mm == 0:
                self.base.stop()
            else:
                self.base.drive_direct(r_mm, l_mm)
        except ConnectionLost:
            pass  # the reader thread reports it; _poll_devices turns it into state
        except (SafetyStop, NotEnabled, DeviceTimeout):
            self._v_out = self._w_out = self._v_target = self._w_target = 0.0
