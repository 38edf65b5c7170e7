"""Model probabilities, Eqs. (5) and (7)-(9): properties with hypothesis, the scoring of a frame against
every model on synthetic scenes (the model that explains more wins; look-alikes leave them equal), and
bad input."""

import math

import ident_scenes as S
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lab.errors import ConfigError
from lab.estimation import OrientationChart, data_log_likelihood, euler_to_rv_jacobian
from lab.identification import (
    LikelihoodForm,
    ModelScorer,
    ScoringConfig,
    apply_floor,
    calc_current_entropy,
    clutter_log_density,
    entropy,
    pool_shared_evidence,
    posterior,
    shared_features,
    state_for_scoring,
    uniform,
    update_model_probabilities,
)
from lab.robot import StereoCamera
from lab.vision import StereoParams

prob_vectors = st.integers(1, 25).flatmap(
    lambda L: st.lists(st.floats(1e-12, 1.0), min_size=L, max_size=L).map(lambda v: np.array(v) / sum(v))
)


@settings(max_examples=200, deadline=None)
@given(prob_vectors, st.floats(0.0, 0.99))
def test_floor_keeps_the_sum_and_the_floor_and_is_idempotent(P, frac):
    floor = frac / len(P) * 0.5
    Q = apply_floor(P, floor)
    assert Q.sum() == pytest.approx(1.0, abs=1e-12)
    assert np.all(Q >= floor - 1e-15)
    np.testing.assert_allclose(apply_floor(Q, floor), Q, atol=1e-15)
    above = Q > floor * (1 + 1e-9)  # entries above the floor keep their ratios
    if above.sum() >= 2:
        r = Q[above] / P[above]
        np.testing.assert_allclose(r, r[0], rtol=1e-9)
    # along the last axis of a stack too
    np.testing.assert_allclose(apply_floor(np.stack([P, P]), floor)[1], Q, atol=1e-15)


@settings(max_examples=200, deadline=None)
@given(
    prob_vectors,
    st.data(),
    st.sampled_from([1e-3, 1e-4, 0.0]),
    st.floats(1e-3, 1.0),
)
def test_bayes_update_sums_to_one_and_respects_the_floor(prior, data, floor, kappa):
    L = len(prior)
    if L * floor >= 1:
        return
    ll = np.array(data.draw(st.lists(st.floats(-1e6, 1e6), min_size=L, max_size=L)))
    cfg = ScoringConfig(floor=floor, evidence_weight=kappa)
    prior = apply_floor(prior, floor)
    P = update_model_probabilities(prior, ll, cfg)
    assert P.sum() == pytest.approx(1.0, abs=1e-9)
    assert np.all(P >= floor - 1e-15)
    assert 0.0 <= entropy(P) <= math.log(L) + 1e-12
    # the same as the batched form the planner uses
    np.testing.assert_allclose(posterior(np.log(prior), ll[None], cfg)[0], P, atol=1e-12)
    # equal likelihoods teach nothing
    np.testing.assert_allclose(update_model_probabilities(prior, np.full(L, ll[0]), cfg), prior, atol=1e-12)


@settings(max_examples=200, deadline=None)
@given(prob_vectors)
def test_entropy_lies_in_0_log_L(P):
    H = entropy(P)
    assert 0.0 <= H <= math.log(len(P)) + 1e-12
    assert entropy(np.eye(len(P))[0]) == 0.0
    assert entropy(uniform(len(P))) == pytest.approx(math.log(len(P)))


def test_bayes_rule_matches_the_textbook_formula():
    prior = np.array([0.5, 0.3, 0.2])
    ll = np.array([-10.0, -12.0, -9.0])
    cfg = ScoringConfig(evidence_weight=1.0, floor=0.0)
    post = prior * np.exp(ll)
    np.testing.assert_allclose(update_model_probabilities(prior, ll, cfg), post / post.sum(), rtol=1e-12)
    cfg = ScoringConfig(evidence_weight=0.5, floor=0.0)  # the evidence weight: likelihood ** kappa
    post = prior * np.exp(0.5 * ll)
    np.testing.assert_allclose(update_model_probabilities(prior, ll, cfg), post / post.sum(), rtol=1e-12)


