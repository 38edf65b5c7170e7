r"""Expected entropy by Monte Carlo: Eqs. (10)-(12) of the identification paper.

For a candidate action ``u+`` and an assumed truth, a pose hypothesis ``h`` of model ``M_i``
(probability ``P(M_i) P(h | M_i)``, :class:`~lab.identification.hypotheses.ModelHypotheses`):

1. **Predict the measurement.** The action puts the camera at ``G_WC+``; the hypothesis becomes
   ``G_{C+,O}`` with covariance ``Sigma+`` (:meth:`ModelHypotheses.relative_to`). The features of
   ``M_i`` that would be seen are those its database saw from the ring viewpoints around the camera's
   direction seen from O (``seen_from``, pooled over the neighbouring viewpoints, one ring step and
   the direction's uncertainty wide), inside the image and the stereo range.
2. **Sample** ``N`` measurement sets ``D~ ~ p(D_{k+1} | theta, u+, M_i)``: a pose
   ``X~ ~ N(mu+, Sigma+)`` per set, each visible feature measured and matched with probability
   ``p_detect`` times its visibility, at ``X~ (+) b_l`` plus stereo noise from the camera's error
   model (``Sigma_m`` at that pixel and depth).
3. **Score against every model** ``M_j``, Eqs. (11)-(12): a sampled feature (a feature ``b_l`` of
   ``M_i``) corresponds to the features of ``M_j`` whose descriptors are within the scoring distance of
   ``b_l``'s (the cross-model correspondence structure, computed once from the databases: on a shared
   face every model has the twin of ``b_l``, on a unique face no other model has), among which the
   geometric gate picks the nearest, exactly as the real scoring does
   (:class:`~lab.identification.scoring.ModelScorer`). ``M_j`` is placed at the true pose ``h``
   (the real scoring shares the bank's poses, and the truth is among them) or, without pose sharing,
   at its own hypotheses. Each explained feature contributes
   ``N(d~_m; mu^j_m, C_m Sigma+ C_m^T + Sigma_m)`` (Eq. (12): independent features), each other one
   the clutter density. Where the model probabilities pool shared evidence (the default), a sampled
   feature that some model explains with one of its shared features counts for every model with the
   best of their densities (:func:`~lab.identification.shared.pool_shared_evidence`).
4. **Posterior and entropy** of every sample (Eq. (7), the same evidence weight and floor as the real
   update), averaged and weighted by the hypothesis's probability:

.. math::

    E_{\mathbf{D}_{k+1}}[H^+] \approx \sum_i P(M_i \mid \theta, \mathbf{u}^+)\ \frac{1}{N}
        \sum_n H^+(\tilde{\mathbf{D}}_n)            \qquad \text{Eq. (10)}

The random draws are common to all candidate actions of one call (the same standard normal and
uniform numbers for the same feature), so the differences between actions are not buried in sampling
noise, and a seed gives the same result bit for bit.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from lab.errors import ConfigError
from lab.estimation.fit import chi2_quantile
from lab.identification.actions import CandidateAction
from lab.identification.bayes import entropy, posterior
from lab.identification.hypotheses import ModelHypotheses
from lab.identification.scoring import ScoringConfig
from lab.identification.shared import pools_shared_evidence, shared_features
from lab.identification.viewpoints import direction_std, viewpoint_directions, viewpoint_weights
from lab.robot import StereoCamera
from lab.vision import FeatureDatabase, Matcher
from lab.vision.stereo import StereoParams, triangulation_covariance

__all__ = ["MonteCarloConfig", "MonteCarloEvaluator", "cross_correspondences"]

_LOG_2PI = math.log(2.0 * math.pi)


@dataclass(frozen=True)
class MonteCarloConfig:
    """Settings of the Monte Carlo expected entropy.

    Attributes
    ----------
    n_samples : int
        ``N``, measurement sets sampled per action and assumed true model.
    p_detect : float
        Probability that a feature the database saw from the camera's direction is measured and matched
        in a robot's frame (measured: the tables' ``W_ii`` are 0.6-0.75 of the viewpoint's
        ``seen_from`` count).
    seed : int
    """

    n_samples: int = 64
    p_detect: float = 0.7
    seed: int = 0

    def __post_init__(self):
        if int(self.n_samples) != self.n_samples or self.n_samples < 1:
            raise ConfigError(f"n_samples must be a positive integer, got {self.n_samples}")
        if not 0.0 < self.p_detect <= 1.0:
            raise ConfigError(f"p_detect must be within (0, 1], got {self.p_detect}")


def cross_correspondences(db_i: FeatureDatabase, db_j: FeatureDatabase, scoring: ScoringConfig) -> np.ndarray:
    """For every feature of ``db_i``, the features of ``db_j`` it could be matched to.

    Returns
    -------
    ndarray, shape (N_i, k), int
        Indices into ``db_j`` of the ``k`` nearest descriptors within
        ``scoring.max_descriptor_distance``, -1 where there are fewer.
    """
    if len(db_i) == 0 or len(db_j) == 0:
        return np.full((len(db_i), 1), -1)
    idx, dist = Matcher(db_j, method="brute", k=scoring.k_neighbours).neighbours(db_i.descriptors)
    return np.where(dist < scoring.max_descriptor_distance, idx, -1)


class MonteCarloEvaluator:
    """*calcExpectedEntropy* by Monte Carlo (module docstring).

    Parameters
    ----------
    dbs : sequence of FeatureDatabase
        The models, in the order of the hypotheses.
    camera : StereoCamera
        The robot's camera (image bounds, stereo error model).
    scoring : ScoringConfig, optional
        Association rule, clutter density, evidence weight and floor: the model probabilities'. A clutter
        density left None is ``camera``'s (:meth:`ScoringConfig.for_camera` with ``stereo``).
    n_frames : int
        Frames the robot observes at the goal; their evidence adds up.
    config : MonteCarloConfig, optional
    stereo : StereoParams, optional
    shared : sequence of ndarray (N_j,) bool, optional
        The databases' shared features; computed from ``dbs`` (:func:`shared_features`) where the
        scoring pools shared evidence (:func:`pools_shared_evidence`), which the evaluator then does
        too: a sampled feature that some model explains with a shared feature counts for every model
        with the best of their densities, as in :func:`pool_shared_evidence`.
    """

    name = "mc"

    def __init__(
        self,
        dbs: Sequence[FeatureDatabase],
        camera: StereoCamera,
        scoring: ScoringConfig | None = None,
        n_frames: int = 1,
        config: MonteCarloConfig | None = None,
        stereo: StereoParams | None = None,
        shared: Sequence[np.ndarray] | None = None,
    ):
        if int(n_frames) != n_frames or n_frames < 1:
            raise ConfigError(f"n_frames must be a positive integer, got {n_frames}")
        if len(dbs) == 0:
            raise ConfigError("the Monte Carlo evaluator needs at least one database")
        self.dbs = tuple(dbs)
        self.camera = camera
        self.n_frames = int(n_frames)
        self.config = config or MonteCarloConfig()
        self.stereo = stereo or StereoParams()
        # the clutter density of the camera the measurements are sampled for, unless set explicitly
        self.scoring = (scoring or ScoringConfig()).for_camera(camera, self.stereo)
        fB = camera.fx * camera.baseline
        self._z_range = (fB / self.stereo.max_disparity, fB / self.stereo.min_disparity)
        self._gate_m2 = chi2_quantile(self.scoring.gate_prob, 3)
        #: angle between neighbouring ring viewpoints of each database [rad]
        self._ring_step = [_ring_step(db.viewpoints) for db in self.dbs]
        #: _cand[i][j]: (N_i, k) candidate features of M_j for every feature of M_i
        self._cand = [[cross_correspondences(a, b, self.scoring) for b in self.dbs] for a in self.dbs]
        # pooling needs one pose per model (the common pose), which pools_shared_evidence implies
        self.pooled = pools_shared_evidence(self.scoring, len(self.dbs))
        if self.pooled:
            shared = shared_features(self.dbs, self.scoring) if shared is None else shared
            if len(shared) != len(self.dbs) or any(
                np.shape(m) != (len(db),) for m, db in zip(shared, self.dbs, strict=False)
            ):
                raise ConfigError(
                    f"shared needs one bool mask per database, of shapes {[(len(db),) for db in self.dbs]}; "
                    f"got {[np.shape(m) for m in shared]}"
                )
            #: per database, its shared features; index -1 (no candidate) reads the appended False
            self.shared = [np.append(np.asarray(m, bool), False) for m in shared]

    @property
    def n_models(self) -> int:
        return len(self.dbs)

    def _visible(self, i: int, G_CO: np.ndarray, sigma_dir: float) -> tuple[np.ndarray, np.ndarray]:
        """Features of model i that a frame taken at relative pose G_CO may show, and how likely.

        ``seen_from`` is one training render's yes or no per viewpoint, a noisy sample of whether a
        feature is found from there (the number a viewpoint saw is 0.45-0.99 of what the rendered
        tables measure, at random); it is pooled over the ring viewpoints around the camera's direction
        with Gaussian weights of width one ring step, widened by the direction's uncertainty
        (:func:`viewpoint_weights`), so the prediction varies smoothly with the pose. Features outside
        the image or the stereo range are dropped.

        Returns
        -------
        idx : ndarray, shape (n,), int
        p_seen : ndarray, shape (n,)
        """
        db = self.dbs[i]
        w = viewpoint_weights(G_CO, db.viewpoints, math.hypot(sigma_dir, self._ring_step[i]))
        p_seen = db.seen_from @ w
        idx = np.flatnonzero(p_seen > 0)
        p = db.points_O[idx] @ G_CO[:3, :3].T + G_CO[:3, 3]
        z_lo, z_hi = self._z_range
        cam = self.camera
        with np.errstate(divide="ignore", invalid="ignore"):
            u = cam.fx * p[:, 0] / p[:, 2] + cam.cx
            v = cam.fy * p[:, 1] / p[:, 2] + cam.cy
        ok = (p[:, 2] > z_lo) & (p[:, 2] < z_hi) & (u >= 0) & (u <= cam.width - 1) & (v >= 0)
        ok &= v <= cam.height - 1
        return idx[ok], p_seen[idx[ok]]

    def _draws(self) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Standard normals and uniforms per model, common to every action of a call."""
        N = self.config.n_samples
        out = []
        for i, db in enumerate(self.dbs):
            rng = np.random.default_rng([self.config.seed, i])
            out.append(
                (rng.standard_normal((N, 6)), rng.random((N, len(db))), rng.standard_normal((N, len(db), 3)))
            )
        return out

    def _log_likelihoods(
        self, i: int, idx: np.ndarray, d: np.ndarray, detected: np.ndarray, Sigma_m, G_CO, Sigma, poses
    ) -> np.ndarray:
        """Eq. (12) plus clutter: log-likelihood (N, L) of the sampled sets under every model.

        ``G_CO`` (H, 4, 4) and ``Sigma`` (H, 6, 6) are the pose hypotheses at the action; model ``j`` is
        scored at each of ``poses[j]`` (indices into them) and keeps its best.
        """
        N, n = d.shape[:2]
        L = self.n_models
        log_c = self.scoring.log_clutter_density
        ll = np.full((N, L), -np.inf)
        # pooling (one pose per model): each model's density of each sampled feature, and whether the
        # database feature that explains it is a shared one
        log_N_j = np.full((L, N, n), -np.inf)
        by_shared = np.zeros((L, N, n), bool)
        for j in range(L):
            cand = self._cand[i][j][idx]  # (n, k) candidates in M_j of each sampled feature
            K = int((cand >= 0).sum(axis=1).max(initial=0))
            if K == 0:  # nothing of M_i can be explained by M_j
                ll[:, j] = np.count_nonzero(detected, axis=1) * log_c
                continue
            cand = np.sort(cand, axis=1)[:, ::-1][:, :K]  # valid candidates first
            valid = cand >= 0
            b = self.dbs[j].points_O[np.where(valid, cand, 0)]  # (n, K, 3)
            for q in poses[j]:
                R, t = G_CO[q, :3, :3], G_CO[q, :3, 3]
                qb = b @ R.T
                mu = qb + t  # mu^j_m: where M_j, at pose q, puts its feature, Eq. (3)
                C = np.concatenate([np.broadcast_to(np.eye(3), qb.shape + (3,)), -skew_batch(qb)], axis=-1)
                S = C @ Sigma[q] @ np.swapaxes(C, -1, -2) + Sigma_m[:, None]  # (n, K, 3, 3), Eq. (11)
                S_inv = np.linalg.inv(S)
                logdet = np.linalg.slogdet(S)[1]
                # residuals (N, n, K) per axis, and r^T S^-1 r written out (the einsum is 10x slower)
                rx, ry, rz = (d[:, :, None, a] - mu[None, :, :, a] for a in range(3))
                A = S_inv[None]
                m2 = (
                    A[..., 0, 0] * rx * rx
                    + A[..., 1, 1] * ry * ry
                    + A[..., 2, 2] * rz * rz
                    + 2.0 * (A[..., 0, 1] * rx * ry + A[..., 0, 2] * rx * rz + A[..., 1, 2] * ry * rz)
                )
                ok = valid[None] & (m2 <= self._gate_m2)
                ok &= rx * rx + ry * ry + rz * rz <= self.scoring.dist_max_m**2
                log_N = -0.5 * (m2 + logdet[None] + 3 * _LOG_2PI)
                gated = np.where(ok, log_N, -np.inf)
                best = np.max(gated, axis=-1)  # the gated candidate nearest, (N, n)
                per_feature = np.where(np.isfinite(best), best, log_c)
                ll[:, j] = np.maximum(ll[:, j], np.sum(np.where(detected, per_feature, 0.0), axis=1))
                if self.pooled:
                    chosen = np.take_along_axis(cand, np.argmax(gated, axis=-1).T, axis=1).T  # (N, n)
                    log_N_j[j] = best
                    by_shared[j] = np.isfinite(best) & self.shared[j][chosen]
        if self.pooled:  # pool_shared_evidence: shared evidence counts alike, the best density, for all
            S = by_shared.any(axis=0) & detected  # (N, n)
            pooled = np.max(log_N_j, axis=0)
            per_feature = np.where(np.isfinite(log_N_j), log_N_j, log_c)  # (L, N, n)
            per_feature = np.where(S[None], pooled[None], per_feature)
            ll = np.sum(np.where(detected[None], per_feature, 0.0), axis=2).T
        return ll

    def expected_entropy(self, actions: Sequence[CandidateAction], hypotheses: ModelHypotheses) -> np.ndarray:
        """``E[H+]`` of every action, Eq. (10), shape (A,) [nats].

        Every pose hypothesis ``h`` (of model ``i = model[h]``) is in turn the truth the measurements
        are sampled from. With ``scoring.share_poses`` (as the real scoring, which tries every filter's
        pose) each model is scored at that true pose, where it explains what it can; otherwise at its
        own pose hypotheses.
        """
        L = self.n_models
        if hypotheses.n_models != L:
            raise ConfigError(f"the hypotheses have {hypotheses.n_models} models, the evaluator {L}")
        if len(actions) == 0:
            return np.zeros(0)
        G_CO, Sigma = hypotheses.relative_to(np.stack([a.G_WC for a in actions]))  # (A, H, ...)
        sigma_dir = direction_std(G_CO, Sigma)  # (A, H)
        with np.errstate(divide="ignore"):
            log_P = np.log(hypotheses.P)
        H_now = entropy(hypotheses.P)
        own = [np.flatnonzero(hypotheses.model == j) for j in range(L)]
        draws = self._draws()
        out = np.zeros(len(actions))
        for a in range(len(actions)):
            EH = 0.0
            for h, (i, p_h) in enumerate(zip(hypotheses.model, hypotheses.probability, strict=True)):
                if p_h == 0:
                    continue
                idx, p_seen = self._visible(i, G_CO[a, h], sigma_dir[a, h])
                if len(idx) == 0:  # nothing of the object in view: nothing learnt
                    EH += p_h * H_now
                    continue
                z_pose, u_det, z_noise = draws[i]
                R, t = G_CO[a, h, :3, :3], G_CO[a, h, :3, 3]
                p = self.dbs[i].points_O[idx] @ R.T + t  # predicted features in C+
                uv = np.stack(
                    [
                        self.camera.fx * p[:, 0] / p[:, 2] + self.camera.cx,
                        self.camera.fy * p[:, 1] / p[:, 2] + self.camera.cy,
                    ],
                    axis=1,
                )
                disparity = self.camera.fx * self.camera.baseline / p[:, 2]
                Sigma_m = triangulation_covariance(uv, disparity, self.camera, self.stereo)  # (n, 3, 3)
                # X~ ~ N(mu_h+, Sigma_h+): position plus a small rotation (rotation-vector chart)
                delta = z_pose @ np.linalg.cholesky(Sigma[a, h] + 1e-12 * np.eye(6)).T  # (N, 6)
                R_s = rotvec_to_R_batch(delta[:, 3:]) @ R  # Exp(phi) R, (N, 3, 3)
                b = self.dbs[i].points_O[idx]
                d = np.einsum("snab,nb->sna", R_s[:, None], b) + (t + delta[:, :3])[:, None, :]
                d = d + np.einsum("nab,snb->sna", np.linalg.cholesky(Sigma_m), z_noise[:, idx])  # + xi
                detected = u_det[:, idx] < self.config.p_detect * p_seen  # measured and matched
                poses = [[h]] * L if self.scoring.share_poses else own
                ll = self._log_likelihoods(i, idx, d, detected, Sigma_m, G_CO[a], Sigma[a], poses)
                P_plus = posterior(log_P, self.n_frames * ll, self.scoring)  # (N, L), Eq. (7)
                EH += p_h * float(np.mean(entropy(P_plus)))  # Eq. (10)
            out[a] = EH
        return out


