r"""Checks that answer back: the notebooks' exercises, and the assignments' public tests.

Every check takes the student's answer, a function, runs it on inputs of its own and returns a
:class:`Feedback`: "correct", or a hint that names the mistake it recognises (a wrong sign, transposed
axes, degrees where radians are wanted, a missing normalisation, ...). A stub that still raises
``NotImplementedError`` (or returns ``None``/``...``) gets "not attempted yet", so a notebook with its
exercises untouched runs to the end.

The checks do not carry the answer. Each compares the student's output, within a tolerance, with a
value computed by an *independent* method on the same inputs: OpenCV's triangulation and projection,
SciPy's rotations, softmax and entropy, finite differences, the information form of the Kalman update,
networkx's shortest paths, a fine numerical integration, products of homogeneous matrices. A NaN fails
every tolerance (``not (err <= tol)``). The hints come from running the same independent reference with
the mistake made on purpose (``R.T`` for "transposed", ``np.radians`` of the input for "degrees") and
comparing again.

The functions' signatures are those of the assignments (``assignments/*/``), so a notebook exercise
prepares its assignment and the public tests can call the same check:

==========================  ===========  ======================================================
check                       notebook     the student's function
==========================  ===========  ======================================================
:func:`check_triangulate`   00, stereo   ``triangulate(uv, disparity, f, cx, cy, baseline)``
:func:`check_project`       00, stereo   ``project(points_C, f, cx, cy)``
:func:`check_depth_std`     00, stereo   ``depth_std(Z, f, baseline, sigma_disparity)``
:func:`check_rotation_zyx`  01, ekf      ``rotation_zyx(alpha, beta, gamma)``
:func:`check_measurement_jacobian`  01   ``measurement_jacobian(X, b_O)``
:func:`check_kalman_update` 01, ekf      ``kalman_update(mu_bar, Sigma_bar, y, C, Sigma_m)``
:func:`check_entropy`       02, planning ``entropy(P)``
:func:`check_model_probabilities`  02    ``model_probabilities(P_prior, log_likelihood)``
:func:`check_information_gain`     02    ``information_gain(P, likelihood)``
:func:`check_detection_likelihood` 03    ``detection_likelihood(shape, cell, detected, alpha, beta)``
:func:`check_map_update`    03, search   ``update_probability_map(P, cell, detected, alpha, beta)``
:func:`check_octile_heuristic`     03    ``octile_heuristic(cell, goal, min_cost)``
:func:`check_wheel_speeds`  04           ``wheel_speeds(v, omega, track)``
:func:`check_ramp_distance` 04           ``ramp_distance(v, accel, duration)``
:func:`check_odometry_step` 04           ``odometry_step(pose, d_left, d_right, track)``
:func:`check_motion_model`  05           ``motion_model(x, u)``
:func:`check_landmark_measurement` 05    ``landmark_measurement(x, l)``
:func:`check_joseph_covariance`    05    ``joseph_covariance(Sigma_bar, K, H, Q)``
==========================  ===========  ======================================================

Units are SI and angles radians throughout (``docs/conventions.md``). This module sits beside the
algorithm packages: it imports the ground floor, NumPy, SciPy and (inside the checks that need them)
OpenCV and networkx; never the simulator or matplotlib.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from lab.geometry import planar_G

__all__ = [
    "Feedback",
    "Status",
    "check_depth_std",
    "check_detection_likelihood",
    "check_entropy",
    "check_information_gain",
    "check_joseph_covariance",
    "check_kalman_update",
    "check_landmark_measurement",
    "check_map_update",
    "check_measurement_jacobian",
    "check_model_probabilities",
    "check_motion_model",
    "check_octile_heuristic",
    "check_odometry_step",
    "check_project",
    "check_ramp_distance",
    "check_rotation_zyx",
    "check_triangulate",
    "check_wheel_speeds",
]


class Status(enum.Enum):
    """What a check found."""

    CORRECT = "correct"
    WRONG = "wrong"
    NOT_ATTEMPTED = "not attempted"
    ERROR = "error"  # the answer raised, or returned something that is not a number of the right shape


_MARK = {Status.CORRECT: "✔", Status.WRONG: "✘", Status.NOT_ATTEMPTED: "…", Status.ERROR: "✘"}


@dataclass(frozen=True)
class Feedback:
    """A check's verdict: its ``status``, one line of ``message`` for the student and, for a wrong
    answer, the ``hint`` key of the mistake it recognised (``None`` when it recognised none)."""

    exercise: str
    status: Status
    message: str
    hint: str | None = None

    @property
    def correct(self) -> bool:
        return self.status is Status.CORRECT

    def __str__(self) -> str:
        return f"{_MARK[self.status]} {self.exercise}: {self.message}"

    __repr__ = __str__  # a check as a cell's last line shows this line


class _Stop(Exception):
    """Raised inside a check to return a Feedback early (not attempted, raised, wrong shape)."""

    def __init__(self, feedback: Feedback):
        self.feedback = feedback


@dataclass(frozen=True)
class _Mistake:
    """A mistake a check recognises: ``key``, what to tell the student, and the output it produces
    (an array to compare with) or a predicate on the student's output."""

    key: str
    message: str
    output: object = None
    test: Callable[[np.ndarray], bool] | None = None


def _call(name: str, fn, *args):
    """Run the student's function; stop with "not attempted" or "raised" feedback."""
    if fn is None:
        raise _Stop(
            Feedback(name, Status.NOT_ATTEMPTED, "not attempted yet: write the function, then run the check")
        )
    try:
        with np.errstate(all="ignore"):  # a NaN the answer makes is judged below, not warned about
            out = fn(*args)
    except NotImplementedError:
        raise _Stop(
            Feedback(
                name,
                Status.NOT_ATTEMPTED,
                "not attempted yet: replace `raise NotImplementedError` by your code",
            )
        ) from None
    except Exception as e:  # the student's code: any error becomes one line of feedback
        raise _Stop(Feedback(name, Status.ERROR, f"your function raised {type(e).__name__}: {e}")) from None
    if out is None or out is Ellipsis:
        raise _Stop(Feedback(name, Status.NOT_ATTEMPTED, "not attempted yet: your function returns nothing"))
    return out