def test_a_floored_model_comes_back():
    cfg = ScoringConfig()
    P = update_model_probabilities(uniform(4), [0.0, -5000.0, 0.0, 0.0], cfg)  # one awful frame
    assert P[1] == pytest.approx(cfg.floor)
    for _ in range(3):  # a few frames in its favour (30 features more than the others explain)
        P = update_model_probabilities(P, [0.0, 30 * 15.0, 0.0, 0.0], cfg)
    assert P.argmax() == 1


def test_clutter_density_is_uniform_over_the_stereo_frustum():
    cam = S.CAMERA
    log_c = clutter_log_density(cam, max_depth_m=5.0)
    # by numerical integration of the frustum's slices
    z = np.linspace(cam.fx * cam.baseline / 96.0, 5.0, 200001)
    area = (cam.width * z / cam.fx) * (cam.height * z / cam.fy)
    V = np.trapezoid(area, z)
    assert log_c == pytest.approx(-math.log(V), abs=1e-6)
    assert -4.5 < log_c < -4.1  # 1 / 74 m^3 for the robot's camera
    with pytest.raises(ConfigError):
        clutter_log_density(cam, max_depth_m=0.1)


def test_the_clutter_density_comes_from_the_camera():
    """ScoringConfig.for_camera fills in the camera's clutter density (the robot's default camera:
    bit for bit the value that used to be a constant computed at import), keeps an explicit one, and a
    scorer refuses a config that has none."""
    default = ScoringConfig().for_camera(StereoCamera.from_fov(320, 240, 60.0, 0.12))
    assert default.log_clutter_density == float.fromhex("-0x1.1383e55a78440p+2")  # -4.30492528757992
    assert ScoringConfig().for_camera(S.CAMERA) == default  # the mounting does not matter
    wide = StereoCamera.from_fov(640, 480, 90.0, 0.12)
    assert ScoringConfig().for_camera(wide).log_clutter_density == clutter_log_density(wide)
    assert ScoringConfig().for_camera(wide).log_clutter_density != default.log_clutter_density
    narrow = StereoParams(max_disparity=48)  # the disparity range bounds the nearest depth
    assert ScoringConfig().for_camera(S.CAMERA, narrow).log_clutter_density == clutter_log_density(
        S.CAMERA, narrow
    )
    explicit = ScoringConfig(log_clutter_density=-3.0)
    assert explicit.for_camera(wide) is explicit
    unresolved = ScoringConfig()
    assert unresolved.log_clutter_density is None
    with pytest.raises(ConfigError, match=r"no clutter density.*for_camera\(robot.camera\)"):
        ModelScorer(S.databases()[0], unresolved)
    with pytest.raises(ConfigError, match="no clutter density"):
        pool_shared_evidence([], [], unresolved)
    with pytest.raises(ConfigError, match="finite"):
        ScoringConfig(log_clutter_density=math.inf)


def test_rotation_vector_chart_gives_the_same_eq9_likelihood():
    rng = np.random.default_rng(0)
    mu = np.array([0.1, 0.0, 1.0, 0.3, 0.2, -0.4])
    A = rng.normal(size=(6, 6)) * 0.05
    Sigma = A @ A.T + 1e-4 * np.eye(6)
    b = rng.uniform(-0.14, 0.14, (10, 3))
    d = b + 0.01
    Sd = np.tile(1e-4 * np.eye(3), (10, 1, 1))
    T = euler_to_rv_jacobian(mu)
    ll_euler = data_log_likelihood(d, b, Sd, mu, Sigma)
    ll_rv = data_log_likelihood(d, b, Sd, mu, T @ Sigma @ T.T, chart=OrientationChart.ROTATION_VECTOR)
    assert ll_rv == pytest.approx(ll_euler, rel=1e-9)


# --- scoring frames against models -------------------------------------------------------------------


@pytest.fixture(scope="module")
def scene():
    dbs = S.databases()
    return dbs, [ModelScorer(db, ScoringConfig().for_camera(S.CAMERA)) for db in dbs]


