r"""A bank of pose EKFs: one per database model, all fed from the same frames.

The identification paper runs "an Extended Kalman Filter ... for each of the plausible models in the
database" (Sec. IV). Every filter sees the same robot and pan-tilt motion, so :meth:`EKFBank.predict`
checks that motion once and applies it to all of them; each model has its own correspondences ``J_i``,
so updates are per model, and :meth:`EKFBank.update_all` batches their linear algebra:

* the whitening of every filter's matches at once: the 3x3 Cholesky factors ``L_j L_j^T = Sigma_j``
  written out (no LAPACK call per match) and ``L_j^-1 [y_j, C_j]`` by forward substitution, the
  filters' rows stacked;
* the 6x6 information-form update of :mod:`lab.estimation.kernel` ((6 + m) x (6 + m) with the
  calibration error's m entries) stacked over the filters: one Cholesky factor of ``Sigma_bar`` and
  one of ``B`` per filter, solves instead of inverses.

It drives each filter through :class:`PoseEKF`'s public steps, doing their shared work once:

* prediction, Eqs. (1)-(2): :func:`~lab.estimation.kernel.checked_motion` (once), then per filter
  :meth:`PoseEKF.predict_staged` (``mu_bar``, ``F``, ``Sigma_bar``), the health check of all of them
  (:func:`~lab.estimation.health.health_many`), and :meth:`PoseEKF.commit_prediction`;
* update, Eq. (3): the gate of all filters (:func:`~lab.estimation.gate.gate_rows_many`), per filter
  :meth:`PoseEKF.begin_update` (checks, the prior with the calibration error), the batched
  :func:`~lab.estimation.kernel.whitened` and :func:`~lab.estimation.kernel.information_update`
  (``K y``, the Joseph-form covariance, the NIS and Eq. (9)'s likelihood; :meth:`PoseEKF.fail_update`
  when a factorisation fails), :meth:`PoseEKF.corrected_state` (``mu = mu_bar + K y`` in the chart),
  the health check of all of them, and :meth:`PoseEKF.finish_update`.

The results are :meth:`PoseEKF.update`'s, filter by filter, to round-off (``tests/test_ekf_filter.py``
checks them against it and against filterpy).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from lab.estimation.ekf import EKFConfig, PoseEKF, UpdateResult
from lab.estimation.estimate import PoseEstimate
from lab.estimation.fit import check_matches, valid_rows
from lab.estimation.gate import gate_rows_many
from lab.estimation.health import health_many
from lab.estimation.kernel import LOG_2PI, checked_motion, information_update, whitened
from lab.estimation.noise import odometry_covariance

__all__ = ["EKFBank"]


class EKFBank:
    """One :class:`PoseEKF` per database model.

    Parameters
    ----------
    n_models : int
        Number of database models ``L``.
    config : EKFConfig, optional
        Shared by every filter.
    rng : numpy.random.Generator
        Seeded generator; each filter gets its own independent child stream (``rng.spawn``), so a
        model's RANSAC draws do not depend on how often the others initialise.
    """

    def __init__(self, n_models: int, config: EKFConfig | None = None, *, rng: np.random.Generator):
        if int(n_models) != n_models or n_models < 1:
            raise ValueError(f"n_models must be a positive integer, got {n_models!r}")
        if not isinstance(rng, np.random.Generator):
            raise ValueError(f"rng must be a numpy.random.Generator (seeded), got {type(rng).__name__}")
        self.filters: tuple[PoseEKF, ...] = tuple(PoseEKF(config, rng=r) for r in rng.spawn(int(n_models)))

    def __len__(self) -> int:
        return len(self.filters)

    def __getitem__(self, i: int) -> PoseEKF:
        return self.filters[i]

    def predict(
        self, G_RC_prev, G_RC, G_odom, dt: float, *, G_OO=None, Sigma_odom=None
    ) -> tuple[PoseEstimate | None, ...]:
        """Apply one step of robot, pan-tilt and (random-walk) object motion to every model's filter.

        Same arguments as :meth:`PoseEKF.predict`; returns each model's ``(mu_bar, Sigma_bar)`` (None for
        a model whose filter is not initialised yet).
        """
        motion = checked_motion(G_RC_prev, G_RC, G_odom, dt, G_OO)  # once for the bank
        if Sigma_odom is None and not motion.bad:  # the odometry's error: once for the bank too
            Sigma_odom = odometry_covariance(motion.mats["G_odom"], self.filters[0].config.process)
        staged = [f.predict_staged(motion, Sigma_odom) for f in self.filters]
        live = [i for i, st in enumerate(staged) if st is not None]
        if live:  # every filter's health at once
            problems = self._health([staged[i][0] for i in live], [staged[i][2] for i in live])
            for i, problem in zip(live, problems, strict=True):
                self.filters[i].commit_prediction(*staged[i], problem)
        return tuple(f.estimate for f in self.filters)

    def _health(self, mus, Sigmas) -> list:
        """The divergence check of several filters' states at once (:func:`health_many`; the filters
        share their config)."""
        f0 = self.filters[0]
        return health_many(f0.config.divergence, f0.euler_chart, np.stack(mus), np.stack(Sigmas))

    def update(self, i: int, d_C, b_O, Sigma_d) -> UpdateResult:
        """Update model ``i``'s filter with its matched pairs (same arguments as :meth:`PoseEKF.update`)."""
        if not 0 <= i < len(self.filters):
            raise ValueError(f"model index {i} is outside [0, {len(self.filters) - 1}]")
        return self.filters[i].update(d_C, b_O, Sigma_d)

    def update_all(self, matches: Sequence[tuple]) -> tuple[UpdateResult, ...]:
        """Update every model's filter with its matched pairs, the linear algebra batched (module
        docstring): ``matches[i]`` is ``(d_C, b_O, Sigma_d)`` for model ``i`` (as :meth:`update`'s).

        Returns each filter's :class:`UpdateResult`, as ``update(i, *matches[i])`` for every ``i``
        would.
        """
        if len(matches) != len(self.filters):
            raise ValueError(f"need one match set per model: {len(matches)} for {len(self.filters)} filters")
        checked, valid = {}, {}  # once per match set that several filters share
        rows = []  # each filter's usable rows, when its update will gate them
        for f, m in zip(self.filters, matches, strict=True):
            key = tuple(id(a) for a in m)
            if key not in valid:
                checked[key] = check_matches(*m)
                valid[key] = valid_rows(*checked[key])
            ok = valid[key]
            gates = f.mu is not None and f.divergence is None
            rows.append(np.flatnonzero(ok) if gates and ok.sum() >= f.config.gate.min_matches else None)
        gated: list = [None] * len(self.filters)
        todo = [i for i, idx in enumerate(rows) if idx is not None]
        if todo:  # every filter's gate at once, the matches' rows stacked
            f0 = self.filters[0]
            keys = [tuple(id(a) for a in matches[i]) for i in todo]
            outs = gate_rows_many(
                [self.filters[i].mu for i in todo],
                [self.filters[i].P for i in todo],
                *([checked[k][j][rows[i]] for i, k in zip(todo, keys, strict=True)] for j in range(3)),
                f0.config.gate,
                f0.config.chart,
            )
            for i, out in zip(todo, outs, strict=True):
                gated[i] = out
        pending = [
            f.begin_update(*m, valid=valid[tuple(id(a) for a in m)], gated=g)
            for f, m, g in zip(self.filters, matches, gated, strict=True)
        ]
        ready = [i for i, p in enumerate(pending) if not isinstance(p, UpdateResult)]
        outs = _batched_updates([pending[i] for i in ready]) if ready else []
        results = list(pending)
        corrected = {}  # i: (mu, P, P_xc, nis, loglik)
        for i, out in zip(ready, outs, strict=True):
            f, p = self.filters[i], pending[i]
            if out is None:  # the batch could not factorise: this filter alone, as update() does
                try:
                    out = information_update(p.prior, *whitened(p.r, p.C, p.S))
                except np.linalg.LinAlgError:
                    results[i] = f.fail_update(p)
                    continue
            dx, P, nis, loglik = out
            corrected[i] = (*f.corrected_state(dx, P), nis, loglik)
        if corrected:  # every corrected state's health at once
            idx = list(corrected)
            problems = self._health([corrected[i][0] for i in idx], [corrected[i][1] for i in idx])
            for i, problem in zip(idx, problems, strict=True):
                results[i] = self.filters[i].finish_update(pending[i], *corrected[i], problem)
        return tuple(results)

    @property
    def estimates(self) -> tuple[PoseEstimate | None, ...]:
        """Every model's current estimate (None where not initialised)."""
        return tuple(f.estimate for f in self.filters)

    @property
    def log_likelihoods(self) -> tuple[float | None, ...]:
        """Every model's Eq. (9) log data likelihood from its last update (None where none was applied)."""
        return tuple(f.log_likelihood for f in self.filters)


