"""What the planner knows: each model's probability and where that model says the object is.

Each EKF of the bank estimates the object's pose ``G_CO`` in the *current* camera frame C, for its own
model. The planner moves the camera, so the hypotheses are kept in the world frame W
(``G_WO = G_WC G_CO``, ``G_WC`` from odometry and the pan-tilt state) and re-expressed in the camera
frame of each candidate goal (:meth:`ModelHypotheses.relative_to`).

**Pose hypotheses.** A model can hold several poses, each with a probability given the model. The
reason is symmetry: a box with three identical faces seen on one of them looks the same turned by 90
degrees, so a filter that has only seen shared faces cannot know on which side the unique face is.
:meth:`ModelHypotheses.from_estimates` with ``symmetries`` (object-frame transforms ``S``, e.g. turns
about O's z axis) gives every model the poses ``G_WO S`` too; the planner then expects the unique face
on any of those sides, weighted by ``symmetry_log_weights`` (the caller can score a frame at each
alias pose to rule some out: :func:`symmetry_log_weights`).

Uncertainty is carried over ``[p, phi]``: position and a small rotation vector, as the rotation-vector
chart of :mod:`lab.estimation` (``R_true = Exp(phi) R``). Changing frames by a rotation ``R_AB`` maps
both parts by ``R_AB``: ``Sigma_A = T Sigma_B T^T`` with ``T = diag(R_AB, R_AB)``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from lab.errors import ConfigError, LabError
from lab.estimation import PoseEstimate
from lab.geometry import G_to_pose6, Rz, se3, se3_inv
from lab.identification.scoring import ModelScorer, ScoringConfig, pose_estimate_rv
from lab.vision import Features3D

__all__ = [
    "ModelHypotheses",
    "NoObjectEstimate",
    "TurnEvidence",
    "symmetry_log_weights",
    "turn_between",
    "z_turns",
]


class NoObjectEstimate(LabError, RuntimeError):
    """No model has a pose estimate: there is no object to plan around (scan for it first)."""


def _rotate_cov(R: np.ndarray, Sigma: np.ndarray) -> np.ndarray:
    T = np.zeros(Sigma.shape[:-2] + (6, 6))
    T[..., :3, :3] = R
    T[..., 3:, 3:] = R
    out = T @ Sigma @ np.swapaxes(T, -1, -2)
    return 0.5 * (out + np.swapaxes(out, -1, -2))


def _frozen(a, dtype=float) -> np.ndarray:
    a = np.array(a, dtype=dtype)
    a.flags.writeable = False
    return a


def z_turns(n: int = 4) -> tuple[np.ndarray, ...]:
    """The ``n`` turns about the object's z axis by multiples of ``360 / n`` degrees, as 4x4 transforms
    (the look-alike poses of a box whose side faces repeat)."""
    return tuple(se3(Rz(2.0 * np.pi * k / n)) for k in range(int(n)))


@dataclass(frozen=True)
class ModelHypotheses:
    """The model probabilities and, for every model, one or more object poses in the world W.

    Attributes
    ----------
    P : ndarray, shape (L,)
        ``P(M_i | D_{1:k})``.
    G_WO : ndarray, shape (H, 4, 4)
        Object frame O of each pose hypothesis in W.
    Sigma_W : ndarray, shape (H, 6, 6) [m^2, m rad, rad^2]
        Uncertainty of each pose over ``[p_W, phi_W]``.
    model : ndarray, shape (H,), int
        The model each pose hypothesis belongs to (every model has at least one).
    weight : ndarray, shape (H,)
        ``P(pose h | M_model[h])``: sums to 1 over each model's hypotheses.
    known : ndarray, shape (L,), bool
        False for a model whose filter has no estimate; its hypotheses then hold the poses of the
        most probable known model (all models share the box's geometry: the object is where the
        others say, only its identity is in doubt).
    """

    P: np.ndarray
    G_WO: np.ndarray = field(repr=False)
    Sigma_W: np.ndarray = field(repr=False)
    model: np.ndarray = field(repr=False)
    weight: np.ndarray = field(repr=False)
    known: np.ndarray = field(repr=False)

    def __post_init__(self):
        P = _frozen(self.P)
        G, S = _frozen(self.G_WO), _frozen(self.Sigma_W)
        model, weight, known = _frozen(self.model, int), _frozen(self.weight), _frozen(self.known, bool)
        L, H = len(P), len(G)
        if P.ndim != 1 or L == 0 or abs(P.sum() - 1.0) > 1e-6 or np.any(P < 0):
            raise ConfigError(f"P must be a probability vector over the models, got {self.P}")
        if G.shape != (H, 4, 4) or S.shape != (H, 6, 6) or model.shape != (H,) or weight.shape != (H,):
            raise ConfigError(
                f"need G_WO (H, 4, 4), Sigma_W (H, 6, 6), model (H,) and weight (H,): got {G.shape}, "
                f"{S.shape}, {model.shape}, {weight.shape}"
            )
        if known.shape != (L,):
            raise ConfigError(f"known must have one entry per model ({L}), got shape {known.shape}")
        if np.any(model < 0) or np.any(model >= L):
            raise ConfigError(f"pose hypotheses name unknown model indices {sorted(set(model.tolist()))}")
        if np.any(weight < 0) or not np.allclose(np.bincount(model, weight, minlength=L), 1.0, atol=1e-6):
            raise ConfigError("every model needs pose hypotheses whose weights are >= 0 and sum to 1")
        if not (np.all(np.isfinite(G)) and np.all(np.isfinite(S))):
            raise ConfigError("model poses and covariances must be finite")
        for name, value in (("P", P), ("G_WO", G), ("Sigma_W", S), ("model", model), ("weight", weight)):
            object.__setattr__(self, name, value)
        object.__setattr__(self, "known", known)

    @property
    def n_models(self) -> int:
        return len(self.P)

    @property
    def n_hypotheses(self) -> int:
        return len(self.G_WO)

    @property
    def probability(self) -> np.ndarray:
        """``P(M_model[h]) P(pose h | M_model[h])`` of each pose hypothesis, shape (H,), sums to 1."""
        return self.P[self.model] * self.weight

    @classmethod
    def one_pose_each(cls, P, G_WO, Sigma_W) -> ModelHypotheses:
        """One pose per model: ``G_WO`` (L, 4, 4) and ``Sigma_W`` (L, 6, 6)."""
        L = len(np.asarray(P))
        return cls(P, G_WO, Sigma_W, np.arange(L), np.ones(L), np.ones(L, bool))

    @classmethod
    def from_estimates(
        cls,
        P,
        estimates: Sequence[PoseEstimate | None],
        G_WC: np.ndarray,
        symmetries: Sequence[np.ndarray] | None = None,
        symmetry_log_weights=None,
    ) -> ModelHypotheses:
        """From the bank's estimates (object in the current camera C) and the camera's pose in W.

        Parameters
        ----------
        P : array_like, shape (L,)
        estimates : sequence of PoseEstimate or None, length L
            ``EKFBank.estimates``.
        G_WC : ndarray, shape (4, 4)
            The current camera in the world (odometry pose ``G_WR`` times ``G_RC(pan, tilt)``).
        symmetries : sequence of ndarray (4, 4), optional
            Object-frame transforms ``S`` whose poses ``G_WO S`` look alike (:func:`z_turns`); each
            model then has one hypothesis per symmetry. Default: the estimate alone.
        symmetry_log_weights : array_like, shape (L, K), optional
            Unnormalised log-probabilities of the K symmetric poses of each model (default: equal).

        Raises
        ------
        NoObjectEstimate
            When no model has an estimate.
        """
        P = np.asarray(P, dtype=float)
        L = len(P)
        if len(estimates) != L:
            raise ConfigError(f"need one estimate per model: {len(estimates)} for {L} models")
        G_WC = np.asarray(G_WC, dtype=float)
        if G_WC.shape != (4, 4) or not np.all(np.isfinite(G_WC)):
            raise ConfigError(f"G_WC must be a finite 4x4 transform, got shape {G_WC.shape}")
        known = np.array([e is not None for e in estimates])
        if not known.any():
            raise NoObjectEstimate("no model has a pose estimate yet: scan until a filter initialises")
        sym = [np.eye(4)] if symmetries is None else [np.asarray(s, dtype=float) for s in symmetries]
        K = len(sym)
        if K == 0 or any(s.shape != (4, 4) for s in sym):
            raise ConfigError("symmetries must be a non-empty sequence of 4x4 transforms")
        lw = np.zeros((L, K)) if symmetry_log_weights is None else np.asarray(symmetry_log_weights, float)
        if lw.shape != (L, K) or np.any(np.isnan(lw)) or np.any(lw == np.inf):
            raise ConfigError(f"symmetry_log_weights must have shape ({L}, {K}) and be finite or -inf")
        best = int(np.flatnonzero(known)[np.argmax(P[known])])
        R = G_WC[:3, :3]
        G, S, model, weight = [], [], [], []
        for i in range(L):
            src = i if known[i] else best
            G_WO = G_WC @ estimates[src].G_CO
            Sigma_W = _rotate_cov(R, estimates[src].Sigma_rv)
            w = np.exp(lw[src] - lw[src].max())
            w = w / w.sum()
            for k in range(K):
                G.append(G_WO @ sym[k])  # the look-alike pose: O turned by S, same uncertainty in W
                S.append(Sigma_W)
                model.append(i)
                weight.append(w[k])
        return cls(P, np.stack(G), np.stack(S), np.array(model), np.array(weight), known)

    def object_centre_W(self) -> np.ndarray:
        """The probability-weighted object origin in W (the paper's ``P_obj``, Sec. IV), shape (3,).

        Models without an estimate do not vote (their weight goes to the others).
        """
        w = np.where(self.known[self.model], self.probability, 0.0)
        w = w / w.sum()
        return w @ self.G_WO[:, :3, 3]

    def relative_to(self, G_WC) -> tuple[np.ndarray, np.ndarray]:
        """Every pose hypothesis and its uncertainty seen from a camera at ``G_WC`` (a candidate goal).

        Parameters
        ----------
        G_WC : ndarray, shape (4, 4) or (A, 4, 4)

        Returns
        -------
        G_CO : ndarray, shape (H, 4, 4) or (A, H, 4, 4)
        Sigma_rv : ndarray, shape (H, 6, 6) or (A, H, 6, 6)
            Over ``[x_r, phi]`` in that camera frame (the rotation-vector chart).
        """
        G_WC = np.asarray(G_WC, dtype=float)
        single = G_WC.ndim == 2
        G_CW = np.stack([se3_inv(g) for g in G_WC.reshape(-1, 4, 4)])  # (A, 4, 4)
        G_CO = G_CW[:, None] @ self.G_WO[None]  # (A, H, 4, 4)
        R = np.broadcast_to(G_CW[:, None, :3, :3], G_CO.shape[:2] + (3, 3))
        S = _rotate_cov(R, np.broadcast_to(self.Sigma_W, G_CO.shape[:2] + (6, 6)))
        return (G_CO[0], S[0]) if single else (G_CO, S)


def symmetry_log_weights(
    frames: Sequence[tuple[Features3D, np.ndarray]],
    scorers: Sequence[ModelScorer],
    estimates: Sequence[PoseEstimate | None],
    G_WC: np.ndarray,
    symmetries: Sequence[np.ndarray],
    config: ScoringConfig | None = None,
) -> np.ndarray:
    """How well each look-alike pose of each model explains the frames seen so far, shape (L, K).

    Model ``i``'s estimate (in the current camera, at ``G_WC``) turned by each symmetry ``S_k`` is put
    in the world, ``G_WO S_k``, and every past frame ``(D, G_WC_f)`` is scored there
    (:meth:`ModelScorer.score` at ``G_WC_f^-1 G_WO S_k``): a pose that puts the unique face where a
    shared one was seen explains less. Returns ``kappa`` times the summed log-likelihoods, minus each
    row's largest (0 for the best pose; rows of models without an estimate are 0): the
    ``symmetry_log_weights`` of :meth:`ModelHypotheses.from_estimates`.
    """
    config = config or ScoringConfig()
    L, K = len(scorers), len(symmetries)
    if len(estimates) != L:
        raise ConfigError(f"need one estimate per model: {len(estimates)} for {L} scorers")
    out = np.zeros((L, K))
    G_WC = np.asarray(G_WC, dtype=float)
    for i, (scorer, est) in enumerate(zip(scorers, estimates, strict=True)):
        if est is None:
            continue
        G_WO = G_WC @ est.G_CO
        for features, G_WC_f in frames:  # every turn of a frame in one vectorised scoring
            G_WC_f = np.asarray(G_WC_f, dtype=float)
            Sigma = _rotate_cov(G_WC_f[:3, :3].T @ G_WC[:3, :3], est.Sigma_rv)  # into that camera
            G_CW_f = se3_inv(G_WC_f)
            aliases = [
                pose_estimate_rv(G_to_pose6(G_CW_f @ G_WO @ np.asarray(S, dtype=float)), Sigma, est.t)
                for S in symmetries
            ]
            for k, sc in enumerate(scorer.score_many(features, aliases)):
                out[i, k] += config.evidence_weight * sc.log_likelihood
        out[i] -= out[i].max()
    return out


def turn_between(G_a: np.ndarray, G_b: np.ndarray, symmetries: Sequence[np.ndarray], tol_deg: float = 20.0):
    """The index ``k`` of the symmetry with ``G_b ~ G_a S_k`` (rotations within ``tol_deg``), or None.

    Two poses of the same object (in the same frame) that differ by one of the look-alike turns: how a
    filter re-initialised on another copy of the shared page relates to its old pose.
    """
    R = np.asarray(G_a, dtype=float)[:3, :3].T @ np.asarray(G_b, dtype=float)[:3, :3]  # S = G_a^-1 G_b
    best, best_deg = None, float(tol_deg)
    for k, S in enumerate(symmetries):
        D = np.asarray(S, dtype=float)[:3, :3].T @ R
        deg = float(np.degrees(np.arccos(np.clip((np.trace(D) - 1.0) / 2.0, -1.0, 1.0))))
        if deg <= best_deg:
            best, best_deg = k, deg
    return best


class TurnEvidence:
    """Which look-alike turn of each model's filter pose the recent keyframes support.

    Each keyframe adds an (L, K) array: :func:`symmetry_log_weights` of that frame alone, at the
    filters' poses *of that frame* (so a box that turned since does not matter: the turn is relative to
    the filter, which follows the box). The evidence is the sum over the last ``window`` keyframes.
    Turn 0 is the filter's own pose; when a filter is re-seated on turn ``k`` (or re-initialised on
    it), its rows are re-indexed (:meth:`reseated`); a re-initialisation unrelated to the old pose
    forgets them (:meth:`forget`).

    Parameters
    ----------
    n_models, n_turns : int
    window : int
        Keyframes kept.
    """

    def __init__(self, n_models: int, n_turns: int, window: int = 8):
        if window < 1:
            raise ConfigError(f"window must be >= 1 keyframe, got {window}")
        self.L, self.K, self.window = int(n_models), int(n_turns), int(window)
        self._frames: list[np.ndarray] = []

    def __len__(self) -> int:
        return len(self._frames)

    def add(self, log_weights) -> None:
        """Add one keyframe's ``symmetry_log_weights`` (L, K)."""
        lw = np.array(log_weights, dtype=float)
        if lw.shape != (self.L, self.K) or not np.all(np.isfinite(lw)):
            raise ConfigError(f"a keyframe's turn log-weights must be finite, shape ({self.L}, {self.K})")
        self._frames.append(lw)
        del self._frames[: -self.window]

    def total(self) -> np.ndarray:
        """Summed log-weights (L, K), each row's best at 0 (all 0 before any keyframe)."""
        if not self._frames:
            return np.zeros((self.L, self.K))
        tot = np.sum(self._frames, axis=0)
        return tot - tot.max(axis=1, keepdims=True)

    def reseated(self, i: int, k: int) -> None:
        """Model ``i``'s filter now sits on what was its turn ``k``: new turn ``j`` is old ``k + j``."""
        for lw in self._frames:
            lw[i] = np.roll(lw[i], -int(k))

    def forget(self, i: int) -> None:
        """Model ``i``'s filter was re-initialised on a pose unrelated to the old one."""
        for lw in self._frames:
            lw[i] = 0.0