def test_the_model_that_explains_more_wins(scene):
    dbs, scorers = scene
    rng = np.random.default_rng(1)
    G_WO, G_WC = S.box_pose(0.0), S.camera_at(10.0)  # the unique +X face, nearly frontal
    for k in range(4):
        f = S.observe(dbs[k], G_WO, G_WC, rng)
        est = S.estimate(G_WO, G_WC)
        scores = [s.score(f, est) for s in scorers]
        n = [s.n_explained for s in scores]
        assert n[k] >= 20 and max(n[j] for j in range(4) if j != k) == 0, n
        # every model is scored on all the measured features: explained ones by Eq. (9), others by c
        for s in scores:
            assert s.n_features == len(f)
            rest = (len(f) - s.n_explained) * scorers[0].config.log_clutter_density
            assert s.log_likelihood == pytest.approx(s.log_likelihood_explained + rest)
        b = calc_current_entropy(uniform(4), f, scorers, [est] * 4)
        assert b.map_model == k and b.P.sum() == pytest.approx(1.0)
        assert b.H < math.log(4)


def test_shared_faces_leave_the_probabilities_uniform(scene):
    dbs, scorers = scene
    rng = np.random.default_rng(2)
    for az, yaw in ((180.0, 0.0), (90.0, 0.0), (270.0, 0.0), (0.0, 180.0)):
        G_WO, G_WC = S.box_pose(yaw), S.camera_at(az)
        f = S.observe(dbs[2], G_WO, G_WC, rng)
        est = S.estimate(G_WO, G_WC)
        P = uniform(4)
        for _ in range(3):
            b = calc_current_entropy(P, f, scorers, [est] * 4)
            P = b.P
        assert len(set(b.n_explained.tolist())) == 1 and b.n_explained[0] >= 20
        np.testing.assert_allclose(P, 0.25, atol=1e-9)


