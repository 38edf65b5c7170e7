"""Graded tests of assignment 2 (model probabilities and next-best view). Never released to students.

Expected values come from SciPy (``logsumexp``, ``entropy``, the multivariate normal) and the papers'
equations written out here, independent of the reference solution. All data are seeded.
"""

import math

import numpy as np
from scipy.special import logsumexp
from scipy.stats import entropy as scipy_entropy
from scipy.stats import multivariate_normal

from lab.grading.suite import TestSuite, as_array, as_float, check_close, fail, fmt

suite = TestSuite("planning")

DELTA_O = np.array([0.003, -0.002, 0.004])  # [m]
SIGMA_O = np.diag([0.005, 0.005, 0.008]) ** 2  # [m^2]


# ------------------------------------------------------------------------------------------ oracles
def posterior_ref(P, ll, floor=0.0):
    P = np.asarray(P, float)
    with np.errstate(divide="ignore"):
        lp = np.log(P) + ll
    post = np.exp(lp - logsumexp(lp))
    return floor + (1 - P.size * floor) * post


def fll_ref(W, delta=DELTA_O, Sigma=SIGMA_O):
    return np.asarray(W, float) * multivariate_normal(np.zeros(3), Sigma).logpdf(delta)


def expected_entropy_ref(P, W, delta=DELTA_O, Sigma=SIGMA_O):
    ll = fll_ref(W, delta, Sigma)
    return float(sum(P[i] * scipy_entropy(posterior_ref(P, ll[i])) for i in range(len(P)) if P[i] > 0))


def _posterior(sub, P, ll, floor=None, what="model_probabilities(P_prior, log_likelihood)"):
    out = sub.model_probabilities(P, ll) if floor is None else sub.model_probabilities(P, ll, floor)
    post = as_array(out, what, (len(P),), finite=False)
    if not np.all(np.isfinite(post)):
        fail(
            f"{what} returned {fmt(post)} for log-likelihoods around {fmt(np.max(ll), 6)}: exp() of such "
            "numbers "
            "underflows to 0 (or overflows to inf), giving 0/0. Subtract the largest log term before "
            "exponentiating (the log-sum-exp trick)."
        )
    if not abs(post.sum() - 1.0) <= 1e-9:
        fail(
            f"{what} returned probabilities that sum to {post.sum():.6g}, not 1: normalise by Eq. (7)'s "
            f"denominator (got {fmt(post)})"
        )
    return post


def _random_P(rng, L):
    return rng.dirichlet(np.ones(L))


# ---------------------------------------------------------------------------------- model probabilities
@suite.test(
    "model_probabilities: Bayes' rule, Eq. (7), on moderate likelihoods",
    points=2,
    target="model_probabilities",
    visibility="visible",
)
def posterior_bayes(sub):
    rng = np.random.default_rng(11)
    for L in (2, 4, 4, 6):
        P, ll = _random_P(rng, L), rng.normal(0, 3, L)
        post = _posterior(sub, P, ll)
        check_close(
            post,
            posterior_ref(P, ll),
            f"model_probabilities for P = {fmt(P, 3)}, log-likelihoods {fmt(ll, 3)}",
            rtol=1e-9,
            atol=1e-12,
            hint="P_i is proportional to p(D | M_i) P_i, i.e. to exp(log_likelihood_i) * P_prior_i.",
        )


@suite.test(
    "model_probabilities works in log space: log-likelihoods near -5000 and a model with prior 0",
    points=2,
    target="model_probabilities",
)
def posterior_log_space(sub):
    rng = np.random.default_rng(12)
    for shift in (-5000.0, -1e5, 3000.0):
        P = np.array([0.4, 0.3, 0.0, 0.3])
        ll = shift + rng.normal(0, 4, 4)
        post = _posterior(sub, P, ll)
        if post[2] != 0.0:
            fail(f"model_probabilities gives probability {post[2]:.3g} to a model whose prior is 0 (floor 0)")
        check_close(
            post,
            posterior_ref(P, ll),
            f"model_probabilities with log-likelihoods {fmt(ll, 6)}",
            rtol=1e-8,
            atol=1e-12,
        )