def _array(name: str, out, shape: tuple[int, ...] | None = None) -> np.ndarray:
    """The output as a float array of ``shape``; a transposed shape is named as such."""
    try:
        a = np.asarray(out, dtype=float)
    except (TypeError, ValueError):
        raise _Stop(
            Feedback(name, Status.ERROR, f"returned {type(out).__name__}, not an array of numbers")
        ) from None
    if shape is not None and a.shape != shape:
        if a.ndim == 2 and a.shape == shape[::-1]:
            raise _Stop(
                Feedback(
                    name,
                    Status.WRONG,
                    f"transposed axes: the shape is {a.shape}, it should be {shape}",
                    "transposed",
                )
            )
        if a.size == math.prod(shape):
            a = a.reshape(shape)  # e.g. (n,) for (n, 1): the same numbers
        else:
            raise _Stop(Feedback(name, Status.ERROR, f"the shape is {a.shape}, it should be {shape}"))
    return a


def _close(got, want, tol: float) -> bool:
    """``got`` within ``tol`` (absolute, or relative to ``want``'s size where that is larger) of ``want``;
    NaN fails."""
    got, want = np.asarray(got, float), np.asarray(want, float)
    if got.shape != want.shape:
        return False
    scale = max(1.0, float(np.max(np.abs(want)))) if want.size else 1.0
    err = float(np.max(np.abs(got - want))) if got.size else 0.0
    return bool(err <= tol * scale)


def _verdict(
    name: str, got: np.ndarray, want: np.ndarray, tol: float, mistakes: Sequence[_Mistake], fallback: str
):
    """Correct; else the first recognised mistake; else a NaN; else ``fallback``."""
    if _close(got, want, tol):
        return Feedback(name, Status.CORRECT, "correct")
    for m in mistakes:
        hit = m.test(got) if m.test is not None else _close(got, m.output, tol)
        if hit:
            return Feedback(name, Status.WRONG, m.message, m.key)
    if not np.all(np.isfinite(got)):
        return Feedback(
            name, Status.WRONG, "your answer holds NaN or infinity where a number is expected", "nan"
        )
    return Feedback(name, Status.WRONG, fallback)


