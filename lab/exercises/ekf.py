"""Notebook 01's checks: the z-y-x rotation, the measurement Jacobian of Eq. (3) and one Kalman update
(assignment ``ekf``).

See :mod:`lab.exercises` for what a check does and how it avoids carrying the answer.
"""

from __future__ import annotations

import numpy as np

from lab.exercises.feedback import (
    Feedback,
    Mistake,
    Status,
    answer_array,
    call_answer,
    checked,
    close,
    verdict,
)

__all__ = ["check_rotation_zyx", "check_measurement_jacobian", "check_kalman_update"]


def _R_zyx(a, b, g):
    from scipy.spatial.transform import Rotation

    return Rotation.from_euler("ZYX", [a, b, g]).as_matrix()  # intrinsic z-y-x: Rz(a) Ry(b) Rx(g)


_ANGLES = ((0.3, -0.4, 1.1), (1.2, 0.5, -0.7), (-2.0, 0.2, 0.4))


@checked
def check_rotation_zyx(rotation_zyx) -> Feedback:
    """Check ``rotation_zyx(alpha, beta, gamma) -> R`` (3, 3), ``R = Rz(alpha) Ry(beta) Rx(gamma)``, against
    SciPy's ``Rotation.from_euler("ZYX", ...)``."""

    name = "rotation_zyx"
    got = np.stack([answer_array(name, call_answer(name, rotation_zyx, *a), (3, 3)) for a in _ANGLES])
    from scipy.spatial.transform import Rotation  # after the answer ran: a stub costs nothing

    want = np.stack([_R_zyx(*a) for a in _ANGLES])
    flips = [
        Mistake(
            f"sign_{axis}",
            f"a wrong sign in R{axis}: a positive angle turns "
            f"counter-clockwise about the axis (sin below the diagonal in Rz)",
            np.stack([_R_zyx(*(s * np.array(a))) for a in _ANGLES]),
        )
        for axis, s in (("z", (-1, 1, 1)), ("y", (1, -1, 1)), ("x", (1, 1, -1)))
    ]
    mistakes = [
        Mistake("transposed", "transposed: that is R^T, the inverse rotation", want.transpose(0, 2, 1)),
        Mistake(
            "order",
            "the product in the wrong order: z-y-x Euler angles give R = Rz(alpha) Ry(beta) Rx(gamma)",
            np.stack([Rotation.from_euler("XYZ", a[::-1]).as_matrix() for a in _ANGLES]),  # Rx Ry Rz
        ),
        Mistake(
            "degrees",
            "the angles are radians: do not convert them (np.radians) again",
            np.stack([_R_zyx(*np.radians(a)) for a in _ANGLES]),
        ),
        *flips,
        Mistake(
            "not_rotation",
            "not a rotation: R R^T should be I and det R = 1",
            test=lambda g: not all(close(r @ r.T, np.eye(3), 1e-6) for r in g),
        ),
    ]
    return verdict(name, got, want, 1e-9, mistakes, "a rotation, but not Rz(alpha) Ry(beta) Rx(gamma)")


def _euler_model(X, b):
    return X[:3] + b @ _R_zyx(*X[3:]).T


_STATE_NAMES = ("x", "y", "z", "alpha", "beta", "gamma")


