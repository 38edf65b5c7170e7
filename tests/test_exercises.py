"""lab.exercises: every check says "correct" to a right answer and, to each typical wrong answer, the
hint that names that mistake (distinct hints per check); a stub is "not attempted yet", not a failure.

The right answers come from the library where it has the function (``lab.localization.models``,
``lab.search.update``, ``lab.estimation``), so these tests also show the library agreeing with the
checks' independent references; the others are written here, never in the notebooks.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from lab import exercises as ex
from lab.estimation import measurement_jacobian as lib_jacobian
from lab.geometry import euler_zyx_to_R, wrap_angle
from lab.localization import models as loc
from lab.search import update as lib_update

# --------------------------------------------------------------------------------------- right answers


def triangulate(uv, disparity, f, cx, cy, baseline):
    uv, d = np.asarray(uv, float), np.asarray(disparity, float)
    Z = f * baseline / d
    return np.column_stack([(uv[:, 0] - cx) * Z / f, (uv[:, 1] - cy) * Z / f, Z])


def project(p, f, cx, cy):
    p = np.asarray(p, float)
    return np.column_stack([f * p[:, 0] / p[:, 2] + cx, f * p[:, 1] / p[:, 2] + cy])


def depth_std(Z, f, baseline, sigma_d):
    return Z**2 * sigma_d / (f * baseline)


def kalman_update(mu_bar, Sigma_bar, y, C, Sigma_m):
    S = C @ Sigma_bar @ C.T + Sigma_m
    K = Sigma_bar @ C.T @ np.linalg.inv(S)
    IKC = np.eye(len(mu_bar)) - K @ C
    return mu_bar + K @ y, IKC @ Sigma_bar @ IKC.T + K @ Sigma_m @ K.T


def entropy(P):
    P = np.asarray(P, float)
    nz = P > 0
    return float(-np.sum(P[nz] * np.log(P[nz])))


def model_probabilities(P, ll):
    w = np.log(P) + ll
    e = np.exp(w - w.max())
    return e / e.sum()


def information_gain(P, lik):
    joint = P[:, None] * lik
    py = joint.sum(axis=0)
    return entropy(P) - sum(py[k] * entropy(joint[:, k] / py[k]) for k in range(lik.shape[1]))


def detection_likelihood(shape, cell, detected, alpha, beta):
    L = np.full(shape, alpha if detected else 1 - alpha)
    L[tuple(cell)] = 1 - beta if detected else beta
    return L


def update_probability_map(P, cell, detected, alpha, beta):
    return lib_update(P, tuple(cell), int(detected), alpha, beta)


def octile(cell, goal, m):
    a, b = abs(cell[0] - goal[0]), abs(cell[1] - goal[1])
    return m * (max(a, b) + (math.sqrt(2) - 1) * min(a, b))


def wheel_speeds(v, omega, track):
    return v - omega * track / 2, v + omega * track / 2


def ramp_distance(v, a, T):
    t_r = min(v / a, T)
    return 0.5 * a * t_r**2 + v * (T - t_r)


def odometry_step(pose, dl, dr, track):
    ds, dth = (dl + dr) / 2, (dr - dl) / track
    x, y, th = pose
    return np.array([x + ds * math.cos(th + dth / 2), y + ds * math.sin(th + dth / 2), th + dth])


def joseph(Sigma_bar, K, H, Q):
    IKH = np.eye(len(Sigma_bar)) - K @ H
    return IKH @ Sigma_bar @ IKH.T + K @ Q @ K.T


# --------------------------------------------------------------------------------------- wrong answers


def _R(a, b, g, order="zyx"):
    from lab.geometry import Rx, Ry, Rz

    return Rz(a) @ Ry(b) @ Rx(g) if order == "zyx" else Rx(g) @ Ry(b) @ Rz(a)


def _jac_sign(X, b):
    C = lib_jacobian(X, b)
    C[:, 4] *= -1
    return C


def _jac_rows(X, b):
    n = len(b)
    return lib_jacobian(X, b).reshape(n, 3, 6).transpose(1, 0, 2).reshape(3 * n, 6)


def _kf_sign(mu_bar, Sb, y, C, Sm):
    mu, S = kalman_update(mu_bar, Sb, y, C, Sm)
    return 2 * mu_bar - mu, S


def _kf_no_noise(mu_bar, Sb, y, C, Sm):
    K = Sb @ C.T @ np.linalg.inv(C @ Sb @ C.T)
    IKC = np.eye(len(mu_bar)) - K @ C
    return mu_bar + K @ y, IKC @ Sb @ IKC.T + K @ Sm @ K.T


def _kf_same_cov(mu_bar, Sb, y, C, Sm):
    return kalman_update(mu_bar, Sb, y, C, Sm)[0], Sb


def _probs_unnormalised(P, ll):
    return P * np.exp(ll)


def _probs_no_prior(P, ll):
    return model_probabilities(np.ones_like(P) / len(P), ll)


def _probs_linear(P, ll):
    p = P * np.exp(ll)
    return p / p.sum()


def _ig_expected(P, lik):
    return entropy(P) - information_gain(P, lik)


def _ig_unweighted(P, lik):
    joint = P[:, None] * lik
    py = joint.sum(axis=0)
    return entropy(P) - np.mean([entropy(joint[:, k] / py[k]) for k in range(lik.shape[1])])


def _motion_world(x, u):
    return np.array([x[0] + u[0], x[1] + u[1], wrap_angle(x[2] + u[2])])


def _motion_transposed(x, u):
    c, s = math.cos(x[2]), math.sin(x[2])
    return np.array([x[0] + c * u[0] + s * u[1], x[1] - s * u[0] + c * u[1], wrap_angle(x[2] + u[2])])


def _motion_unwrapped(x, u):
    m = loc.motion_model(x, u)
    return np.array([m[0], m[1], x[2] + u[2]])


def _meas_transposed(x, l):
    c, s = math.cos(x[2]), math.sin(x[2])
    dX, dY = l[0] - x[0], l[1] - x[1]
    return np.array([c * dX - s * dY, s * dX + c * dY, wrap_angle(l[2] - x[2])])


def _meas_sign(x, l):
    z = loc.measurement_model(x, l)
    return np.array([-z[0], -z[1], z[2]])


def _meas_world(x, l):
    return np.array([l[0] - x[0], l[1] - x[1], wrap_angle(l[2] - x[2])])


def _notimpl(*args):
    raise NotImplementedError


# check, right answer, [(wrong answer, the hint it must get), ...]
CASES = {
    "triangulate": (
        ex.check_triangulate,
        triangulate,
        [
            (lambda uv, d, f, cx, cy, B: triangulate(uv, d, f, cx, cy, B)[:, [1, 0, 2]], "swapped_axes"),
            (lambda uv, d, f, cx, cy, B: triangulate(uv, d, f, 0.0, 0.0, B), "principal_point"),
            (
                lambda uv, d, f, cx, cy, B: triangulate(uv, (f * B) ** 2 / np.asarray(d), f, cx, cy, B),
                "depth_inverted",
            ),
            (lambda uv, d, f, cx, cy, B: 1000 * triangulate(uv, d, f, cx, cy, B), "units"),
            (lambda uv, d, f, cx, cy, B: triangulate(uv, d, f, cx, cy, B).T, "transposed"),
        ],
    ),
    "project": (
        ex.check_project,
        project,
        [
            (lambda p, f, cx, cy: project(p, f, cx, cy)[:, ::-1], "swapped_axes"),
            (lambda p, f, cx, cy: f * np.asarray(p)[:, :2] + [cx, cy], "normalisation"),
            (lambda p, f, cx, cy: project(p, f, 0.0, 0.0), "principal_point"),
        ],
    ),
    "depth_std": (
        ex.check_depth_std,
        depth_std,
        [
            (lambda Z, f, B, s: Z * s / (f * B), "linear"),
            (lambda Z, f, B, s: depth_std(Z, f, B, s) ** 2, "variance"),
            (lambda Z, f, B, s: Z**2 / (f * B), "missing_sigma"),
        ],
    ),
    "rotation_zyx": (
        ex.check_rotation_zyx,
        euler_zyx_to_R,
        [
            (lambda a, b, g: _R(a, b, g).T, "transposed"),
            (lambda a, b, g: _R(a, b, g, order="xyz"), "order"),
            (lambda a, b, g: _R(*np.radians([a, b, g])), "degrees"),
            (lambda a, b, g: _R(a, -b, g), "sign_y"),
        ],
    ),
    "measurement_jacobian": (
        ex.check_measurement_jacobian,
        lib_jacobian,
        [
            (_jac_sign, "sign_beta"),
            (_jac_rows, "row_order"),
            (lambda X, b: lib_jacobian(X, b).T, "transposed"),
            (lambda X, b: np.hstack([np.zeros((3 * len(b), 3)), lib_jacobian(X, b)[:, 3:]]), "translation"),
        ],
    ),
    "kalman_update": (
        ex.check_kalman_update,
        kalman_update,
        [
            (_kf_sign, "innovation_sign"),
            (_kf_no_noise, "missing_noise"),
            (_kf_same_cov, "covariance_unchanged"),
        ],
    ),
    "entropy": (
        ex.check_entropy,
        entropy,
        [
            (lambda P: entropy(P) / math.log(2), "bits"),
            (lambda P: -entropy(P), "sign"),
            (lambda P: -np.sum(P * np.log(P)), "zero_log_zero"),
        ],
    ),
    "model_probabilities": (
        ex.check_model_probabilities,
        model_probabilities,
        [
            (_probs_unnormalised, "normalisation"),
            (_probs_no_prior, "prior"),
            (_probs_linear, "log_space"),
            (lambda P, ll: P * ll / np.sum(P * ll), "not_exponentiated"),
        ],
    ),
    "information_gain": (
        ex.check_information_gain,
        information_gain,
        [
            (_ig_expected, "expected_entropy"),
            (lambda P, L: -information_gain(P, L), "sign"),
            (_ig_unweighted, "weights"),
            (lambda P, L: information_gain(P, L) / math.log(2), "bits"),
        ],
    ),
    "detection_likelihood": (
        ex.check_detection_likelihood,
        detection_likelihood,
        [
            (lambda s, c, y, a, b: detection_likelihood(s, c, y, b, a), "swapped_rates"),
            (lambda s, c, y, a, b: detection_likelihood(s, c, not y, a, b), "outcome"),
            (lambda s, c, y, a, b: detection_likelihood(s, c[::-1], y, a, b), "transposed"),
        ],
    ),
    "update_probability_map": (
        ex.check_map_update,
        update_probability_map,
        [
            (lambda P, c, y, a, b: detection_likelihood(P.shape, c, y, a, b) * P, "normalisation"),
            (lambda P, c, y, a, b: update_probability_map(P, c, y, b, a), "swapped_rates"),
            (lambda P, c, y, a, b: update_probability_map(P, c, not y, a, b), "outcome"),
            (lambda P, c, y, a, b: update_probability_map(P, c[::-1], y, a, b), "transposed"),
        ],
    ),
    "octile_heuristic": (
        ex.check_octile_heuristic,
        octile,
        [
            (lambda c, g, m: m * math.dist(c, g), "euclidean"),
            (lambda c, g, m: m * (abs(c[0] - g[0]) + abs(c[1] - g[1])), "manhattan"),
            (lambda c, g, m: m * max(abs(c[0] - g[0]), abs(c[1] - g[1])), "chebyshev"),
            (lambda c, g, m: octile(c, g, 1.0), "scale"),
        ],
    ),
    "wheel_speeds": (
        ex.check_wheel_speeds,
        wheel_speeds,
        [
            (lambda v, w, t: wheel_speeds(v, w, t)[::-1], "swapped"),
            (lambda v, w, t: wheel_speeds(v, w, 2 * t), "half_track"),
            (lambda v, w, t: tuple(1000 * s for s in wheel_speeds(v, w, t)), "units"),
        ],
    ),
    "ramp_distance": (
        ex.check_ramp_distance,
        ramp_distance,
        [
            (lambda v, a, T: v * T, "no_ramp"),
            (lambda v, a, T: a * min(v / a, T) ** 2 + v * (T - min(v / a, T)), "half"),
            (lambda v, a, T: 0.5 * a * T**2, "no_cap"),
        ],
    ),
    "odometry_step": (
        ex.check_odometry_step,
        odometry_step,
        [
            (lambda p, dl, dr, t: odometry_step(p, dr, dl, t), "swapped"),
            (lambda p, dl, dr, t: odometry_step(p, dl, dr, t / 2), "half_track"),
            (
                lambda p, dl, dr, t: (
                    odometry_step(p, dl, dr, t) + [0, 0, math.degrees((dr - dl) / t) - (dr - dl) / t]
                ),
                "degrees",
            ),
            (lambda p, dl, dr, t: np.asarray(p) + [(dl + dr) / 2, 0.0, (dr - dl) / t], "frame"),
        ],
    ),
    "motion_model": (
        ex.check_motion_model,
        loc.motion_model,
        [(_motion_world, "frame"), (_motion_transposed, "transposed"), (_motion_unwrapped, "wrap")],
    ),
    "landmark_measurement": (
        ex.check_landmark_measurement,
        loc.measurement_model,
        [(_meas_transposed, "transposed"), (_meas_sign, "sign"), (_meas_world, "frame")],
    ),
    "joseph_covariance": (
        ex.check_joseph_covariance,
        joseph,
        [
            (lambda Sb, K, H, Q: (np.eye(3) - K @ H) @ Sb, "short_form"),
            (lambda Sb, K, H, Q: (np.eye(3) - K @ H) @ Sb @ (np.eye(3) - K @ H).T, "missing_noise"),
            (lambda Sb, K, H, Q: (np.eye(3) - K @ H) @ Sb @ (np.eye(3) - K @ H) + K @ Q @ K.T, "transposed"),
        ],
    ),
}


@pytest.mark.parametrize("name", CASES)
def test_a_right_answer_is_correct(name):
    check, right, _ = CASES[name]
    fb = check(right)
    assert fb.correct and fb.status is ex.Status.CORRECT, fb
    assert str(fb).endswith("correct")


WRONG = [
    pytest.param(name, k, id=f"{name}-{hint}")
    for name, (_, _, ws) in CASES.items()
    for k, (_, hint) in enumerate(ws)
]


@pytest.mark.parametrize("name, k", WRONG)
def test_a_typical_mistake_gets_the_hint_that_names_it(name, k):
    check, _, wrongs = CASES[name]
    wrong, hint = wrongs[k]
    fb = check(wrong)
    assert not fb.correct
    assert fb.status is ex.Status.WRONG and fb.hint == hint, fb


@pytest.mark.parametrize("name", CASES)
def test_each_check_has_three_distinct_hints(name):
    _, _, wrongs = CASES[name]
    check = CASES[name][0]
    messages = {check(w).message for w, _ in wrongs}
    assert len(messages) == len(wrongs) >= 3


@pytest.mark.parametrize("name", CASES)
def test_a_stub_is_not_attempted_yet_and_never_raises(name):
    check = CASES[name][0]
    for stub in (_notimpl, lambda *a: None, None):
        fb = check(stub)
        assert fb.status is ex.Status.NOT_ATTEMPTED and "not attempted yet" in fb.message, fb


@pytest.mark.parametrize("name", CASES)
def test_nan_and_errors_fail(name):
    check, right, _ = CASES[name]

    def nan_answer(*args):
        out = right(*args)
        if isinstance(out, tuple):
            return tuple(np.full_like(np.asarray(o, float), np.nan) for o in out)
        return np.full_like(np.asarray(out, float), np.nan)

    fb = check(nan_answer)
    assert not fb.correct, fb

    def boom(*args):
        raise ValueError("operands could not be broadcast")

    fb = check(boom)
    assert fb.status is ex.Status.ERROR and "ValueError: operands could not be broadcast" in fb.message


def test_an_unrecognised_mistake_still_says_wrong_without_a_hint():
    fb = ex.check_entropy(lambda P: 0.3)
    assert fb.status is ex.Status.WRONG and fb.hint is None and fb.message


def test_a_first_order_odometry_step_is_accepted():
    # the old heading instead of the mid-step one: first order, within the 5 mm of these short steps
    def euler(pose, dl, dr, track):
        ds, dth = (dl + dr) / 2, (dr - dl) / track
        return np.array([pose[0] + ds * math.cos(pose[2]), pose[1] + ds * math.sin(pose[2]), pose[2] + dth])

    assert ex.check_odometry_step(euler).correct


def test_the_checks_do_not_write_to_the_students_inputs():
    seen = []

    def keeps(P):
        seen.append(P.copy())
        P[:] = 0.0  # a student's function that scribbles on its input
        return entropy(seen[-1])

    fb = ex.check_entropy(keeps)
    assert fb.correct, fb
