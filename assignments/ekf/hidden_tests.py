"""Graded tests of assignment 1 (the pose EKF). Never released to students.

Every expected value comes from an independent source, not from the reference solution: SciPy's
rotations, central differences, the Kalman equations written out densely here, SciPy's multivariate
normal, and a simulated static object whose true pose is known. All data are seeded.
"""

import math

import numpy as np
from scipy.spatial.transform import Rotation
from scipy.stats import chi2, multivariate_normal

from lab.grading.suite import TestSuite, as_array, as_float, check_close, fail, fmt

suite = TestSuite("ekf")

ANGLE_NAMES = ("alpha", "beta", "gamma")
COLUMN_NAMES = ("x", "y", "z", "alpha", "beta", "gamma")


# ------------------------------------------------------------------------------------------ oracles
def R_ref(alpha, beta, gamma):
    return Rotation.from_euler("ZYX", [alpha, beta, gamma]).as_matrix()  # intrinsic z-y-x


def H_ref(X, b):
    return b @ R_ref(*X[3:]).T + X[:3]


def C_fd(X, b, h=1e-6):
    """Central differences of the true measurement model, shape (3n, 6)."""
    cols = []
    for k in range(6):
        e = np.zeros(6)
        e[k] = h
        cols.append(((H_ref(X + e, b) - H_ref(X - e, b)) / (2 * h)).reshape(-1))
    return np.stack(cols, axis=1)


def kalman_ref(mu_bar, Sigma_bar, y, C, Sigma_m):
    S = C @ Sigma_bar @ C.T + Sigma_m
    K = Sigma_bar @ C.T @ np.linalg.inv(S)
    I_KC = np.eye(6) - K @ C
    return mu_bar + K @ y, I_KC @ Sigma_bar @ I_KC.T + K @ Sigma_m @ K.T


def random_pose(rng, angle=0.8):
    return np.concatenate([rng.uniform([-0.3, -0.2, 0.8], [0.3, 0.2, 2.0]), rng.uniform(-angle, angle, 3)])


def random_features(rng, n):
    return rng.uniform(-0.14, 0.14, (n, 3))  # on a 0.28 m box


def random_spd(rng, n, scale):
    A = rng.normal(size=(n, n))
    return scale * (A @ A.T / n + 0.2 * np.eye(n))


def block_diag_cov(rng, n, sigma):
    """Per-feature 3x3 covariances (stereo: depth worse than the image directions), stacked (3n, 3n)."""
    S = np.zeros((3 * n, 3 * n))
    for j in range(n):
        s = sigma * rng.uniform(0.7, 1.3)
        S[3 * j : 3 * j + 3, 3 * j : 3 * j + 3] = np.diag([s**2, s**2, (2.5 * s) ** 2])
    return S


# ----------------------------------------------------------------------------------------- rotation
@suite.test(
    "rotation_zyx equals Rz(alpha) Ry(beta) Rx(gamma) (SciPy's intrinsic 'ZYX')",
    points=1,
    target="rotation_zyx",
    visibility="visible",
)
def rotation_matches_scipy(sub):
    rng = np.random.default_rng(101)
    for a, b, g in rng.uniform(-np.pi, np.pi, (12, 3)) * [1, 0.49, 1]:
        R = as_array(
            sub.rotation_zyx(float(a), float(b), float(g)), "rotation_zyx(alpha, beta, gamma)", (3, 3)
        )
        want = R_ref(a, b, g)
        if np.allclose(R, want, atol=1e-9):
            continue
        call = f"rotation_zyx({a:.3f}, {b:.3f}, {g:.3f})"
        if np.allclose(R, want.T, atol=1e-9):
            fail(f"{call} returned the transpose of R: check the signs of the sines in Rz, Ry, Rx")
        if np.allclose(R, Rotation.from_euler("zyx", [a, b, g]).as_matrix(), atol=1e-9):
            fail(
                f"{call} multiplies in the wrong order (Rx Ry Rz); the papers use R = Rz(alpha) Ry(beta) "
                "Rx(gamma)"
            )
        check_close(R, want, call, atol=1e-9)
    return "12 seeded angle triples match SciPy to 1e-9"