def skew_batch(q: np.ndarray) -> np.ndarray:
    """``[q]_x`` for a stack of vectors (..., 3) -> (..., 3, 3)."""
    Z = np.zeros(q.shape[:-1])
    x, y, z = q[..., 0], q[..., 1], q[..., 2]
    return np.stack([np.stack([Z, -z, y], -1), np.stack([z, Z, -x], -1), np.stack([-y, x, Z], -1)], axis=-2)


def rotvec_to_R_batch(phi: np.ndarray) -> np.ndarray:
    """``Exp(phi)`` (Rodrigues' formula) for a stack of rotation vectors (N, 3) -> (N, 3, 3)."""
    th2 = np.einsum("na,na->n", phi, phi)
    th = np.sqrt(th2)
    small = th2 < 1e-12
    a = np.where(small, 1.0 - th2 / 6.0, np.sin(th) / np.where(small, 1.0, th))
    b = np.where(small, 0.5 - th2 / 24.0, (1.0 - np.cos(th)) / np.where(small, 1.0, th2))
    K = skew_batch(phi)
    return np.eye(3) + a[:, None, None] * K + b[:, None, None] * (K @ K)


def _ring_step(viewpoints) -> float:
    """Smallest angle [rad] between two distinct ring viewpoints (10 degrees for the default ring)."""
    U = viewpoint_directions(viewpoints)
    if len(U) < 2:
        return math.pi
    cos = np.clip(U @ U.T, -1.0, 1.0)
    np.fill_diagonal(cos, -1.0)
    return float(np.arccos(cos.max()))