def test_aliases_are_counted_once_and_geometry_picks_the_face(scene):
    """The shared page is on three faces: a measured feature has three look-alike candidates, and the
    one the pose puts there explains it, once."""
    dbs, scorers = scene
    rng = np.random.default_rng(3)
    G_WO, G_WC = S.box_pose(0.0), S.camera_at(180.0)  # the -X face
    f = S.observe(dbs[0], G_WO, G_WC, rng, clutter=0)
    e = scorers[0].explain(f, S.estimate(G_WO, G_WC))
    n_shared = 3 * (len(dbs[0]) // 4)
    face = n_shared // 3
    assert e.n_explained == len(f)  # every feature explained exactly once
    assert np.all(e.idx_db[e.explained] < face)  # by the -X copy (the first third), not +Y or -Y
    # the pose turned by a quarter puts the -Y face where -X was: the same page, so it explains as much,
    # by the -Y copy (the last third)
    e_turned = scorers[0].explain(f, S.estimate(G_WO @ S.se3(S.Rz(-math.pi / 2)), G_WC))
    assert e_turned.n_explained == len(f)
    assert np.all((e_turned.idx_db >= 2 * face) & (e_turned.idx_db < 3 * face))


def test_wrong_pose_explains_nothing_and_no_pose_explains_nothing(scene):
    dbs, scorers = scene
    rng = np.random.default_rng(4)
    G_WO, G_WC = S.box_pose(0.0), S.camera_at(180.0)
    f = S.observe(dbs[0], G_WO, G_WC, rng)
    far = S.estimate(G_WO @ S.se3(None, (0.5, 0.0, 0.0)), G_WC)
    assert scorers[0].explain(f, far).n_explained == 0
    s = scorers[0].score(f, None)
    assert s.n_explained == 0 and s.log_likelihood == pytest.approx(
        len(f) * scorers[0].config.log_clutter_density
    )


def test_pose_sharing_scores_a_model_without_a_filter_at_the_others_pose(scene):
    dbs, scorers = scene
    rng = np.random.default_rng(5)
    G_WO, G_WC = S.box_pose(0.0), S.camera_at(180.0)
    f = S.observe(dbs[0], G_WO, G_WC, rng)
    est = S.estimate(G_WO, G_WC)
    states = [est, None, est, None]
    shared = calc_current_entropy(uniform(4), f, scorers, states)
    np.testing.assert_allclose(shared.P, 0.25, atol=1e-9)
    own = calc_current_entropy(
        uniform(4), f, scorers, states, ScoringConfig(share_poses=False).for_camera(S.CAMERA)
    )
    assert own.P[1] < 0.2 and own.P[0] > 0.3  # without sharing, no pose means no explanation


def _dense_explain(scorer, f, est):
    """The explanation of the scoring's docstring, one measured feature and candidate at a time: the k
    nearest descriptors by a full sort, the candidates within the descriptor distance, each gated by
    its Euclidean residual and its Mahalanobis distance under C_l Sigma_bar C_l^T + Sigma_d (C_l from
    finite differences of the measurement model in the rotation-vector chart, S inverted densely), the
    nearest in Mahalanobis distance kept (the first on exact ties)."""
    from lab.estimation import measurement_model, retract_rv
    from lab.estimation.fit import chi2_quantile

    cfg = scorer.config
    n = len(f)
    idx_db, m2_out, ld_out = np.full(n, -1), np.full(n, np.inf), np.full(n, -np.inf)
    D = scorer.db.descriptors.astype(float)
    mu, Sig = np.asarray(est.mu, float), np.asarray(est.Sigma_rv, float)
    vis = scorer.visible(est)
    for m in range(n):
        dist = np.linalg.norm(D - f.descriptors[m].astype(float), axis=1)
        best = None
        for l in np.argsort(dist, kind="stable")[: scorer.k_neighbours]:
            if not dist[l] < cfg.max_descriptor_distance or (vis is not None and not vis[l]):
                continue
            b = scorer.db.points_O[l : l + 1]
            h = measurement_model(mu, b)[0]
            C = np.zeros((3, 6))
            for a in range(6):  # central differences of H along the chart's coordinates
                e = np.zeros(6)
                e[a] = 1e-6
                C[:, a] = (
                    measurement_model(retract_rv(mu, e), b)[0] - measurement_model(retract_rv(mu, -e), b)[0]
                ) / 2e-6
            r = f.points_C[m] - h
            Sm = C @ Sig @ C.T + f.covariances[m]
            m2 = float(r @ np.linalg.inv(Sm) @ r)
            if np.linalg.norm(r) > cfg.dist_max_m or m2 > chi2_quantile(cfg.gate_prob, 3):
                continue
            if best is None or m2 < best[0]:
                best = (m2, l, -0.5 * (m2 + np.linalg.slogdet(Sm)[1] + 3 * math.log(2 * math.pi)))
        if best is not None:
            m2_out[m], idx_db[m], ld_out[m] = best
    return idx_db, m2_out, ld_out


def test_the_vectorised_explanation_is_the_dense_per_candidate_one(scene):
    """explain_many (all poses at once, Euclidean gate first, closed-form 3x3 Cholesky) against the
    per-candidate reference, at right, look-alike, nearly-gated and wrong poses, with and without the
    visibility test; and explain / score at one pose are explain_many's."""
    dbs, _ = scene
    rng = np.random.default_rng(11)
    vis_cfg = ScoringConfig(visibility_deg=15.0).for_camera(S.CAMERA)
    scorers = [ModelScorer(db, ScoringConfig().for_camera(S.CAMERA)) for db in dbs[:2]]
    scorers += [ModelScorer(dbs[1], vis_cfg)]
    counts = []
    for az, yaw in ((10.0, 0.0), (180.0, 0.0), (135.0, 30.0)):
        G_WO, G_WC = S.box_pose(yaw), S.camera_at(az)
        f = S.observe(dbs[1], G_WO, G_WC, rng)
        Sig = np.diag([1e-4] * 3 + [1e-3] * 3)
        poses = [
            S.estimate(G_WO, G_WC, Sig),
            S.estimate(G_WO @ S.se3(S.Rz(math.pi / 2)), G_WC, Sig),  # a look-alike turn
            S.estimate(G_WO @ S.se3(S.Rz(0.12), (0.03, -0.02, 0.02)), G_WC, Sig),  # off: some gated out
            S.estimate(G_WO @ S.se3(None, (0.5, 0.0, 0.0)), G_WC, Sig),  # wrong: nothing
            None,
        ]
        for sc in scorers:
            many = sc.explain_many(f, poses)
            assert many[-1].n_explained == 0
            for est, e in zip(poses[:-1], many[:-1], strict=True):
                idx_db, m2, ld = _dense_explain(sc, f, est)
                np.testing.assert_array_equal(e.idx_db, idx_db)
                np.testing.assert_array_equal(e.explained, idx_db >= 0)
                np.testing.assert_allclose(e.m2, m2, rtol=1e-6, atol=1e-9)  # finite differences: 1e-6
                np.testing.assert_allclose(e.log_density, ld, rtol=1e-9, atol=1e-6)
                one = sc.explain(f, est)
                for a, b in ((one.idx_db, e.idx_db), (one.m2, e.m2), (one.log_density, e.log_density)):
                    np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)
            counts.append([e.n_explained for e in many])
            scores = sc.score_many(f, poses)
            for est, s in zip(poses, scores, strict=True):
                assert s.log_likelihood == pytest.approx(sc.score(f, est).log_likelihood, rel=1e-12)
    counts = np.array(counts)  # (scorer x view, pose)
    assert counts[:, 0].max() > 20 and counts[:, 1].max() > 20  # the right pose and a look-alike turn
    assert np.any((counts[:, 2] > 0) & (counts[:, 2] < counts[:, 0]))  # the gate cut some, not all