def _checked(fn):
    """Turn the early-stop exception of a check into its Feedback."""

    def wrapper(*args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except _Stop as s:
            return s.feedback

    wrapper.__name__, wrapper.__qualname__, wrapper.__doc__ = fn.__name__, fn.__qualname__, fn.__doc__
    wrapper.__module__ = fn.__module__
    return wrapper


# ---------------------------------------------------------------------------------------- notebook 00: stereo

_F, _CX, _CY, _B = 207.8, 159.5, 119.5, 0.12  # the simulated head: 320 x 240, 60 deg vertical field of view


def _stereo_inputs():
    rng = np.random.default_rng(51)
    uv = np.column_stack([rng.uniform(20, 300, 6), rng.uniform(20, 220, 6)])
    disparity = rng.uniform(5.0, 40.0, 6)
    return uv, disparity


def _cv_triangulate(uv, disparity, f, cx, cy, baseline):
    import cv2

    K = np.array([[f, 0, cx], [0, f, cy], [0, 0, 1.0]])
    P_L = K @ np.hstack([np.eye(3), np.zeros((3, 1))])
    P_R = K @ np.hstack([np.eye(3), [[-baseline], [0.0], [0.0]]])
    uv_R = uv - np.column_stack([disparity, np.zeros_like(disparity)])
    X = cv2.triangulatePoints(P_L, P_R, uv.T.astype(float), uv_R.T.astype(float))
    return (X[:3] / X[3]).T


@_checked
def check_triangulate(triangulate) -> Feedback:
    """Check ``triangulate(uv, disparity, f, cx, cy, baseline) -> points_C`` (n, 3) [m] against OpenCV's
    ``triangulatePoints`` on the rectified pair (the right pixel ``u - d`` on the same row)."""
    name = "triangulate"
    uv, d = _stereo_inputs()
    got = _array(name, _call(name, triangulate, uv.copy(), d.copy(), _F, _CX, _CY, _B), (len(d), 3))
    want = _cv_triangulate(uv, d, _F, _CX, _CY, _B)
    Z = want[:, 2]
    mistakes = [
        _Mistake(
            "units", "the right shape, but 1000 times too large: millimetres? Work in metres", want * 1000
        ),
        _Mistake(
            "depth_inverted",
            "your depth grows with the disparity: a near point has a LARGE disparity, Z = f B / d",
            test=lambda g: _close(g[:, 2] / d, np.full(len(d), g[0, 2] / d[0]), 1e-6),
        ),
        _Mistake(
            "principal_point",
            "X and Y are off by a constant in pixels: measure u and v from the principal point (cx, cy)",
            np.column_stack([uv[:, 0] * Z / _F, uv[:, 1] * Z / _F, Z]),
        ),
        _Mistake(
            "swapped_axes", "X and Y are swapped: X goes with u (right), Y with v (down)", want[:, [1, 0, 2]]
        ),
        _Mistake(
            "sign",
            "a wrong sign: in the camera frame x points right, y down and z forward",
            test=lambda g: _close(np.abs(g), np.abs(want), 1e-6),
        ),
    ]
    return _verdict(name, got, want, 1e-6, mistakes, "not the triangulated points: check Z = f B / d first")


@_checked
def check_project(project) -> Feedback:
    """Check ``project(points_C, f, cx, cy) -> uv`` (n, 2) [px] against OpenCV's ``projectPoints``."""
    import cv2

    name = "project"
    uv, d = _stereo_inputs()
    p = _cv_triangulate(uv, d, _F, _CX, _CY, _B) + [0.05, -0.03, 0.2]
    got = _array(name, _call(name, project, p.copy(), _F, _CX, _CY), (len(p), 2))
    K = np.array([[_F, 0, _CX], [0, _F, _CY], [0, 0, 1.0]])
    want = cv2.projectPoints(p, np.zeros(3), np.zeros(3), K, None)[0].reshape(-1, 2)
    mistakes = [
        _Mistake(
            "swapped_axes", "u and v are swapped: u is the column (from X), v the row (from Y)", want[:, ::-1]
        ),
        _Mistake(
            "normalisation",
            "missing normalisation: divide X and Y by the depth Z before scaling by f",
            np.column_stack([_F * p[:, 0] + _CX, _F * p[:, 1] + _CY]),
        ),
        _Mistake(
            "principal_point",
            "off by a constant: add the principal point (cx, cy), it "
            "is where the optical axis meets the image",
            want - [_CX, _CY],
        ),
        _Mistake("sign", "a wrong sign: subtract nothing, u = f X / Z + cx", want - 2 * np.array([_CX, _CY])),
    ]
    return _verdict(
        name, got, want, 1e-6, mistakes, "not the pinhole projection u = f X / Z + cx, v = f Y / Z + cy"
    )


@_checked
def check_depth_std(depth_std) -> Feedback:
    """Check ``depth_std(Z, f, baseline, sigma_disparity) -> sigma_Z`` [m], the first-order depth
    uncertainty, against a finite-difference derivative of ``Z(d) = f B / d`` times ``sigma_d``."""
    name = "depth_std"
    Zs, sigma_d = np.array([0.5, 1.0, 2.0, 3.5]), 0.4
    got = _array(name, [_call(name, depth_std, float(z), _F, _B, sigma_d) for z in Zs], (len(Zs),))
    depth = lambda disp: _F * _B / disp  # noqa: E731
    d, h = _F * _B / Zs, 1e-6
    want = np.abs((depth(d + h) - depth(d - h)) / (2 * h)) * sigma_d
    mistakes = [
        _Mistake(
            "linear",
            "your uncertainty grows linearly with the distance: it grows with its SQUARE (Z = f B / d)",
            test=lambda g: _close(g / want * Zs, np.full(len(Zs), g[0] / want[0] * Zs[0]), 1e-6),
        ),
        _Mistake("variance", "that is the variance: a standard deviation is its square root", want**2),
        _Mistake("missing_sigma", "scale by the disparity's standard deviation sigma_d", want / sigma_d),
    ]
    return _verdict(name, got, want, 1e-6, mistakes, "not the first-order sigma_Z: differentiate Z = f B / d")


# -------------------------------------------------------------------------------------- notebook 01: pose EKF


def _R_zyx(a, b, g):
    from scipy.spatial.transform import Rotation

    return Rotation.from_euler("ZYX", [a, b, g]).as_matrix()  # intrinsic z-y-x: Rz(a) Ry(b) Rx(g)


_ANGLES = ((0.3, -0.4, 1.1), (1.2, 0.5, -0.7), (-2.0, 0.2, 0.4))


@_checked
def check_rotation_zyx(rotation_zyx) -> Feedback:
    """Check ``rotation_zyx(alpha, beta, gamma) -> R`` (3, 3), ``R = Rz(alpha) Ry(beta) Rx(gamma)``, against
    SciPy's ``Rotation.from_euler("ZYX", ...)``."""
    from scipy.spatial.transform import Rotation

    name = "rotation_zyx"
    got = np.stack([_array(name, _call(name, rotation_zyx, *a), (3, 3)) for a in _ANGLES])
    want = np.stack([_R_zyx(*a) for a in _ANGLES])
    flips = [
        _Mistake(
            f"sign_{axis}",
            f"a wrong sign in R{axis}: a positive angle turns "
            f"counter-clockwise about the axis (sin below the diagonal in Rz)",
            np.stack([_R_zyx(*(s * np.array(a))) for a in _ANGLES]),
        )
        for axis, s in (("z", (-1, 1, 1)), ("y", (1, -1, 1)), ("x", (1, 1, -1)))
    ]
    mistakes = [
        _Mistake("transposed", "transposed: that is R^T, the inverse rotation", want.transpose(0, 2, 1)),
        _Mistake(
            "order",
            "the product in the wrong order: z-y-x Euler angles give R = Rz(alpha) Ry(beta) Rx(gamma)",
            np.stack([Rotation.from_euler("XYZ", a[::-1]).as_matrix() for a in _ANGLES]),  # Rx Ry Rz
        ),
        _Mistake(
            "degrees",
            "the angles are radians: do not convert them (np.radians) again",
            np.stack([_R_zyx(*np.radians(a)) for a in _ANGLES]),
        ),
        *flips,
        _Mistake(
            "not_rotation",
            "not a rotation: R R^T should be I and det R = 1",
            test=lambda g: not all(_close(r @ r.T, np.eye(3), 1e-6) for r in g),
        ),
    ]
    return _verdict(name, got, want, 1e-9, mistakes, "a rotation, but not Rz(alpha) Ry(beta) Rx(gamma)")


def _euler_model(X, b):
    return X[:3] + b @ _R_zyx(*X[3:]).T


_STATE_NAMES = ("x", "y", "z", "alpha", "beta", "gamma")


@_checked
def check_measurement_jacobian(measurement_jacobian) -> Feedback:
    """Check ``measurement_jacobian(X, b_O) -> C`` (3n, 6) of Eq. (3), ``d_j = x_r + R(x_o) b_j``, against
    central finite differences of the model (written with SciPy's rotations); rows ``3j..3j+2`` are
    feature ``j``."""
    name = "measurement_jacobian"
    rng = np.random.default_rng(3)
    X = np.array([0.1, -0.2, 1.5, 0.4, -0.3, 0.7])
    b = rng.uniform(-0.14, 0.14, (4, 3))
    n = len(b)
    got = _array(name, _call(name, measurement_jacobian, X.copy(), b.copy()), (3 * n, 6))
    h = 1e-6
    want = np.column_stack(
        [((_euler_model(X + h * e, b) - _euler_model(X - h * e, b)) / (2 * h)).ravel() for e in np.eye(6)]
    )
    by_coordinate = want.reshape(n, 3, 6).transpose(1, 0, 2).reshape(3 * n, 6)
    mistakes = [
        _Mistake(
            "row_order",
            "rows in the wrong order: rows 3j..3j+2 belong to feature j (x, y, z of d_j)",
            by_coordinate,
        ),
        *[
            _Mistake(
                f"sign_{_STATE_NAMES[k]}",
                f"column {k} (d/d{_STATE_NAMES[k]}) has the wrong sign",
                want * np.where(np.arange(6) == k, -1.0, 1.0),
            )
            for k in range(6)
        ],
        _Mistake(
            "translation",
            "the first three columns: d_j moves one for one with x_r, so each 3 x 3 block starts with I",
            test=lambda g: _close(g[:, 3:], want[:, 3:], 1e-5) and not _close(g[:, :3], want[:, :3], 1e-5),
        ),
    ]

    def wrong_columns(g):
        bad = [_STATE_NAMES[k] for k in range(6) if not _close(g[:, k], want[:, k], 1e-5)]
        return f"differs from finite differences in the column(s) of {', '.join(bad)}"

    fb = _verdict(name, got, want, 1e-5, mistakes, "")
    return fb if fb.message else Feedback(name, Status.WRONG, wrong_columns(got))


def _kalman_inputs():
    rng = np.random.default_rng(7)
    A = rng.normal(size=(6, 6))
    Sigma_bar = A @ A.T / 6 + 0.1 * np.eye(6)
    C = rng.normal(size=(9, 6))
    B = rng.normal(size=(9, 9))
    Sigma_m = B @ B.T / 9 + 0.2 * np.eye(9)
    return rng.normal(size=6), Sigma_bar, rng.normal(size=9), C, Sigma_m


@_checked
def check_kalman_update(kalman_update) -> Feedback:
    r"""Check ``kalman_update(mu_bar, Sigma_bar, y, C, Sigma_m) -> (mu, Sigma)`` (``y`` the innovation
    ``D - H(mu_bar)``) against the information form of the same update,
    :math:`\Sigma^{-1} = \bar\Sigma^{-1} + C^T \Sigma_m^{-1} C`,
    :math:`\mu = \bar\mu + \Sigma C^T \Sigma_m^{-1} y`."""
    name = "kalman_update"
    mu_bar, Sb, y, C, Sm = _kalman_inputs()
    out = _call(name, kalman_update, mu_bar.copy(), Sb.copy(), y.copy(), C.copy(), Sm.copy())
    if not (isinstance(out, tuple | list) and len(out) == 2):
        return Feedback(name, Status.ERROR, "return the pair (mu, Sigma)")
    mu, Sigma = _array(name, out[0], (6,)), _array(name, out[1], (6, 6))
    got = np.concatenate([mu, Sigma.ravel()])
    inv = np.linalg.inv
    Sigma_ref = inv(inv(Sb) + C.T @ inv(Sm) @ C)
    want = np.concatenate([mu_bar + Sigma_ref @ C.T @ inv(Sm) @ y, Sigma_ref.ravel()])

    def with_gain(K):
        IKC = np.eye(6) - K @ C
        return np.concatenate([mu_bar + K @ y, (IKC @ Sb @ IKC.T + K @ Sm @ K.T).ravel()])

    S = C @ Sb @ C.T + Sm
    K_ref = Sb @ C.T @ inv(S)
    mistakes = [
        _Mistake(
            "innovation_sign",
            "a wrong sign: the innovation y = D - H(mu_bar) is ADDED, mu = mu_bar + K y",
            np.concatenate([mu_bar - K_ref @ y, Sigma_ref.ravel()]),
        ),
        _Mistake(
            "missing_noise",
            "S = C Sigma_bar C^T + Sigma_m: you left out the measurement noise",
            with_gain(Sb @ C.T @ inv(C @ Sb @ C.T)),
        ),
        _Mistake(
            "covariance_unchanged",
            "the mean is right, but the covariance did not shrink: Sigma = "
            "(I - K C) Sigma_bar (I - K C)^T + K Sigma_m K^T",
            test=lambda g: _close(g[:6], want[:6], 1e-8) and _close(g[6:], Sb.ravel(), 1e-8),
        ),
        _Mistake(
            "no_inverse",
            "the gain is K = Sigma_bar C^T S^{-1}: multiply by the INVERSE of S",
            with_gain(Sb @ C.T @ S),
        ),
        _Mistake(
            "not_symmetric",
            "the covariance is not symmetric: is a transpose missing in the Joseph form?",
            test=lambda g: not _close(g[6:].reshape(6, 6), g[6:].reshape(6, 6).T, 1e-8),
        ),
    ]
    return _verdict(
        name, got, want, 1e-8, mistakes, "not the Kalman update: compute S, then K, then mu and Sigma"
    )


# --------------------------------------------------------------------------------------- notebook 02: entropy


_PS = (np.array([0.25, 0.25, 0.25, 0.25]), np.array([0.7, 0.1, 0.15, 0.05]), np.array([0.5, 0.0, 0.5, 0.0]))


@_checked
def check_entropy(entropy) -> Feedback:
    """Check ``entropy(P) -> H`` [nats], Eq. (5) of the identification paper with ``0 log 0 = 0``, against
    ``scipy.stats.entropy``."""
    from scipy.stats import entropy as sp_entropy

    name = "entropy"
    got = _array(name, [_call(name, entropy, P.copy()) for P in _PS], (len(_PS),))
    want = np.array([sp_entropy(P) for P in _PS])
    mistakes = [
        _Mistake(
            "bits",
            "that is in bits (log2): the paper's entropy is in nats, use the natural log",
            want / math.log(2),
        ),
        _Mistake("sign", "a wrong sign: H = -sum P log P is never negative", -want),
        _Mistake(
            "zero_log_zero",
            "NaN where a probability is 0: the term 0 log 0 counts as 0 (skip the zeros)",
            test=lambda g: _close(g[:2], want[:2], 1e-9) and not np.isfinite(g[2]),
        ),
    ]
    return _verdict(name, got, want, 1e-9, mistakes, "not -sum P log P")


_LL_CASES = (
    (np.array([0.1, 0.2, 0.3, 0.4]), np.array([-2.0, -1.0, -3.5, -0.5])),
    (np.array([0.25, 0.25, 0.25, 0.25]), np.array([-3000.0, -3001.0, -3004.0, -3000.5])),
)


@_checked
def check_model_probabilities(model_probabilities) -> Feedback:
    """Check ``model_probabilities(P_prior, log_likelihood) -> P``, Bayes' rule over the models (Eq. (7)),
    against ``scipy.special.softmax(log P_prior + log_likelihood)``; the second case's likelihoods are
    ``exp(-3000)``, 0.0 in double precision."""
    from scipy.special import softmax

    name = "model_probabilities"
    got = np.concatenate(
        [_array(name, _call(name, model_probabilities, P.copy(), ll.copy()), (4,)) for P, ll in _LL_CASES]
    )
    want = np.concatenate([softmax(np.log(P) + ll) for P, ll in _LL_CASES])
    (P1, ll1), (P2, ll2) = _LL_CASES
    mistakes = [
        _Mistake(
            "normalisation",
            "missing normalisation: divide by the sum over the models "
            "(Eq. (7)'s denominator), so P sums to 1",
            test=lambda g: _close(g[:4], P1 * np.exp(ll1), 1e-9),
        ),
        _Mistake(
            "prior",
            "the prior is missing: multiply each likelihood by P(M_i) first",
            np.concatenate([softmax(ll1), softmax(ll2)]),
        ),
        _Mistake(
            "log_space",
            "right for moderate likelihoods, but exp(-3000) is 0.0: stay in "
            "log space and subtract the largest before exp",
            test=lambda g: _close(g[:4], want[:4], 1e-9) and not _close(g[4:], want[4:], 1e-9),
        ),
        _Mistake(
            "not_exponentiated",
            "these are LOG-likelihoods: exponentiate (or add them to log P) rather than multiply by them",
            test=lambda g: _close(g[:4], P1 * ll1 / np.sum(P1 * ll1), 1e-9),
        ),
    ]
    return _verdict(
        name, got, want, 1e-9, mistakes, "not Bayes' rule: P_i proportional to P_prior_i times likelihood_i"
    )


_IG_CASES = (
    (np.array([0.25, 0.25, 0.25, 0.25]), np.array([[0.8, 0.2], [0.3, 0.7], [0.3, 0.7], [0.3, 0.7]])),
    (
        np.array([0.6, 0.1, 0.2, 0.1]),
        np.array([[0.7, 0.2, 0.1], [0.1, 0.8, 0.1], [0.2, 0.2, 0.6], [1 / 3, 1 / 3, 1 / 3]]),
    ),
)


def _mutual_information(P, lik):
    joint = P[:, None] * lik  # p(M_i, y)
    py = joint.sum(axis=0)
    nz = joint > 0
    return float(np.sum(joint[nz] * np.log(joint[nz] / (P[:, None] * py[None, :])[nz])))


def _expected_entropy(P, lik, weights=None):
    from scipy.stats import entropy as sp_entropy

    joint = P[:, None] * lik
    py = joint.sum(axis=0)
    H_post = np.array([sp_entropy(joint[:, k] / py[k]) for k in range(lik.shape[1])])
    w = py if weights is None else weights
    return float(np.sum(w * H_post))


@_checked
def check_information_gain(information_gain) -> Feedback:
    r"""Check ``information_gain(P, likelihood) -> I`` [nats], Eq. (4) for a discrete measurement:
    ``P`` (L,) the model probabilities, ``likelihood`` (L, Y) with ``likelihood[i, y] = p(y | M_i)``, and
    :math:`I = H(M) - E_y[H(M \mid y)]`. The reference is the mutual information computed from the joint
    distribution :math:`p(M_i, y)`, a different route to the same number."""
    from scipy.stats import entropy as sp_entropy

    name = "information_gain"
    got = _array(
        name, [_call(name, information_gain, P.copy(), L.copy()) for P, L in _IG_CASES], (len(_IG_CASES),)
    )
    want = np.array([_mutual_information(P, L) for P, L in _IG_CASES])
    H = np.array([sp_entropy(P) for P, _ in _IG_CASES])
    EH = np.array([_expected_entropy(P, L) for P, L in _IG_CASES])
    unweighted = np.array(
        [
            H[k] - _expected_entropy(P, L, np.full(L.shape[1], 1 / L.shape[1]))
            for k, (P, L) in enumerate(_IG_CASES)
        ]
    )
    mistakes = [
        _Mistake(
            "expected_entropy", "that is the expected entropy E[H+]: the gain is the entropy now MINUS it", EH
        ),
        _Mistake(
            "sign", "a wrong sign: the gain is H now minus the expected entropy after, never negative", -want
        ),
        _Mistake(
            "weights",
            "weight each outcome's posterior entropy by its probability "
            "p(y) = sum_i P_i p(y | M_i), not equally",
            unweighted,
        ),
        _Mistake("bits", "that is in bits (log2): use the natural log (nats)", want / math.log(2)),
    ]
    return _verdict(
        name, got, want, 1e-9, mistakes, "not H(M) - E_y[H(M | y)]: compute p(y), each posterior, its entropy"
    )


# ----------------------------------------------------------------------------------- notebook 03: grid search

_SHAPE, _CELL = (5, 4), (1, 3)


def _eq2(shape, cell, detected, alpha, beta):
    """P(y | h_ij = 1) of Eq. (2), written out cell by cell."""
    L = np.empty(shape)
    for i in range(shape[0]):
        for j in range(shape[1]):
            there = (i, j) == tuple(cell)
            p_miss = beta if there else 1 - alpha  # P(y = 0 | h_ij = 1)
            L[i, j] = 1 - p_miss if detected else p_miss
    return L


@_checked
def check_detection_likelihood(detection_likelihood) -> Feedback:
    """Check ``detection_likelihood(shape, cell, detected, alpha, beta) -> L``, ``L[i, j] = P(y | h_ij = 1)``
    of Eq. (2) of the search paper, after a detection and after a miss."""
    name = "detection_likelihood"
    a, b = 0.1, 0.3
    got = np.concatenate(
        [
            _array(name, _call(name, detection_likelihood, _SHAPE, _CELL, y, a, b), _SHAPE).ravel()
            for y in (True, False)
        ]
    )
    ref = lambda shape, cell, a_, b_, flip=False: np.concatenate(  # noqa: E731
        [_eq2(shape, cell, y != flip, a_, b_).ravel() for y in (True, False)]
    )
    want = ref(_SHAPE, _CELL, a, b)
    mistakes = [
        _Mistake(
            "swapped_rates",
            "alpha and beta swapped: alpha is the false-alarm rate, beta the missed detection",
            ref(_SHAPE, _CELL, b, a),
        ),
        _Mistake(
            "outcome",
            "the likelihood of the other outcome: for a detection (y = 1) it is 1 - beta in the cell",
            ref(_SHAPE, _CELL, a, b, True),
        ),
        _Mistake(
            "transposed",
            "transposed axes: the cell is (row i, column j) = cell[0], cell[1]",
            ref(_SHAPE, _CELL[::-1], a, b),
        ),
    ]
    return _verdict(
        name,
        got,
        want,
        1e-12,
        mistakes,
        "not Eq. (2): 1 - beta / beta in the cell, alpha / 1 - alpha elsewhere",
    )


def _map_prior():
    rng = np.random.default_rng(5)
    P = rng.uniform(0.2, 1.0, _SHAPE)
    return P / P.sum()


@_checked
def check_map_update(update_probability_map) -> Feedback:
    """Check ``update_probability_map(P, cell, detected, alpha, beta) -> P_post``, Eqs. (1)-(3) of the search
    paper, against the posterior taken from the joint distribution ``p(h, y)`` of the hypotheses and the
    measurement."""
    name = "update_probability_map"
    P = _map_prior()
    a, b = 0.1, 0.3

    def post(cell, detected, a_, b_, normalise=True):
        joint = _eq2(_SHAPE, cell, detected, a_, b_) * P  # p(h_ij = 1, y)
        return joint / joint.sum() if normalise else joint

    got = np.concatenate(
        [
            _array(name, _call(name, update_probability_map, P.copy(), _CELL, y, a, b), _SHAPE).ravel()
            for y in (True, False)
        ]
    )

    def both(cell=_CELL, flip=False, ab=(a, b), norm=True):  # the posteriors after a detection and a miss
        return np.concatenate([post(cell, y != flip, *ab, norm).ravel() for y in (True, False)])

    want = both()
    mistakes = [
        _Mistake(
            "normalisation",
            "missing normalisation: divide by P(y) (Eq. (3)) so that the map sums to 1",
            both(norm=False),
        ),
        _Mistake(
            "swapped_rates",
            "alpha and beta swapped: alpha is the false-alarm rate, beta the missed detection",
            both(ab=(b, a)),
        ),
        _Mistake(
            "outcome",
            "the update of the other outcome: a detection (y = 1) must make the cell MORE probable",
            both(flip=True),
        ),
        _Mistake(
            "transposed",
            "transposed axes: the cell is (row i, column j) = cell[0], cell[1]",
            both(cell=_CELL[::-1]),
        ),
    ]
    return _verdict(
        name, got, want, 1e-12, mistakes, "not Eqs. (1)-(3): likelihood times prior, divided by their sum"
    )


_OCTILE_CASES = (((0, 0), (3, 7)), ((6, 2), (1, 5)), ((4, 4), (4, 0)), ((2, 8), (7, 3)))


@_checked
def check_octile_heuristic(octile_heuristic) -> Feedback:
    """Check ``octile_heuristic(cell, goal, min_cost) -> h``, the cost of the cheapest 8-connected path on
    open floor where every cell costs ``min_cost`` (steps of length 1 and sqrt 2), against networkx's
    Dijkstra on that grid."""
    import networkx as nx

    name = "octile_heuristic"
    m = 1.5
    got = _array(
        name, [_call(name, octile_heuristic, c, g, m) for c, g in _OCTILE_CASES], (len(_OCTILE_CASES),)
    )
    G = nx.Graph()
    for i in range(9):
        for j in range(9):
            for di, dj in ((1, 0), (0, 1), (1, 1), (1, -1)):
                if 0 <= i + di < 9 and 0 <= j + dj < 9:
                    G.add_edge((i, j), (i + di, j + dj), weight=m * math.hypot(di, dj))
    want = np.array([nx.dijkstra_path_length(G, c, g) for c, g in _OCTILE_CASES])
    delta = np.array([[abs(c[0] - g[0]), abs(c[1] - g[1])] for c, g in _OCTILE_CASES], float)
    mistakes = [
        _Mistake(
            "euclidean",
            "that is the straight line: admissible, but on an 8-connected "
            "grid the exact cost is the octile distance",
            m * np.hypot(*delta.T),
        ),
        _Mistake(
            "manhattan",
            "that is the Manhattan distance: it overestimates a diagonal step "
            "(sqrt 2 < 2), so A* may miss the cheapest path",
            m * delta.sum(1),
        ),
        _Mistake("chebyshev", "a diagonal step costs sqrt 2 cells, not 1", m * delta.max(1)),
        _Mistake("scale", "scale by min_cost: the heuristic is a cost, not a number of cells", want / m),
    ]
    return _verdict(
        name, got, want, 1e-9, mistakes, "not the octile distance: max + (sqrt 2 - 1) min of the cell offsets"
    )


# -------------------------------------------------------------------------------------- notebook 04: the base

_TRACK = 0.235  # the Create 2's wheel track [m]
_TWIST_CASES = ((0.2, 0.0), (0.1, 0.8), (0.0, -1.2), (-0.15, 0.4))


@_checked
def check_wheel_speeds(wheel_speeds) -> Feedback:
    """Check ``wheel_speeds(v, omega, track) -> (v_left, v_right)`` [m/s] of a differential drive (what
    the Create's Drive Direct command takes, in mm/s) by driving them forward: the base's speed is the
    wheels' mean, its turn rate their difference over the track (counter-clockwise positive)."""
    name = "wheel_speeds"
    got = np.stack([_array(name, _call(name, wheel_speeds, v, w, _TRACK), (2,)) for v, w in _TWIST_CASES])
    twist = np.column_stack([got.mean(axis=1), (got[:, 1] - got[:, 0]) / _TRACK])  # forward kinematics
    want = np.array(_TWIST_CASES, float)
    mistakes = [
        _Mistake(
            "swapped",
            "left and right swapped: the base turns the wrong way (omega > 0 "
            "is counter-clockwise: the right wheel is faster)",
            want * [1, -1],
        ),
        _Mistake(
            "half_track",
            "the turn is off by a factor of 2: each wheel is track / 2 from the centre",
            want * [1, 2],
        ),
        _Mistake(
            "half_track",
            "the turn is off by a factor of 2: each wheel is track / 2 from the centre",
            want * [1, 0.5],
        ),
        _Mistake(
            "units",
            "1000 times too fast: that is mm/s, the Open Interface's unit; this function works in m/s",
            want * 1000,
        ),
    ]
    return _verdict(name, twist, want, 1e-9, mistakes, "the wheels do not give the commanded v and omega")


_RAMP_CASES = ((0.2, 0.5, 1.0), (0.3, 0.5, 0.4), (0.2, 1.0, 2.0), (0.4, 0.25, 3.0))


def _integrate_ramp(v, a, T, n=20000):
    dt = T / n
    t = (np.arange(n) + 0.5) * dt
    return float(np.sum(np.minimum(a * t, v)) * dt)  # midpoint rule of the speed profile


@_checked
def check_ramp_distance(ramp_distance) -> Feedback:
    """Check ``ramp_distance(v, accel, duration) -> distance`` [m]: a base at rest, commanded to ``v``
    [m/s], speeds up at ``accel`` [m/s^2] until it reaches ``v``; how far has it gone after ``duration``
    [s]? Against a numerical integration of the speed."""
    name = "ramp_distance"
    got = _array(name, [_call(name, ramp_distance, *c) for c in _RAMP_CASES], (len(_RAMP_CASES),))
    want = np.array([_integrate_ramp(*c) for c in _RAMP_CASES])
    t_r = lambda v, a, T: min(v / a, T)  # noqa: E731
    mistakes = [
        _Mistake(
            "no_ramp",
            "the base starts from rest: it needs v / accel seconds to reach v",
            np.array([v * T for v, a, T in _RAMP_CASES]),
        ),
        _Mistake(
            "half",
            "the ramp's distance is 1/2 accel t^2 (the mean speed on the ramp is half the final one)",
            np.array([a * t_r(v, a, T) ** 2 + v * (T - t_r(v, a, T)) for v, a, T in _RAMP_CASES]),
        ),
        _Mistake(
            "no_cap",
            "the speed stops growing at v: the ramp ends at t = v / accel",
            np.array([0.5 * a * T**2 for v, a, T in _RAMP_CASES]),
        ),
    ]
    return _verdict(name, got, want, 1e-6, mistakes, "not the distance of a ramp to v, then constant speed")


_ODOM_CASES = (((1.0, 2.0, 2.0), 0.05, 0.07), ((-0.5, 0.3, -0.4), 0.06, 0.03), ((0.0, 0.0, 3.0), 0.04, 0.05))


def _integrate_odometry(pose, dl, dr, track, n=2000):
    x, y, th = map(float, pose)
    ds, dth = (dl + dr) / 2 / n, (dr - dl) / track / n
    for _ in range(n):
        x, y, th = x + ds * math.cos(th + dth / 2), y + ds * math.sin(th + dth / 2), th + dth
    return np.array([x, y, th])


@_checked
def check_odometry_step(odometry_step) -> Feedback:
    """Check ``odometry_step(pose, d_left, d_right, track) -> new_pose``: the pose ``(x, y, theta)`` [m, m,
    rad] in the world after the wheels rolled ``d_left``, ``d_right`` [m], against a fine numerical
    integration of the arc. A first-order step (the old or the mid heading) is within the tolerance of
    5 mm for these short steps; the heading is not wrapped here."""
    name = "odometry_step"
    got = np.stack(
        [
            _array(name, _call(name, odometry_step, np.array(p), dl, dr, _TRACK), (3,))
            for p, dl, dr in _ODOM_CASES
        ]
    )
    want = np.stack([_integrate_odometry(p, dl, dr, _TRACK) for p, dl, dr in _ODOM_CASES])
    tol = 5e-3
    mistakes = [
        _Mistake(
            "swapped",
            "left and right swapped: the robot turns the wrong way (right wheel further: counter-clockwise)",
            np.stack([_integrate_odometry(p, dr, dl, _TRACK) for p, dl, dr in _ODOM_CASES]),
        ),
        _Mistake(
            "half_track",
            "the turn is off by a factor of 2: the heading changes by (d_right - d_left) / track",
            np.stack([_integrate_odometry(p, dl, dr, _TRACK / 2) for p, dl, dr in _ODOM_CASES]),
        ),
        _Mistake(
            "degrees",
            "the heading is in radians: do not convert the turn to degrees",
            test=lambda g: _close(
                g[:, 2], [p[2] + math.degrees((dr - dl) / _TRACK) for p, dl, dr in _ODOM_CASES], tol
            ),
        ),
        _Mistake(
            "frame",
            "the distance is along the robot's heading: rotate it into the world (cos theta, sin theta)",
            np.stack([np.array(p) + [(dl + dr) / 2, 0.0, (dr - dl) / _TRACK] for p, dl, dr in _ODOM_CASES]),
        ),
    ]
    return _verdict(name, got, want, tol, mistakes, "not where the wheels took the robot")


# ---------------------------------------------------------------------------------- notebook 05: localization


def _pose_of(G):
    return np.array([G[0, 3], G[1, 3], math.atan2(G[1, 0], G[0, 0])])


_MOTION_CASES = (
    ((1.0, 2.0, 0.5), (0.3, 0.05, 0.2)),
    ((-1.0, 0.5, 3.0), (0.2, -0.1, 0.4)),
    ((0.0, 0.0, -2.0), (0.1, 0.2, -0.3)),
)


@_checked
def check_motion_model(motion_model) -> Feedback:
    """Check ``motion_model(x, u) -> x_new``, the pose ``x = (x, y, theta)`` moved by the increment ``u =
    (dx, dy, dtheta)`` written in its own frame, against the product of homogeneous 2D transforms
    ``G(x) G(u)``; the heading must be wrapped to (-pi, pi]."""
    name = "motion_model"
    got = np.stack(
        [_array(name, _call(name, motion_model, np.array(x), np.array(u)), (3,)) for x, u in _MOTION_CASES]
    )
    want = np.stack([_pose_of(planar_G(*x) @ planar_G(*u)) for x, u in _MOTION_CASES])

    def rotated(x, u, s):  # R(s theta) (dx, dy) added to (x, y)
        c, sn = math.cos(x[2]), s * math.sin(x[2])
        return np.add(x[:2], np.array([[c, -sn], [sn, c]]) @ u[:2])

    mistakes = [
        _Mistake(
            "frame",
            "u is in the robot's own frame: rotate (dx, dy) by the heading before adding it",
            test=lambda g: _close(g[:, :2], [np.add(x[:2], u[:2]) for x, u in _MOTION_CASES], 1e-9),
        ),
        _Mistake(
            "transposed",
            "transposed rotation: that is R(theta)^T, it turns the increment the wrong way",
            test=lambda g: _close(g[:, :2], [rotated(x, u, -1.0) for x, u in _MOTION_CASES], 1e-9),
        ),
        _Mistake(
            "wrap",
            "the heading is not wrapped: keep theta in (-pi, pi]",
            test=lambda g: (
                _close(g[:, :2], want[:, :2], 1e-9) and _close(np.cos(g[:, 2]), np.cos(want[:, 2]), 1e-9)
            ),
        ),
    ]
    return _verdict(name, got, want, 1e-9, mistakes, "not the increment composed onto the pose")


_LANDMARK_CASES = (
    ((1.0, 2.0, 0.5), (3.0, 1.0, 2.0)),
    ((-1.0, 0.5, 3.0), (-2.5, 2.0, -2.8)),
    ((0.2, -0.3, -1.0), (1.0, -2.0, 1.5)),
)


@_checked
def check_landmark_measurement(landmark_measurement) -> Feedback:
    """Check ``landmark_measurement(x, l) -> z``, the planar pose of landmark ``l = (x_l, y_l, theta_l)``
    (in the world) as the robot at ``x`` sees it, in its own frame, against ``G(x)^-1 G(l)``; the angle
    wrapped to (-pi, pi]."""
    name = "landmark_measurement"
    got = np.stack(
        [
            _array(name, _call(name, landmark_measurement, np.array(x), np.array(l)), (3,))
            for x, l in _LANDMARK_CASES
        ]
    )
    want = np.stack([_pose_of(np.linalg.inv(planar_G(*x)) @ planar_G(*l)) for x, l in _LANDMARK_CASES])

    def rotate(x, v, s):
        c, sn = math.cos(x[2]), s * math.sin(x[2])
        return np.array([[c, -sn], [sn, c]]) @ v

    diff = [np.subtract(l[:2], x[:2]) for x, l in _LANDMARK_CASES]
    mistakes = [
        _Mistake(
            "transposed",
            "transposed rotation: into the robot's frame is R(theta)^T (l - x), not R(theta) (l - x)",
            test=lambda g: _close(
                g[:, :2], [rotate(x, d, 1.0) for (x, _), d in zip(_LANDMARK_CASES, diff, strict=True)], 1e-9
            ),
        ),
        _Mistake(
            "sign",
            "a wrong sign: the landmark MINUS the robot, l - x",
            test=lambda g: _close(g[:, :2], -want[:, :2], 1e-9),
        ),
        _Mistake(
            "frame",
            "the difference is in the world frame: rotate it into the robot's frame",
            test=lambda g: _close(g[:, :2], diff, 1e-9),
        ),
        _Mistake(
            "wrap",
            "the angle is not wrapped: keep it in (-pi, pi]",
            test=lambda g: (
                _close(g[:, :2], want[:, :2], 1e-9) and _close(np.cos(g[:, 2]), np.cos(want[:, 2]), 1e-9)
            ),
        ),
    ]
    return _verdict(name, got, want, 1e-9, mistakes, "not the landmark's pose in the robot frame")


def _joseph_inputs():
    rng = np.random.default_rng(11)
    A = rng.normal(size=(3, 3))
    Sigma_bar = A @ A.T / 3 + 0.05 * np.eye(3)
    H = rng.normal(size=(3, 3))
    Q = np.diag([0.02, 0.03, 0.01])
    K = 0.5 * Sigma_bar @ H.T @ np.linalg.inv(H @ Sigma_bar @ H.T + Q)  # half the optimal gain
    return Sigma_bar, K, H, Q


@_checked
def check_joseph_covariance(joseph_covariance) -> Feedback:
    r"""Check ``joseph_covariance(Sigma_bar, K, H, Q) -> Sigma``, the covariance of :math:`\bar x + K\nu`
    for ANY gain ``K``: the check passes half the optimal gain. The reference is the covariance of the
    new error :math:`e' = [I - KH,\; -K]\,[e; v]` with
    :math:`[e; v] \sim N(0, \mathrm{diag}(\bar\Sigma, Q))`."""
    from scipy.linalg import block_diag

    name = "joseph_covariance"
    Sb, K, H, Q = _joseph_inputs()
    got = _array(name, _call(name, joseph_covariance, Sb.copy(), K.copy(), H.copy(), Q.copy()), (3, 3))
    A = np.hstack([np.eye(3) - K @ H, -K])
    want = A @ block_diag(Sb, Q) @ A.T
    IKH = np.eye(3) - K @ H
    mistakes = [
        _Mistake(
            "short_form",
            "that is the short form (I - KH) Sigma_bar: it holds only for the optimal gain",
            IKH @ Sb,
        ),
        _Mistake("missing_noise", "the measurement noise is missing: add K Q K^T", IKH @ Sb @ IKH.T),
        _Mistake(
            "transposed",
            "a transpose is missing: (I - KH) Sigma_bar (I - KH)^T + K Q K^T",
            IKH @ Sb @ IKH + K @ Q @ K.T,
        ),
    ]
    return _verdict(name, got, want, 1e-10, mistakes, "not the covariance of the updated error")
