"""The final pose the identification states: each model's filter run again beside it, fusing only
updates that are consistent with its prediction.

**Why.** The bank's filters (:class:`~lab.estimation.EKFBank`) fuse every frame's gated matches. Each
match passes the gate alone (within its chi-square(3) bound), yet a frame's matches can be jointly
inconsistent with the prediction: a few of them on the wrong copy of the shared page, or a sliver of a
face seen edge-on. Their update's NIS is then far above its chi-square quantile, and one such update
moves the pose by centimetres and tens of degrees while the covariance shrinks as after any update; the
filter recovers over the next frames, but an episode that ends within them states that pose as if it
were sure of it (measured: docs/tuning/identify-final-pose.md). The loop keeps the bank's filters as
they are (the probabilities and the planner rest on them); the pose it reports comes from here.

**What.** :class:`ConsistentShadows` keeps, beside each model's filter, a copy fed the same predictions
and the same matches, whose update is the consistent part of the frame (:func:`consistent_update`):
while the update's NIS exceeds the chi-square quantile of the filter's own ``divergence.nis_prob`` (the
level at which the filter calls an update's NIS huge), the used match farthest from the prediction
(Mahalanobis distance under its predicted covariance) is dropped and the update recomputed; with fewer
than the gate's minimum left, the frame is not fused and the copy keeps its prediction.

Each copy follows its filter's discontinuities: a (re)initialisation by RANSAC, or a copy that diverged,
copies the filter again; a re-seat of the filter on a look-alike turn (the agent's keyframes, the
identified model's seating) is applied to the copy as the same turn.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence

import numpy as np

from lab.estimation import EKFBank, PoseEKF, PoseEstimate, UpdateOutcome, UpdateResult
from lab.estimation.fit import chi2_quantile
from lab.estimation.gate import GateConfig, gate_rows
from lab.geometry import G_to_pose6, se3_inv

__all__ = ["ConsistentShadows", "consistent_update", "match_mahalanobis"]

_RESTART = (UpdateOutcome.INITIALIZED, UpdateOutcome.REINITIALIZED)


def match_mahalanobis(ekf: PoseEKF, d_C, b_O, Sigma_d) -> np.ndarray:
    """Each match's squared Mahalanobis distance ``r_j^T (C_j P C_j^T + Sigma_j)^-1 r_j`` under the
    filter's current (predicted) state, shape (n,): what the gate tests, without its thresholds."""
    no_gate = GateConfig(dist_max_m=np.inf, gate_prob=None)
    _, r, C = gate_rows(ekf.mu, ekf.P, d_C, b_O, Sigma_d, no_gate, ekf.config.chart)
    S = C @ ekf.P @ np.swapaxes(C, 1, 2) + Sigma_d
    return np.einsum("na,na->n", r, np.linalg.solve(S, r[..., None])[..., 0])


def consistent_update(ekf: PoseEKF, d_C, b_O, Sigma_d) -> tuple[PoseEKF, UpdateResult | None, np.ndarray]:
    """The update of ``ekf`` (left unchanged) with the part of the matches consistent with its prediction.

    The update is tried on all matches; while its NIS exceeds the chi-square(dof) quantile of
    ``ekf.config.divergence.nis_prob``, the used match with the largest Mahalanobis distance under the
    prediction (:func:`match_mahalanobis`) is dropped and the update tried again.

    Returns
    -------
    filter : PoseEKF
        The updated copy; ``ekf`` itself when no consistent update was left (the prediction stands).
    result : UpdateResult or None
        The applied (or skipped) update's record; None when no try was consistent (or there were too
        few matches to try).
    kept : ndarray of int
        The rows not dropped (with ``result`` None, fewer than the gate's minimum were left).
    """
    d, b, S = (np.asarray(a, dtype=float) for a in (d_C, b_O, Sigma_d))
    rows = np.arange(len(d))
    prob = ekf.config.divergence.nis_prob
    while len(rows) >= ekf.config.gate.min_matches:
        trial = copy.deepcopy(ekf)
        res = trial.update(d[rows], b[rows], S[rows])
        if res.outcome is not UpdateOutcome.UPDATED or res.nis <= chi2_quantile(prob, res.dof):
            return trial, res, rows  # consistent, or skipped (the copy keeps the skip's bookkeeping)
        used = rows[res.inliers]
        worst = used[int(np.argmax(match_mahalanobis(ekf, d[used], b[used], S[used])))]
        rows = rows[rows != worst]
    return ekf, None, rows


class ConsistentShadows:
    """Beside each filter of ``bank``, a copy that fuses only consistent updates (module docstring).

    Call :meth:`predict` with the bank's prediction's arguments before ``bank.predict`` and :meth:`update`
    with the bank's update results and the matches they were given; :meth:`estimate` is the pose to
    state. ``n_dropped`` counts the matches dropped, ``n_unfused`` the frames none of whose matches
    made a consistent update.
    """

    def __init__(self, bank: EKFBank):
        self.bank = bank
        self.shadows: list[PoseEKF | None] = [None] * len(bank)
        self._seen: list[np.ndarray | None] = [None] * len(bank)  # each filter's pose after its update
        self.n_dropped = 0
        self.n_unfused = 0

    def _follow_reseats(self) -> None:
        """Apply to each copy the turn its filter was re-seated on since its last update."""
        for i, f in enumerate(self.bank.filters):
            sh, seen, est = self.shadows[i], self._seen[i], f.estimate
            if sh is None or seen is None or est is None or sh.estimate is None:
                continue
            T = se3_inv(seen) @ est.G_CO
            if np.allclose(T, np.eye(4), atol=1e-9):
                continue
            s = sh.estimate
            sh.initialize(G_to_pose6(s.G_CO @ T), None, Sigma_rv=s.Sigma_rv)  # as the agent re-seats
            self._seen[i] = est.G_CO.copy()

    def predict(self, G_RC_prev, G_RC, G_odom, dt: float) -> None:
        """The bank's prediction (:meth:`EKFBank.predict`'s arguments), applied to every copy."""
        self._follow_reseats()
        for sh in self.shadows:
            if sh is not None and sh.initialized:
                sh.predict(G_RC_prev, G_RC, G_odom, dt)

    def update(self, updates: Sequence[UpdateResult], matches: Sequence[tuple]) -> None:
        """After the bank's update (its ``updates``, each filter's ``matches`` ``(d_C, b_O, Sigma_d)``)."""
        for i, (u, m) in enumerate(zip(updates, matches, strict=True)):
            f, sh = self.bank[i], self.shadows[i]
            if f.estimate is None:
                self.shadows[i] = None
            elif sh is None or not sh.initialized or sh.divergence is not None or u.outcome in _RESTART:
                self.shadows[i] = copy.deepcopy(f)
            else:
                self.shadows[i], res, kept = consistent_update(sh, *m)
                self.n_dropped += len(m[0]) - len(kept)
                self.n_unfused += res is None and len(kept) < len(m[0])
            self._seen[i] = None if f.estimate is None else f.estimate.G_CO.copy()

    def estimate(self, i: int) -> PoseEstimate | None:
        """Model ``i``'s pose to state: its copy's estimate (the filter's while it has no copy)."""
        self._follow_reseats()
        sh = self.shadows[i]
        if sh is not None and sh.estimate is not None:
            return sh.estimate
        return self.bank[i].estimate
