"""The stated final pose of identification (lab.identification.final_pose): an update is fused only as
far as it is consistent with the prediction, checked against the truth of synthetic frames and against
the plain filter as the peer where every frame is consistent."""

import copy

import numpy as np
from ekf_scenarios import cube, observe

from lab.estimation import EKFBank, EKFConfig, OrientationChart, PoseEKF, UpdateOutcome
from lab.estimation.fit import chi2_quantile
from lab.geometry import G_to_pose6, Rz, se3
from lab.identification.final_pose import ConsistentShadows, consistent_update, match_mahalanobis

X_TRUE = np.array([0.05, -0.03, 1.1, 0.7, -0.3, 1.9])
I4 = np.eye(4)
CONFIG = EKFConfig(chart=OrientationChart.ROTATION_VECTOR)  # the identification agent's chart
PRIOR_RV = np.diag([0.01**2] * 3 + [np.radians(2.0) ** 2] * 3)  # 1 cm, 2 deg


def frame_with_a_pulled_subset(seed, n=20, n_bad=6, shift=(0.03, 0.0, 0.02)):
    """A filter at the true pose with a 1 cm / 2 deg prior, and a frame of ``n`` matches of which the
    first ``n_bad`` are displaced together by ``shift`` [m]: each within the gate alone (about 3 sigma of
    its predicted covariance), jointly far from the prediction."""
    rng = np.random.default_rng(seed)
    b_O, nrm = cube(rng)
    ekf = PoseEKF(CONFIG, rng=rng)
    ekf.initialize(X_TRUE, None, Sigma_rv=PRIOR_RV)
    f = observe(rng, X_TRUE, b_O, nrm, n_max=n)
    d = f.d_C.copy()
    d[:n_bad] += np.asarray(shift)
    return ekf, d, f.b_O, f.Sigma_d


def test_a_jointly_inconsistent_subset_is_dropped_and_the_pose_stays_on_the_truth():
    for seed in range(4):
        ekf, d, b, S = frame_with_a_pulled_subset(seed)
        plain = copy.deepcopy(ekf)
        r0 = plain.update(d, b, S)
        assert r0.n_used == len(d)  # every match passed the gate alone ...
        assert r0.nis > chi2_quantile(CONFIG.divergence.nis_prob, r0.dof)  # ... not jointly
        mu0 = ekf.mu.copy()
        out, res, kept = consistent_update(ekf, d, b, S)
        assert res is not None and res.outcome is UpdateOutcome.UPDATED
        assert res.nis <= chi2_quantile(CONFIG.divergence.nis_prob, res.dof)
        np.testing.assert_array_equal(kept, np.arange(6, len(d)))  # exactly the pulled six dropped
        clean = copy.deepcopy(ekf)  # the peer: the plain update on the matches that were not pulled
        clean.update(d[6:], b[6:], S[6:])
        np.testing.assert_allclose(out.mu, clean.mu, atol=1e-12)
        err, err_plain = (np.linalg.norm(e.mu[:3] - X_TRUE[:3]) for e in (out, plain))
        assert err < 0.006 and err < err_plain
        np.testing.assert_array_equal(ekf.mu, mu0)  # the filter passed in is left as it was


def test_a_consistent_frame_is_the_plain_update():
    rng = np.random.default_rng(7)
    b_O, nrm = cube(rng)
    ekf = PoseEKF(CONFIG, rng=rng)
    ekf.initialize(X_TRUE, None, Sigma_rv=PRIOR_RV)
    f = observe(rng, X_TRUE, b_O, nrm)
    plain = copy.deepcopy(ekf)
    r0 = plain.update(f.d_C, f.b_O, f.Sigma_d)
    out, res, kept = consistent_update(ekf, f.d_C, f.b_O, f.Sigma_d)
    assert len(kept) == len(f.d_C) and res.nis == r0.nis
    np.testing.assert_allclose(out.mu, plain.mu, atol=1e-12)
    np.testing.assert_allclose(out.P, plain.P, atol=1e-15)