# -------------------------------------------------------------------------------- measurement model
@suite.test(
    "measurement_model: d_j = x_r + R(x_o) b_j, Eq. (3)",
    points=2,
    target="measurement_model",
    uses=("rotation_zyx",),
    visibility="visible",
)
def measurement_model_eq3(sub):
    rng = np.random.default_rng(202)
    for n in (1, 7, 40):
        X, b = random_pose(rng), random_features(rng, n)
        d = as_array(sub.measurement_model(X, b), f"measurement_model(X, b_O) with n = {n}", (n, 3))
        want = H_ref(X, b)
        if not np.allclose(d, want, atol=1e-9):
            if np.allclose(d, b @ R_ref(*X[3:]) + X[:3], atol=1e-9):
                fail(
                    "measurement_model applies R^T instead of R (b @ R where it should be b @ R.T, i.e. R "
                    "@ b_j) "
                    f"for n = {n}"
                )
            if np.allclose(d, b @ R_ref(*X[3:]).T, atol=1e-9):
                fail(f"measurement_model forgets the translation x_r = X[:3] (n = {n})")
            check_close(d, want, f"measurement_model(X, b_O) with n = {n}", atol=1e-9)
    return "n = 1, 7 and 40 features at seeded poses"


# ------------------------------------------------------------------------------------------ jacobian
@suite.test(
    "measurement_jacobian: shape (3n, 6), identity blocks in the translation columns, the alpha column "
    "e_z x R b_j",
    points=1,
    target="measurement_jacobian",
)
def jacobian_shape_and_translation(sub):
    rng = np.random.default_rng(303)
    for n in (1, 5):
        X, b = random_pose(rng), random_features(rng, n)
        C = as_array(sub.measurement_jacobian(X, b), f"measurement_jacobian(X, b_O) with n = {n}", (3 * n, 6))
        check_close(
            C[:, :3],
            np.tile(np.eye(3), (n, 1)),
            f"the translation columns C[:, :3] (n = {n})",
            atol=1e-9,
            hint="d d_j / d x_r is the 3x3 identity for every feature j (rows 3j..3j+2).",
        )
        Rb = b @ R_ref(*X[3:]).T  # R b_j, one row per feature
        rot = C[:, 3:].reshape(n, 3, 3)
        for j in range(n):
            if not np.abs(rot[j]).max() >= 1e-6 * np.linalg.norm(b[j]):
                fail(
                    f"the rotation columns C[:, 3:] are zero for feature {j} (n = {n}): turning the object "
                    "moves every feature off its centre, d d_j / d theta = (dR/dtheta) b_j"
                )
        # turning by alpha turns about the camera's z axis: Rz' Ry Rx b_j = e_z x (R b_j)
        check_close(
            rot[:, :, 0],
            np.cross([0.0, 0.0, 1.0], Rb),
            f"the alpha column C[:, 3] (n = {n})",
            atol=1e-9,
            hint="d d_j / d alpha = Rz'(alpha) Ry Rx b_j, which is e_z x (R b_j).",
        )


@suite.test(
    "measurement_jacobian matches central differences of H at seeded poses",
    points=3,
    target="measurement_jacobian",
)
def jacobian_finite_differences(sub):
    rng = np.random.default_rng(404)
    poses = [random_pose(rng) for _ in range(5)] + [np.array([0.1, -0.1, 1.5, 2.5, 1.3, -2.8])]
    worst = 0.0
    for X in poses:
        n = 6
        b = random_features(rng, n)
        C = as_array(sub.measurement_jacobian(X, b), "measurement_jacobian(X, b_O)", (3 * n, 6))
        F = C_fd(X, b)
        err = np.abs(C - F)
        worst = max(worst, float(err.max()))
        if err.max() <= 1e-6:
            continue
        at = f"at X = {fmt(X, 3)}"
        if np.allclose(C, F.reshape(n, 3, 6).transpose(1, 0, 2).reshape(3 * n, 6), atol=1e-6):
            fail(
                f"measurement_jacobian {at}: rows are stacked coordinate by coordinate; Eq. (3) stacks "
                "feature "
                "by feature (rows 3j..3j+2 belong to d_j)"
            )
        bad = [k for k in range(6) if np.abs(C[:, k] - F[:, k]).max() > 1e-6]
        flipped = [k for k in bad if np.allclose(C[:, k], -F[:, k], atol=1e-6)]
        names = ", ".join(f"{k} (d/d {COLUMN_NAMES[k]})" for k in bad)
        msg = (
            f"measurement_jacobian {at} differs from central differences of H in column(s) {names}; "
            f"largest error {fmt(err.max(), 3)} (tolerance 1e-6)."
        )
        if flipped:
            msg += (
                f"\nColumn(s) {', '.join(COLUMN_NAMES[k] for k in flipped)} have exactly the wrong sign: "
                "check the sign of the derivative of the elementary rotation (d/da of cos a is -sin a)."
            )
        elif bad and all(k >= 3 for k in bad):
            msg += (
                "\nThe translation columns are right; check dR/dtheta for the angle(s) named: "
                "dR/dalpha = Rz' Ry Rx, dR/dbeta = Rz Ry' Rx, dR/dgamma = Rz Ry Rx'."
            )
        k = bad[0] if bad else int(np.argmax(err.max(axis=0)))
        msg += f"\nColumn {k}: got {fmt(C[:6, k], 4)}..., finite differences give {fmt(F[:6, k], 4)}..."
        fail(msg)
    return f"6 seeded poses (one with |beta| = 1.3 rad); largest error {worst:.1e}"