@checked
def check_measurement_jacobian(measurement_jacobian) -> Feedback:
    """Check ``measurement_jacobian(X, b_O) -> C`` (3n, 6) of Eq. (3), ``d_j = x_r + R(x_o) b_j``, against
    central finite differences of the model (written with SciPy's rotations); rows ``3j..3j+2`` are
    feature ``j``."""
    name = "measurement_jacobian"
    rng = np.random.default_rng(3)
    X = np.array([0.1, -0.2, 1.5, 0.4, -0.3, 0.7])
    b = rng.uniform(-0.14, 0.14, (4, 3))
    n = len(b)
    got = answer_array(name, call_answer(name, measurement_jacobian, X.copy(), b.copy()), (3 * n, 6))
    h = 1e-6
    want = np.column_stack(
        [((_euler_model(X + h * e, b) - _euler_model(X - h * e, b)) / (2 * h)).ravel() for e in np.eye(6)]
    )
    by_coordinate = want.reshape(n, 3, 6).transpose(1, 0, 2).reshape(3 * n, 6)
    mistakes = [
        Mistake(
            "row_order",
            "rows in the wrong order: rows 3j..3j+2 belong to feature j (x, y, z of d_j)",
            by_coordinate,
        ),
        *[
            Mistake(
                f"sign_{_STATE_NAMES[k]}",
                f"column {k} (d/d{_STATE_NAMES[k]}) has the wrong sign",
                want * np.where(np.arange(6) == k, -1.0, 1.0),
            )
            for k in range(6)
        ],
        Mistake(
            "translation",
            "the first three columns: d_j moves one for one with x_r, so each 3 x 3 block starts with I",
            test=lambda g: close(g[:, 3:], want[:, 3:], 1e-5) and not close(g[:, :3], want[:, :3], 1e-5),
        ),
    ]

    def wrong_columns(g):
        bad = [_STATE_NAMES[k] for k in range(6) if not close(g[:, k], want[:, k], 1e-5)]
        return f"differs from finite differences in the column(s) of {', '.join(bad)}"

    fb = verdict(name, got, want, 1e-5, mistakes, "")
    return fb if fb.message else Feedback(name, Status.WRONG, wrong_columns(got))


def _kalman_inputs():
    rng = np.random.default_rng(7)
    A = rng.normal(size=(6, 6))
    Sigma_bar = A @ A.T / 6 + 0.1 * np.eye(6)
    C = rng.normal(size=(9, 6))
    B = rng.normal(size=(9, 9))
    Sigma_m = B @ B.T / 9 + 0.2 * np.eye(9)
    return rng.normal(size=6), Sigma_bar, rng.normal(size=9), C, Sigma_m


@checked
def check_kalman_update(kalman_update) -> Feedback:
    r"""Check ``kalman_update(mu_bar, Sigma_bar, y, C, Sigma_m) -> (mu, Sigma)`` (``y`` the innovation
    ``D - H(mu_bar)``) against the information form of the same update,
    :math:`\Sigma^{-1} = \bar\Sigma^{-1} + C^T \Sigma_m^{-1} C`,
    :math:`\mu = \bar\mu + \Sigma C^T \Sigma_m^{-1} y`."""
    name = "kalman_update"
    mu_bar, Sb, y, C, Sm = _kalman_inputs()
    out = call_answer(name, kalman_update, mu_bar.copy(), Sb.copy(), y.copy(), C.copy(), Sm.copy())
    if not (isinstance(out, tuple | list) and len(out) == 2):
        return Feedback(name, Status.ERROR, "return the pair (mu, Sigma)")
    mu, Sigma = answer_array(name, out[0], (6,)), answer_array(name, out[1], (6, 6))
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
        Mistake(
            "innovation_sign",
            "a wrong sign: the innovation y = D - H(mu_bar) is ADDED, mu = mu_bar + K y",
            np.concatenate([mu_bar - K_ref @ y, Sigma_ref.ravel()]),
        ),
        Mistake(
            "missing_noise",
            "S = C Sigma_bar C^T + Sigma_m: you left out the measurement noise",
            with_gain(Sb @ C.T @ inv(C @ Sb @ C.T)),
        ),
        Mistake(
            "covariance_unchanged",
            "the mean is right, but the covariance did not shrink: Sigma = "
            "(I - K C) Sigma_bar (I - K C)^T + K Sigma_m K^T",
            test=lambda g: close(g[:6], want[:6], 1e-8) and close(g[6:], Sb.ravel(), 1e-8),
        ),
        Mistake(
            "no_inverse",
            "the gain is K = Sigma_bar C^T S^{-1}: multiply by the INVERSE of S",
            with_gain(Sb @ C.T @ S),
        ),
        Mistake(
            "not_symmetric",
            "the covariance is not symmetric: is a transpose missing in the Joseph form?",
            test=lambda g: not close(g[6:].reshape(6, 6), g[6:].reshape(6, 6).T, 1e-8),
        ),
    ]
    return verdict(
        name, got, want, 1e-8, mistakes, "not the Kalman update: compute S, then K, then mu and Sigma"
    )