def test_joint_and_per_feature_forms_agree_on_clean_data(scene):
    dbs, scorers = scene
    rng = np.random.default_rng(6)
    G_WO, G_WC = S.box_pose(0.0), S.camera_at(0.0)
    f = S.observe(dbs[0], G_WO, G_WC, rng, clutter=0)
    est = S.estimate(G_WO, G_WC, Sigma=np.diag([1e-8] * 3 + [1e-8] * 3))  # pose known: no correlation
    joint = ModelScorer(dbs[0], ScoringConfig(likelihood=LikelihoodForm.JOINT).for_camera(S.CAMERA)).score(
        f, est
    )
    per = scorers[0].score(f, est)
    assert joint.n_explained == per.n_explained > 20
    assert joint.log_likelihood == pytest.approx(per.log_likelihood, rel=1e-4)


def _without(db, drop):
    """``db`` without the features ``drop`` (a database trained apart that missed them)."""
    from dataclasses import replace

    keep = np.setdiff1d(np.arange(len(db)), drop)
    return replace(
        db, points_O=db.points_O[keep], descriptors=db.descriptors[keep], seen_from=db.seen_from[keep]
    )


def test_shared_evidence_counts_alike_for_every_model_and_the_unique_face_still_decides():
    """The drift on shared faces: one database lacks a few features of the shared page (as the rendered
    databases do, trained apart). Without pooling, that model explains fewer of them and falls behind
    on every frame of a shared face; with pooling the shared page counts alike for all, exactly, and a
    unique face still identifies its model."""
    dbs = S.databases()
    dbs[1] = _without(dbs[1], [0, 10, 20])  # three features of the shared page on -X
    cfg = ScoringConfig(shared_region_m=0.05)  # the synthetic pages are sparse: 30 features a face
    masks = shared_features(dbs, cfg)
    n_face = len(dbs[0]) // 4
    for i, m in enumerate(masks):  # the unique +X page comes last in each database
        assert not m[-n_face:].any() and m[:-n_face].all(), (i, np.flatnonzero(~m))
    rng = np.random.default_rng(7)
    G_WO, G_WC = S.box_pose(0.0), S.camera_at(180.0)  # the shared -X face
    f = S.observe(dbs[2], G_WO, G_WC, rng)
    est = S.estimate(G_WO, G_WC)
    runs = {}
    for pool in (False, True):
        cfg = ScoringConfig(shared_region_m=0.05, pool_shared=pool).for_camera(S.CAMERA)
        scorers = [ModelScorer(db, cfg) for db in dbs]
        P = uniform(4)
        for _ in range(5):
            b = calc_current_entropy(P, f, scorers, [est] * 4)
            P = b.P
        runs[pool] = (P, b.n_explained)
    P_raw, n_raw = runs[False]
    assert n_raw[1] == n_raw[0] - 3 and P_raw[1] < 0.2  # the drift, without pooling
    P_pool, n_pool = runs[True]
    assert len(set(n_pool.tolist())) == 1
    np.testing.assert_allclose(P_pool, 0.25, atol=1e-12)
    # the unique face still identifies its model, with pooling
    for k in range(4):
        f = S.observe(dbs[k], S.box_pose(0.0), S.camera_at(10.0), rng)
        b = calc_current_entropy(uniform(4), f, scorers, [S.estimate(S.box_pose(0.0), S.camera_at(10.0))] * 4)
        assert b.map_model == k and b.n_explained[k] > max(np.delete(b.n_explained, k)) + 15, b.n_explained