@suite.test(
    "model_probabilities: the floor P = floor + (1 - L floor) posterior",
    points=1,
    target="model_probabilities",
)
def posterior_floor(sub):
    P = np.array([0.25, 0.25, 0.25, 0.25])
    ll = np.array([-10.0, -12.0, -3000.0, -11.0])
    floor = 0.02
    post = _posterior(sub, P, ll, floor, "model_probabilities(P_prior, log_likelihood, floor=0.02)")
    want = posterior_ref(P, ll, floor)
    if not post.min() >= floor - 1e-12:
        fail(f"with floor = {floor}, model_probabilities returned {fmt(post)}: an entry is below the floor")
    clip = np.maximum(posterior_ref(P, ll), floor)
    if np.allclose(post, clip / clip.sum(), atol=1e-12) and not np.allclose(post, want, atol=1e-12):
        fail(
            "model_probabilities clips at the floor and renormalises; the floor here is the mixture "
            "P = floor + (1 - L floor) * posterior (see the docstring)"
        )
    check_close(post, want, "model_probabilities with floor = 0.02", rtol=1e-9, atol=1e-12)


@suite.test(
    "model_probabilities is a recursion: two updates equal one with the summed log-likelihoods",
    points=1,
    target="model_probabilities",
)
def posterior_recursive(sub):
    rng = np.random.default_rng(14)
    P0 = _random_P(rng, 5)
    ll1, ll2 = rng.normal(-50, 5, 5), rng.normal(-80, 5, 5)
    P1 = _posterior(sub, P0, ll1)
    P2 = _posterior(sub, P1, ll2)
    both = _posterior(sub, P0, ll1 + ll2)
    check_close(
        P2, both, "two successive updates vs one update with log-likelihoods summed", rtol=1e-8, atol=1e-12
    )
    check_close(both, posterior_ref(P0, ll1 + ll2), "model_probabilities", rtol=1e-8, atol=1e-12)


# -------------------------------------------------------------------------------------------- entropy
@suite.test(
    "entropy: -sum P log P in nats, Eq. (5): SciPy's values, log L for the uniform distribution",
    points=1,
    target="entropy",
    visibility="visible",
)
def entropy_values(sub):
    rng = np.random.default_rng(21)
    for L in (2, 4, 7):
        H = as_float(sub.entropy(np.full(L, 1.0 / L)), f"entropy of the uniform distribution over {L} models")
        if not abs(H - np.log(L)) <= 1e-9:
            hint = " (that is log2: use the natural log)" if math.isclose(H, np.log2(L), rel_tol=1e-9) else ""
            fail(
                f"entropy of the uniform distribution over {L} models is {H:.6g}, expected log {L} = "
                f"{np.log(L):.6g}{hint}"
            )
    for _ in range(30):
        P = _random_P(rng, 4)
        H = as_float(sub.entropy(P), f"entropy({fmt(P, 3)})")
        if not abs(H - scipy_entropy(P)) <= 1e-9:
            fail(f"entropy({fmt(P, 4)}) is {H:.6g}, expected {scipy_entropy(P):.6g}")
    return "uniform over 2, 4, 7 models and 30 seeded distributions"


@suite.test(
    "entropy with zero probabilities: 0 log 0 = 0 (a certain model has entropy 0, not NaN)",
    points=1,
    target="entropy",
)
def entropy_zero_probabilities(sub):
    for P, want in (([1.0, 0.0, 0.0, 0.0], 0.0), ([0.5, 0.5, 0.0, 0.0], np.log(2)), ([0.0, 0.2, 0.8], None)):
        want = scipy_entropy(P) if want is None else want
        H = as_float(sub.entropy(np.array(P)), f"entropy({P})", finite=False)
        if not np.isfinite(H):
            fail(
                f"entropy({P}) is {H}: 0 * log 0 gives NaN in floating point; leave out the zero "
                "probabilities (the limit of p log p at 0 is 0)"
            )
        if not abs(H - want) <= 1e-12:
            fail(f"entropy({P}) is {H:.6g}, expected {want:.6g}")