# -------------------------------------------------------------------------------------- kalman update
def _kalman_case(rng, n):
    mu_bar = random_pose(rng)
    Sigma_bar = random_spd(rng, 6, 1e-3)
    C = rng.normal(size=(3 * n, 6))
    Sigma_m = random_spd(rng, 3 * n, 1e-4)
    y = rng.normal(scale=0.02, size=3 * n)
    return mu_bar, Sigma_bar, y, C, Sigma_m


@suite.test(
    "kalman_update: mu = mu_bar + K y and the Joseph-form covariance", points=2, target="kalman_update"
)
def kalman_update_matches_equations(sub):
    rng = np.random.default_rng(505)
    for n in (1, 4, 12):
        mu_bar, Sigma_bar, y, C, Sigma_m = _kalman_case(rng, n)
        out = sub.kalman_update(mu_bar, Sigma_bar, y, C, Sigma_m)
        if not (isinstance(out, list) and len(out) == 2):
            fail(
                f"kalman_update must return a pair (mu, Sigma); it returned {type(out).__name__}"
                + (f" of length {len(out)}" if isinstance(out, list) else "")
            )
        mu = as_array(out[0], "mu from kalman_update", (6,))
        Sigma = as_array(out[1], "Sigma from kalman_update", (6, 6))
        mu_want, Sigma_want = kalman_ref(mu_bar, Sigma_bar, y, C, Sigma_m)
        K = Sigma_bar @ C.T @ np.linalg.inv(C @ Sigma_bar @ C.T + Sigma_m)
        if np.allclose(mu, mu_bar - K @ y, atol=1e-10) and not np.allclose(mu, mu_want, atol=1e-10):
            fail("kalman_update moves the state the wrong way: mu = mu_bar + K y with y = D - H(mu_bar)")
        check_close(mu, mu_want, f"mu from kalman_update (m = {3 * n})", rtol=1e-7, atol=1e-10)
        I_KC = np.eye(6) - K @ C
        if np.allclose(Sigma, I_KC @ Sigma_bar @ I_KC.T, rtol=1e-6, atol=1e-14):
            fail("Sigma from kalman_update lacks the + K Sigma_m K^T term of the Joseph form")
        check_close(Sigma, Sigma_want, f"Sigma from kalman_update (m = {3 * n})", rtol=1e-6, atol=1e-14)
    return "m = 3, 12 and 36 measurements, random SPD covariances"


