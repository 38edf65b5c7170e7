"""Notebook 04's checks: a differential drive's wheel speeds, the distance of an acceleration ramp and one
odometry step.

See :mod:`lab.exercises` for what a check does and how it avoids carrying the answer.
"""

from __future__ import annotations

import math

import numpy as np

from lab.exercises.feedback import Feedback, Mistake, answer_array, call_answer, checked, close, verdict

__all__ = ["check_wheel_speeds", "check_ramp_distance", "check_odometry_step"]

_TRACK = 0.235  # the Create 2's wheel track [m]
_TWIST_CASES = ((0.2, 0.0), (0.1, 0.8), (0.0, -1.2), (-0.15, 0.4))


@checked
def check_wheel_speeds(wheel_speeds) -> Feedback:
    """Check ``wheel_speeds(v, omega, track) -> (v_left, v_right)`` [m/s] of a differential drive (what
    the Create's Drive Direct command takes, in mm/s) by driving them forward: the base's speed is the
    wheels' mean, its turn rate their difference over the track (counter-clockwise positive)."""
    name = "wheel_speeds"
    got = np.stack(
        [answer_array(name, call_answer(name, wheel_speeds, v, w, _TRACK), (2,)) for v, w in _TWIST_CASES]
    )
    twist = np.column_stack([got.mean(axis=1), (got[:, 1] - got[:, 0]) / _TRACK])  # forward kinematics
    want = np.array(_TWIST_CASES, float)
    mistakes = [
        Mistake(
            "swapped",
            "left and right swapped: the base turns the wrong way (omega > 0 "
            "is counter-clockwise: the right wheel is faster)",
            want * [1, -1],
        ),
        Mistake(
            "half_track",
            "the turn is off by a factor of 2: each wheel is track / 2 from the centre",
            want * [1, 2],
        ),
        Mistake(
            "half_track",
            "the turn is off by a factor of 2: each wheel is track / 2 from the centre",
            want * [1, 0.5],
        ),
        Mistake(
            "units",
            "1000 times too fast: that is mm/s, the Open Interface's unit; this function works in m/s",
            want * 1000,
        ),
    ]
    return verdict(name, twist, want, 1e-9, mistakes, "the wheels do not give the commanded v and omega")


_RAMP_CASES = ((0.2, 0.5, 1.0), (0.3, 0.5, 0.4), (0.2, 1.0, 2.0), (0.4, 0.25, 3.0))


def _integrate_ramp(v, a, T, n=20000):
    dt = T / n
    t = (np.arange(n) + 0.5) * dt
    return float(np.sum(np.minimum(a * t, v)) * dt)  # midpoint rule of the speed profile


@checked
def check_ramp_distance(ramp_distance) -> Feedback:
    """Check ``ramp_distance(v, accel, duration) -> distance`` [m]: a base at rest, commanded to ``v``
    [m/s], speeds up at ``accel`` [m/s^2] until it reaches ``v``; how far has it gone after ``duration``
    [s]? Against a numerical integration of the speed."""
    name = "ramp_distance"
    got = answer_array(name, [call_answer(name, ramp_distance, *c) for c in _RAMP_CASES], (len(_RAMP_CASES),))
    want = np.array([_integrate_ramp(*c) for c in _RAMP_CASES])
    t_r = lambda v, a, T: min(v / a, T)  # noqa: E731
    mistakes = [
        Mistake(
            "no_ramp",
            "the base starts from rest: it needs v / accel seconds to reach v",
            np.array([v * T for v, a, T in _RAMP_CASES]),
        ),
        Mistake(
            "half",
            "the ramp's distance is 1/2 accel t^2 (the mean speed on the ramp is half the final one)",
            np.array([a * t_r(v, a, T) ** 2 + v * (T - t_r(v, a, T)) for v, a, T in _RAMP_CASES]),
        ),
        Mistake(
            "no_cap",
            "the speed stops growing at v: the ramp ends at t = v / accel",
            np.array([0.5 * a * T**2 for v, a, T in _RAMP_CASES]),
        ),
    ]
    return verdict(name, got, want, 1e-6, mistakes, "not the distance of a ramp to v, then constant speed")


_ODOM_CASES = (((1.0, 2.0, 2.0), 0.05, 0.07), ((-0.5, 0.3, -0.4), 0.06, 0.03), ((0.0, 0.0, 3.0), 0.04, 0.05))


def _integrate_odometry(pose, dl, dr, track, n=2000):
    x, y, th = map(float, pose)
    ds, dth = (dl + dr) / 2 / n, (dr - dl) / track / n
    for _ in range(n):
        x, y, th = x + ds * math.cos(th + dth / 2), y + ds * math.sin(th + dth / 2), th + dth
    return np.array([x, y, th])


@checked
def check_odometry_step(odometry_step) -> Feedback:
    """Check ``odometry_step(pose, d_left, d_right, track) -> new_pose``: the pose ``(x, y, theta)`` [m, m,
    rad] in the world after the wheels rolled ``d_left``, ``d_right`` [m], against a fine numerical
    integration of the arc. A first-order step (the old or the mid heading) is within the tolerance of
    5 mm for these short steps; the heading is not wrapped here."""
    name = "odometry_step"
    got = np.stack(
        [
            answer_array(name, call_answer(name, odometry_step, np.array(p), dl, dr, _TRACK), (3,))
            for p, dl, dr in _ODOM_CASES
        ]
    )
    want = np.stack([_integrate_odometry(p, dl, dr, _TRACK) for p, dl, dr in _ODOM_CASES])
    tol = 5e-3
    mistakes = [
        Mistake(
            "swapped",
            "left and right swapped: the robot turns the wrong way (right wheel further: counter-clockwise)",
            np.stack([_integrate_odometry(p, dr, dl, _TRACK) for p, dl, dr in _ODOM_CASES]),
        ),
        Mistake(
            "half_track",
            "the turn is off by a factor of 2: the heading changes by (d_right - d_left) / track",
            np.stack([_integrate_odometry(p, dl, dr, _TRACK / 2) for p, dl, dr in _ODOM_CASES]),
        ),
        Mistake(
            "degrees",
            "the heading is in radians: do not convert the turn to degrees",
            test=lambda g: close(
                g[:, 2], [p[2] + math.degrees((dr - dl) / _TRACK) for p, dl, dr in _ODOM_CASES], tol
            ),
        ),
        Mistake(
            "frame",
            "the distance is along the robot's heading: rotate it into the world (cos theta, sin theta)",
            np.stack([np.array(p) + [(dl + dr) / 2, 0.0, (dr - dl) / _TRACK] for p, dl, dr in _ODOM_CASES]),
        ),
    ]
    return verdict(name, got, want, tol, mistakes, "not where the wheels took the robot")