# --------------------------------------------------------------------------- eq. (15) and expectations
@suite.test(
    "feature_log_likelihood: W times the log-density of one 3-D Gaussian residual, Eq. (15)",
    points=1,
    target="feature_log_likelihood",
)
def feature_log_likelihood_eq15(sub):
    rng = np.random.default_rng(31)
    for W in (0, 1, 37):
        got = as_float(sub.feature_log_likelihood(W, DELTA_O, SIGMA_O), f"feature_log_likelihood({W}, ...)")
        want = float(fll_ref(W))
        if abs(got - want) <= 1e-9 * max(1.0, abs(want)):
            continue
        _, ld = np.linalg.slogdet(SIGMA_O)
        as_printed = -0.5 * W * (np.log(2 * np.pi) + ld + DELTA_O @ np.linalg.solve(SIGMA_O, DELTA_O))
        if math.isclose(got, as_printed, rel_tol=1e-9, abs_tol=1e-9):
            fail(
                f"feature_log_likelihood({W}) = {got:.6g} uses (2 pi)^(W/2) as printed in the paper; each "
                "feature "
                f"is a 3-D Gaussian, so the normalisation is (2 pi)^(3W/2) (expected {want:.6g})"
            )
        fail(f"feature_log_likelihood({W}, delta_o, Sigma_o) is {got:.6g}, expected {want:.6g}")
    Wm = rng.integers(0, 80, (4, 4))
    got = as_array(
        sub.feature_log_likelihood(Wm, DELTA_O, SIGMA_O), "feature_log_likelihood(W (4x4), ...)", (4, 4)
    )
    check_close(got, fll_ref(Wm), "feature_log_likelihood for a 4x4 W", rtol=1e-9, atol=1e-9)


@suite.test(
    "expected_entropy: sum_i P_i H(posterior if M_i is true), Eqs. (10) and (15)",
    points=2,
    target="expected_entropy",
    uses=("model_probabilities", "entropy", "feature_log_likelihood"),
)
def expected_entropy_value(sub):
    rng = np.random.default_rng(41)
    for L in (2, 4, 4, 5):
        P = _random_P(rng, L)
        W = rng.integers(0, 6, (L, L)) + np.diag(rng.integers(0, 8, L))
        got = as_float(
            sub.expected_entropy(P, W, DELTA_O, SIGMA_O), "expected_entropy(P, W, delta_o, Sigma_o)"
        )
        want = expected_entropy_ref(P, W)
        if not abs(got - want) <= 1e-8:
            fail(
                f"expected_entropy for P = {fmt(P, 3)} and W =\n{W}\nis {got:.6g}, expected {want:.6g}. For "
                "each i: "
                "log-likelihoods feature_log_likelihood(W[i], ...) over the candidate models j, the "
                "posterior from "
                "P and those (Eq. (7), no floor), its entropy; then the P-weighted sum."
            )
    return "4 seeded (P, W) pairs"