@suite.test(
    "kalman_update: the posterior covariance is symmetric, positive definite and no larger than the "
    "prior, also with very precise measurements",
    points=1,
    target="kalman_update",
)
def kalman_update_covariance(sub):
    rng = np.random.default_rng(606)
    for scale_m in (1e-4, 1e-12):
        mu_bar, Sigma_bar, y, C, _ = _kalman_case(rng, 8)
        Sigma_m = random_spd(rng, 24, scale_m)
        out = sub.kalman_update(mu_bar, Sigma_bar, y, C, Sigma_m)
        if not (isinstance(out, list) and len(out) == 2):
            fail("kalman_update must return a pair (mu, Sigma)")
        Sigma = as_array(out[1], "Sigma from kalman_update", (6, 6))
        top = np.abs(Sigma).max()
        if not np.abs(Sigma - Sigma.T).max() <= 1e-9 * top:
            fail(
                "Sigma from kalman_update is not symmetric (|Sigma - Sigma^T| up to "
                f"{fmt(np.abs(Sigma - Sigma.T).max(), 3)}"
                f" with Sigma_m ~ {scale_m:g}): the Joseph form keeps it symmetric"
            )
        ev = np.linalg.eigvalsh(0.5 * (Sigma + Sigma.T))
        if not ev.min() > 0:
            fail(
                f"Sigma from kalman_update is not positive definite (smallest eigenvalue {fmt(ev.min(), 3)} "
                "with "
                f"Sigma_m ~ {scale_m:g}): use the Joseph form"
            )
        shrink = np.linalg.eigvalsh(Sigma_bar - 0.5 * (Sigma + Sigma.T)).min()
        if not shrink >= -1e-9 * np.abs(Sigma_bar).max():
            fail(
                "Sigma from kalman_update is larger than Sigma_bar in some direction: a measurement can only "
                "reduce uncertainty"
            )
        if np.allclose(Sigma, Sigma_bar, rtol=1e-6, atol=0.0):
            fail(
                f"Sigma from kalman_update equals Sigma_bar (with Sigma_m ~ {scale_m:g}): 24 measurements "
                "must shrink it, Sigma = (I - K C) Sigma_bar (I - K C)^T + K Sigma_m K^T"
            )
        # the information form, another route to the same posterior: (Sigma_bar^-1 + C^T Sigma_m^-1 C)^-1
        Sigma_info = np.linalg.inv(np.linalg.inv(Sigma_bar) + C.T @ np.linalg.solve(Sigma_m, C))
        check_close(
            Sigma,
            Sigma_info,
            f"Sigma from kalman_update with Sigma_m ~ {scale_m:g}",
            rtol=1e-4,
            atol=1e-4 * np.abs(Sigma_info).max(),
            hint="It should equal the information form (Sigma_bar^-1 + C^T Sigma_m^-1 C)^-1.",
        )


# ----------------------------------------------------------------------------------- log likelihood
@suite.test(
    "data_log_likelihood equals log N(y; 0, C Sigma_bar C^T + Sigma_m), Eq. (9), without underflow",
    points=2,
    target="data_log_likelihood",
)
def log_likelihood_eq9(sub):
    rng = np.random.default_rng(707)
    for n, far in ((1, 1.0), (10, 1.0), (60, 1.0), (60, 8.0)):
        _, Sigma_bar, y, C, Sigma_m = _kalman_case(rng, n)
        Sigma_m = block_diag_cov(rng, n, 0.004)
        S = C @ Sigma_bar @ C.T + Sigma_m
        y = far * rng.multivariate_normal(np.zeros(3 * n), S)
        want = multivariate_normal(np.zeros(3 * n), S).logpdf(y)
        got = as_float(
            sub.data_log_likelihood(y, C, Sigma_bar, Sigma_m), f"data_log_likelihood (m = {3 * n})"
        )
        if abs(got - want) <= 1e-6 * max(1.0, abs(want)):
            continue
        if math.isclose(got, -want, rel_tol=1e-6, abs_tol=1e-6):
            fail(f"data_log_likelihood has the wrong sign (got {got:.4f}, expected {want:.4f})")
        fail(
            f"data_log_likelihood for m = {3 * n} stacked "
            f"measurements{' far from the prediction' if far > 1 else ''}"
            f" is {got:.6g}, expected {want:.6g} (log N(y; 0, S), natural log, S = C Sigma_bar C^T + Sigma_m)"
        )
    return "m = 3 .. 180; log-likelihoods down to about -1e4"


# -------------------------------------------------------------------------------------- ekf update
def _static_object(rng, n=8):
    X = random_pose(rng, angle=0.6)
    b = random_features(rng, n)
    Sigma_m = block_diag_cov(rng, n, 0.004)
    return X, b, Sigma_m


EKF_HINT = (
    "ekf_update: y = (d_C - measurement_model(mu_bar, b_O)).reshape(-1) (feature by feature), "
    "C = measurement_jacobian(mu_bar, b_O), then kalman_update."
)