def test_an_empty_database_shares_nothing_and_is_scored_as_before():
    dbs = S.databases()
    dbs[3] = _without(dbs[3], np.arange(len(dbs[3])))
    assert all(not m.any() for m in shared_features(dbs))
    f = S.observe(dbs[0], S.box_pose(0.0), S.camera_at(180.0), np.random.default_rng(8))
    est = S.estimate(S.box_pose(0.0), S.camera_at(180.0))
    pooled = calc_current_entropy(
        uniform(4), f, [ModelScorer(db, ScoringConfig().for_camera(S.CAMERA)) for db in dbs], [est] * 4
    )
    raw_cfg = ScoringConfig(pool_shared=False).for_camera(S.CAMERA)
    raw = calc_current_entropy(uniform(4), f, [ModelScorer(db, raw_cfg) for db in dbs], [est] * 4)
    np.testing.assert_array_equal(pooled.P, raw.P)
    assert pooled.n_explained[3] == 0


def test_pooling_is_the_rule_of_the_docstring():
    """pool_shared_evidence on hand-made explanations: shared evidence gets the best density for all."""
    from lab.identification import Explanation, ModelScore

    cfg = ScoringConfig().for_camera(S.CAMERA)
    c = cfg.log_clutter_density
    # 4 measured features; database features 0-1 shared, 2 not
    shared = [np.array([True, True, False])] * 2
    ex = [
        Explanation(
            np.array([1, 1, 1, 0], bool),
            np.array([0, 2, 1, -1]),
            np.zeros(4),
            np.array([-1.0, -2.0, -3.0, -np.inf]),
        ),
        Explanation(
            np.array([1, 0, 0, 0], bool),
            np.array([0, -1, -1, -1]),
            np.zeros(4),
            np.array([-4.0, -np.inf, -np.inf, -np.inf]),
        ),
    ]
    scores = [ModelScore(0.0, 0.0, e.n_explained, 4, e) for e in ex]
    a, b = pool_shared_evidence(scores, shared, cfg)
    # feature 0 (shared, both): best density -1 for both; feature 2 (model 0 by shared feature 1): -3 for
    # both; feature 1 (model 0 by its own feature 2): model 0 only; feature 3: clutter for both
    assert a.log_likelihood == pytest.approx(-1.0 - 3.0 - 2.0 + c)
    assert b.log_likelihood == pytest.approx(-1.0 - 3.0 + 2 * c)
    assert (a.n_explained, b.n_explained) == (3, 2)


def test_state_for_scoring_prefers_the_fresh_initialisation():
    from lab.estimation import UpdateOutcome, UpdateResult

    pred = S.estimate(S.box_pose(0.0), S.camera_at(0.0))
    init = S.estimate(S.box_pose(10.0), S.camera_at(0.0))
    assert state_for_scoring(pred, UpdateResult(True, UpdateOutcome.UPDATED, "")) is pred
    assert state_for_scoring(None, UpdateResult(False, UpdateOutcome.INITIALIZED, "", estimate=init)) is init
    assert state_for_scoring(None, UpdateResult(False, UpdateOutcome.SKIPPED, "")) is None


# --- bad input ---------------------------------------------------------------------------------------


def test_bad_input_is_refused_with_a_clear_error(scene):
    dbs, scorers = scene
    with pytest.raises(ConfigError, match="one log-likelihood per model"):
        update_model_probabilities(uniform(4), [0.0, 0.0, 0.0])
    with pytest.raises(ConfigError, match="sum to 1"):
        update_model_probabilities([0.5, 0.6], [0.0, 0.0])
    with pytest.raises(ConfigError, match="finite"):
        update_model_probabilities(uniform(2), [np.nan, 0.0])
    with pytest.raises(ConfigError, match="too large"):
        apply_floor(uniform(4), 0.3)
    with pytest.raises(ConfigError):
        ScoringConfig(evidence_weight=0.0)
    with pytest.raises(ConfigError):
        uniform(0)
    with pytest.raises(ConfigError, match="one scorer and one state per model"):
        calc_current_entropy(
            uniform(4),
            S.observe(dbs[0], S.box_pose(), S.camera_at(0), np.random.default_rng(0)),
            scorers[:3],
            [None] * 4,
        )
    # all models impossible (-inf): nothing learnt, the prior is kept
    np.testing.assert_allclose(update_model_probabilities(uniform(3), [-np.inf] * 3), uniform(3))