@suite.test(
    "expected_entropy: within [0, log L], equal to H(P) for an uninformative action, right for hundreds "
    "of features (also with nearly equal counts: no overflow)",
    points=1,
    target="expected_entropy",
    uses=("model_probabilities", "entropy", "feature_log_likelihood"),
)
def expected_entropy_properties(sub):
    rng = np.random.default_rng(42)
    L = 4
    P = np.array([0.4, 0.3, 0.2, 0.1])
    flat = np.tile(rng.integers(5, 50, (L, 1)), (1, L))  # every candidate matches equally well
    got = as_float(sub.expected_entropy(P, flat, DELTA_O, SIGMA_O), "expected_entropy for an uninformative W")
    if not abs(got - scipy_entropy(P)) <= 1e-9:
        fail(
            f"for W with constant rows (every model matches equally) nothing is learnt, so expected_entropy "
            f"should equal entropy(P) = {scipy_entropy(P):.6g}; got {got:.6g}"
        )
    # counts in the hundreds: exp() of their log-likelihoods overflows. Spread widely, every hypothetical
    # posterior is certain (entropy 0 whatever the arithmetic); a count or two apart, it is not.
    Ws = [rng.integers(0, 300, (L, L)) for _ in range(6)] + [
        250 + rng.integers(0, 2, (L, L)) for _ in range(4)
    ]
    for W in Ws:
        got = as_float(
            sub.expected_entropy(P, W, DELTA_O, SIGMA_O), f"expected_entropy with W up to {W.max()}"
        )
        if not (-1e-12 <= got <= np.log(L) + 1e-12):
            fail(f"expected_entropy = {got:.6g} is outside [0, log {L}] for W =\n{W}")
        want = expected_entropy_ref(P, W)
        if not abs(got - want) <= 1e-8:
            fail(f"expected_entropy with W up to {W.max()} features is {got:.6g}, expected {want:.6g}")


def _pair(out):
    if not (isinstance(out, list) and len(out) == 2):
        fail(f"next_best_action must return a pair (best, gains); it returned {type(out).__name__}")
    return out


@suite.test(
    "next_best_action picks the largest information gain, Eqs. (4) and (6); ties go to the first",
    points=2,
    target="next_best_action",
    uses=("expected_entropy", "entropy"),
)
def next_best_action_choice(sub):
    L = 4
    P = np.array([0.3, 0.3, 0.2, 0.2])
    shared = np.full((L, L), 40)  # looking at a face every box shares: nothing to learn
    group = np.array([0, 0, 1, 1])
    pairs = np.where(group[:, None] == group[None, :], 30, 20)  # tells {M0, M1} from {M2, M3} only
    unique = 5 + 60 * np.eye(L, dtype=int)  # the unique face: only the true model matches
    W_actions = np.stack([shared, pairs, unique, unique, pairs])
    out = _pair(sub.next_best_action(P, W_actions, DELTA_O, SIGMA_O))
    best = as_float(out[0], "best from next_best_action")
    gains = as_array(out[1], "gains from next_best_action", (5,))
    H = scipy_entropy(P)
    want = np.array([H - expected_entropy_ref(P, W) for W in W_actions])
    check_close(gains, want, "gains from next_best_action (I_u = H(P) - E[H+_u])", rtol=1e-8, atol=1e-9)
    if best != 2:
        fail(
            f"next_best_action chose action {best:g}; the gains are {fmt(want, 4)}, so the best is 2 "
            "(viewing the "
            "unique faces; action 3 ties with it and comes later)"
        )
    rng = np.random.default_rng(43)
    for _ in range(5):
        P = _random_P(rng, L)
        Ws = rng.integers(0, 40, (6, L, L))
        out = _pair(sub.next_best_action(P, Ws, DELTA_O, SIGMA_O))
        want = np.array([scipy_entropy(P) - expected_entropy_ref(P, W) for W in Ws])
        check_close(
            as_array(out[1], "gains from next_best_action", (6,)),
            want,
            "gains from next_best_action",
            rtol=1e-8,
            atol=1e-9,
        )
        best = as_float(out[0], "best from next_best_action")
        if best not in range(len(Ws)) or not want[int(best)] >= want.max() - 1e-9:
            fail(
                f"next_best_action chose {best:g}, but the largest gain is that of action "
                f"{int(np.argmax(want))}: "
                f"{fmt(want, 4)}"
            )
    return "a designed 4-box scene and 5 seeded ones"