@suite.test(
    "ekf_update: one update from a seeded prediction",
    points=1,
    target="ekf_update",
    uses=("measurement_model", "measurement_jacobian", "kalman_update"),
)
def ekf_update_one_step(sub):
    rng = np.random.default_rng(808)
    X, b, Sigma_m = _static_object(rng)
    Sigma_bar = np.diag([0.02**2] * 3 + [0.05**2] * 3)
    mu_bar = X + rng.multivariate_normal(np.zeros(6), Sigma_bar)
    d = H_ref(X, b) + rng.multivariate_normal(np.zeros(Sigma_m.shape[0]), Sigma_m).reshape(-1, 3)
    out = sub.ekf_update(mu_bar, Sigma_bar, d, b, Sigma_m)
    if not (isinstance(out, list) and len(out) == 2):
        fail("ekf_update must return a pair (mu, Sigma)")
    mu = as_array(out[0], "mu from ekf_update", (6,))
    Sigma = as_array(out[1], "Sigma from ekf_update", (6, 6))
    y = (d - H_ref(mu_bar, b)).reshape(-1)
    mu_want, Sigma_want = kalman_ref(mu_bar, Sigma_bar, y, C_fd(mu_bar, b), Sigma_m)
    check_close(mu, mu_want, "mu from ekf_update", rtol=1e-6, atol=1e-8, hint=EKF_HINT)
    check_close(Sigma, Sigma_want, "Sigma from ekf_update", rtol=1e-5, atol=1e-12, hint=EKF_HINT)


@suite.test(
    "ekf_update is consistent: each update equals the EKF written out here, and NEES over 30 seeded runs "
    "of a static object stays near 6",
    points=3,
    target="ekf_update",
    uses=("measurement_model", "measurement_jacobian", "kalman_update"),
    timeout_s=10,
)
def ekf_consistency(sub):
    """Search paper Eq. (4): a static object, X_k = X_{k-1} + eta. The prediction is done here."""
    rng = np.random.default_rng(909)
    runs, steps, dim = 30, 8, 6
    P0 = np.diag([0.02**2] * 3 + [0.05**2] * 3)
    Q = 1e-10 * np.eye(6)
    nees, final_err = [], []
    for _ in range(runs):
        X, b, Sigma_m = _static_object(rng)
        mu, Sigma = X + rng.multivariate_normal(np.zeros(6), P0), P0
        for _ in range(steps):
            Sigma_bar = Sigma + Q  # prediction of the static model
            d = H_ref(X, b) + rng.multivariate_normal(np.zeros(Sigma_m.shape[0]), Sigma_m).reshape(-1, 3)
            out = sub.ekf_update(mu, Sigma_bar, d, b, Sigma_m)
            if not (isinstance(out, list) and len(out) == 2):
                fail("ekf_update must return a pair (mu, Sigma)")
            y = (d - H_ref(mu, b)).reshape(-1)
            mu_want, Sigma_want = kalman_ref(mu, Sigma_bar, y, C_fd(mu, b), Sigma_m)  # from the same input
            mu = as_array(out[0], "mu from ekf_update", (6,))
            Sigma = as_array(out[1], "Sigma from ekf_update", (6, 6))
            where = f"run {len(final_err) + 1}, update {len(nees) % steps + 1}"
            check_close(mu, mu_want, f"mu from ekf_update ({where})", rtol=1e-6, atol=1e-8, hint=EKF_HINT)
            check_close(
                Sigma, Sigma_want, f"Sigma from ekf_update ({where})", rtol=1e-5, atol=1e-12, hint=EKF_HINT
            )
            e = mu - X
            try:
                nees.append(float(e @ np.linalg.solve(Sigma, e)))
            except np.linalg.LinAlgError:
                fail("Sigma from ekf_update became singular during a run")
        final_err.append(np.linalg.norm(mu[:3] - X[:3]))
    mean = float(np.mean(nees))
    lo, hi = (chi2.ppf([0.0005, 0.9995], dim * runs) / runs) * [0.8, 1.25]  # correlated steps: widened
    err_mm = 1000 * float(np.median(final_err))
    if not (lo <= mean <= hi and err_mm <= 10):
        msg = (
            f"average NEES (e^T Sigma^-1 e, e = mu - X_true) over {runs} runs x {steps} updates is "
            f"{mean:.3g}; "
            f"a consistent filter gives about {dim} (pass band [{lo:.2f}, {hi:.2f}]); median final position "
            f"error {err_mm:.1f} mm."
        )
        if mean > hi:
            msg += (
                "\nThe filter is overconfident or diverges: the update moves the state the wrong way or the "
                "covariance shrinks too fast. Check measurement_jacobian against finite differences and the "
                "innovation y = D - H(mu_bar)."
            )
        else:
            msg += "\nThe covariance is larger than the actual errors: check the Joseph form and the gain."
        fail(msg)
    return f"average NEES {mean:.2f} (band [{lo:.2f}, {hi:.2f}]), median final position error {err_mm:.2f} mm"