def _batched_updates(pending) -> list:
    """``information_update(prior, *whitened(r, C, S))`` of each pending update, batched (module
    docstring); None for every one when a factorisation fails or the priors differ in size (each is then
    done alone)."""
    k = pending[0].prior.shape[0]
    if any(p.prior.shape[0] != k for p in pending):
        return [None] * len(pending)
    S = np.concatenate([p.S for p in pending])  # (N, 3, 3)
    rC = np.concatenate([np.concatenate([p.r[..., None], p.C], axis=2) for p in pending])  # (N, 3, 1 + k)
    with np.errstate(invalid="ignore", divide="ignore"):
        l11 = np.sqrt(S[:, 0, 0])  # Sigma_j = L_j L_j^T, written out
        l21 = S[:, 1, 0] / l11
        l31 = S[:, 2, 0] / l11
        l22 = np.sqrt(S[:, 1, 1] - l21 * l21)
        l32 = (S[:, 2, 1] - l31 * l21) / l22
        l33 = np.sqrt(S[:, 2, 2] - l31 * l31 - l32 * l32)
    diag = np.stack([l11, l22, l33], axis=1)
    if not (np.all(np.isfinite(diag)) and np.all(diag > 0)):
        return [None] * len(pending)
    w = np.empty_like(rC)  # L_j^-1 [y_j, C_j], forward substitution
    w[:, 0] = rC[:, 0] / l11[:, None]
    w[:, 1] = (rC[:, 1] - l21[:, None] * w[:, 0]) / l22[:, None]
    w[:, 2] = (rC[:, 2] - l31[:, None] * w[:, 0] - l32[:, None] * w[:, 1]) / l33[:, None]
    log_diag = np.log(diag).sum(axis=1)
    bounds = np.cumsum([0] + [len(p.S) for p in pending])
    Lam, g, yy, logdet_m = [], [], [], []
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        y_w = w[a:b, :, 0].reshape(-1)
        C_w = w[a:b, :, 1:].reshape(-1, k)
        Lam.append(C_w.T @ C_w)  # Lambda = C^T Sigma_m^-1 C
        g.append(C_w.T @ y_w)  # g = C^T Sigma_m^-1 y
        yy.append(y_w @ y_w)
        logdet_m.append(2.0 * float(np.sum(log_diag[a:b])))
    Sigma_bar = np.stack([p.prior for p in pending])
    Lam, g = np.stack(Lam), np.stack(g)
    try:
        L = np.linalg.cholesky(Sigma_bar)  # Sigma_bar = L L^T, one per filter
        Lt = np.swapaxes(L, 1, 2)
        eye = np.eye(k)
        B = eye + Lt @ Lam @ L  # B = I + L^T Lambda L, eigenvalues >= 1
        L_B = np.linalg.cholesky(B)
    except np.linalg.LinAlgError:
        return [None] * len(pending)
    Z = np.linalg.solve(L_B, Lt)  # Z = L_B^-1 L^T
    M = np.swapaxes(Z, 1, 2) @ Z  # M = L B^-1 L^T = (Sigma_bar^-1 + Lambda)^-1
    dx = np.einsum("fij,fj->fi", M, g)  # K y
    I_KC = eye - M @ Lam  # I - K C
    P = I_KC @ Sigma_bar @ np.swapaxes(I_KC, 1, 2) + M @ Lam @ np.swapaxes(M, 1, 2)  # Joseph form
    P = 0.5 * (P + np.swapaxes(P, 1, 2))
    out = []
    for f, p in enumerate(pending):
        nis = float(yy[f] - g[f] @ dx[f])  # y^T S^-1 y (Woodbury)
        logdet_S = logdet_m[f] + 2.0 * float(np.sum(np.log(np.diag(L_B[f]))))  # log|Sigma_m| + log|B|
        loglik = -0.5 * (nis + logdet_S + 3 * len(p.S) * LOG_2PI)  # log N(y; 0, S), Eq. (9)
        out.append((dx[f], P[f], nis, loglik))
    return out