def test_with_too_few_consistent_matches_the_prediction_stands():
    ekf, d, b, S = frame_with_a_pulled_subset(3, n=8, n_bad=6, shift=(0.03, 0.0, 0.02))
    out, res, kept = consistent_update(ekf, d[:6], b[:6], S[:6])  # only the pulled ones
    if res is None:  # every try inconsistent down to fewer than three: the prediction
        assert out is ekf and len(kept) < CONFIG.gate.min_matches
    else:  # or a consistent few: still within the prior's reach of the truth
        assert res.nis <= chi2_quantile(CONFIG.divergence.nis_prob, res.dof)


def test_match_mahalanobis_is_the_hand_computed_distance():
    ekf, d, b, S = frame_with_a_pulled_subset(1)
    m2 = match_mahalanobis(ekf, d, b, S)
    R, p = ekf.estimate.G_CO[:3, :3], ekf.estimate.G_CO[:3, 3]
    for j in (0, 10):
        q = R @ b[j]
        C = np.hstack([np.eye(3), -np.array([[0, -q[2], q[1]], [q[2], 0, -q[0]], [-q[1], q[0], 0]])])
        r = d[j] - (p + q)
        assert np.isclose(m2[j], r @ np.linalg.solve(C @ ekf.P @ C.T + S[j], r), rtol=1e-9)


def run_bank(seed, bad_frame=None, frames=8, pull=(0.0, 0.0, 0.055)):
    """A one-model bank and its consistent copy on frames of the cube at X_TRUE; at ``bad_frame`` a
    third of the matches is pulled together by ``pull`` [m] (along the depth, where the stereo error is
    largest: each within the gate alone)."""
    rng = np.random.default_rng(seed)
    b_O, nrm = cube(rng)
    bank = EKFBank(1, CONFIG, rng=np.random.default_rng(seed))
    shadows = ConsistentShadows(bank)
    for k in range(frames):
        if k:
            shadows.predict(I4, I4, I4, 0.2)
            bank.predict(I4, I4, I4, 0.2)
        f = observe(rng, X_TRUE, b_O, nrm, n_max=24)
        d = f.d_C.copy()
        if k == bad_frame:
            d[:8] += np.asarray(pull)
        m = (d, f.b_O, f.Sigma_d)
        shadows.update(bank.update_all([m]), [m])
    return bank, shadows


def test_the_copy_follows_the_filter_on_consistent_frames_and_not_into_a_pulled_one():
    bank, shadows = run_bank(2)
    np.testing.assert_allclose(shadows.estimate(0).mu, bank[0].estimate.mu, atol=1e-9)
    assert shadows.n_dropped == 0
    for seed in range(5):  # the last frame pulled: the filter is pulled off, its copy much less
        bank, shadows = run_bank(seed, bad_frame=7)
        err_bank = np.linalg.norm(bank[0].estimate.mu[:3] - X_TRUE[:3])
        err_copy = np.linalg.norm(shadows.estimate(0).mu[:3] - X_TRUE[:3])
        assert shadows.n_dropped > 0 and err_bank > 0.012 and err_copy < 0.6 * err_bank


def test_a_reseat_on_a_look_alike_turn_is_applied_to_the_copy():
    bank, shadows = run_bank(4, bad_frame=7)
    before = shadows.estimate(0).G_CO
    e = bank[0].estimate
    turn = se3(Rz(np.pi / 2))
    bank[0].initialize(G_to_pose6(e.G_CO @ turn), None, Sigma_rv=e.Sigma_rv)  # as the agent re-seats
    np.testing.assert_allclose(shadows.estimate(0).G_CO, before @ turn, atol=1e-9)
    np.testing.assert_allclose(shadows.estimate(0).Sigma_rv, shadows.shadows[0].estimate.Sigma_rv)
