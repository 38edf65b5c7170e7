r"""The 6-DOF pose EKF of the identification paper (Sec. III-A) and the search paper (Sec. III-C).

One filter tracks one database model's pose ``X = [x, y, z, alpha, beta, gamma]`` of the object in
the left camera frame C. A step is::

    ekf.predict(G_RC_prev, G_RC, G_odom, dt)   # Eqs. (1)-(2): robot, pan-tilt and object motion
    result = ekf.update(d_C, b_O, Sigma_d)     # Eq. (3): matched 3D features, gated, Joseph form
    result.log_likelihood                      # Eq. (9): the data likelihood for the model's probability

The update's algebra (whitened, 6x6 information form, never the 3n x 3n innovation covariance) is
:mod:`lab.estimation.kernel`; the errors the filter models besides each feature's own noise (the
camera's calibration, shared by every feature and every frame, and the database's points) are
:mod:`lab.estimation.uncertainty`; when a filter counts as diverged is :mod:`lab.estimation.health`.

**Steps a bank drives.** :meth:`PoseEKF.predict` and :meth:`PoseEKF.update` are each a few public
steps, which :class:`lab.estimation.EKFBank` runs for all its filters, their shared work batched
(:mod:`lab.estimation.bank` lists them).

With ``EKFConfig(chart=ROTATION_VECTOR)`` the same equations run with ``C`` and ``Sigma`` over
``[x_r, phi]`` (``phi`` a small rotation in C) and the correction is applied as
``R <- Exp(phi) R``: the state is still the Euler ``X``, but the filter no longer breaks down at
gimbal lock (see :class:`OrientationChart`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum

import numpy as np

from lab.estimation.estimate import PoseEstimate
from lab.estimation.fit import (
    RansacConfig,
    check_matches,
    chi2_quantile,
    point_spread,
    ransac_pose,
    valid_rows,
)
from lab.estimation.gate import GateConfig, gate_rows
from lab.estimation.health import DivergenceConfig, health_many
from lab.estimation.kernel import (
    Motion,
    PendingUpdate,
    checked_motion,
    data_log_likelihood,
    information_update,
    whitened,
)
from lab.estimation.models import (
    OrientationChart,
    canonical_state,
    euler_to_rv_jacobian,
    motion_step,
    retract_rv,
    rv_to_euler_jacobian,
)
from lab.estimation.noise import ProcessNoise, process_noise_covariance
from lab.estimation.uncertainty import (
    CalibrationUncertainty,
    ModelUncertainty,
    calibration_columns,
    calibration_jacobian,
    model_offset_covariance,
    with_calibration,
)

__all__ = [
    "EKFConfig",
    "UpdateOutcome",
    "UpdateResult",
    "PoseEKF",
    # re-exported from lab.estimation.uncertainty, .health and .kernel, where they moved
    "CalibrationUncertainty",
    "DivergenceConfig",
    "ModelUncertainty",
    "calibration_jacobian",
    "data_log_likelihood",
    "model_offset_covariance",
]


@dataclass(frozen=True)
class EKFConfig:
    """Everything a :class:`PoseEKF` can be tuned with.

    Attributes
    ----------
    process : ProcessNoise
        Object motion noise, odometry error, Eq. (4)'s floor.
    gate : GateConfig
        Geometric feasibility check before an update.
    ransac : RansacConfig
        (Re-)initialisation from matches.
    divergence : DivergenceConfig
        Divergence criteria.
    auto_initialize : bool
        ``update`` initialises (and re-initialises after divergence) from its matches by RANSAC.
    calibration : CalibrationUncertainty
        The calibration error all features of a frame share (see the module docstring);
        ``CalibrationUncertainty.none()`` is the papers' update.
    model : ModelUncertainty
        The database's offset from its object, shared by all features of all frames;
        ``ModelUncertainty.none()`` is the papers' update.
    chart : OrientationChart
        Coordinates of the covariance's orientation part. ``EULER`` (default) is the papers' EKF and
        matches filterpy step for step; ``ROTATION_VECTOR`` keeps the same state ``X`` but tracks the
        uncertainty as a small rotation in C, which stays well defined at Euler gimbal lock (a box's
        x face looking straight at a level camera). See :mod:`lab.estimation.models`.
    """

    process: ProcessNoise = field(default_factory=ProcessNoise)
    gate: GateConfig = field(default_factory=GateConfig)
    ransac: RansacConfig = field(default_factory=RansacConfig)
    divergence: DivergenceConfig = field(default_factory=DivergenceConfig)
    auto_initialize: bool = True
    chart: OrientationChart = OrientationChart.EULER
    calibration: CalibrationUncertainty = field(default_factory=CalibrationUncertainty)
    model: ModelUncertainty = field(default_factory=ModelUncertainty)


class UpdateOutcome(Enum):
    """What :meth:`PoseEKF.update` did with a frame's matches."""

    UPDATED = "updated"  # an EKF measurement update was applied
    INITIALIZED = "initialized"  # the filter was (first) initialised by RANSAC
    REINITIALIZED = "reinitialized"  # re-initialised by RANSAC after divergence
    SKIPPED = "skipped"  # nothing changed; see the reason


@dataclass(frozen=True)
class UpdateResult:
    """The record of one :meth:`PoseEKF.update` call.

    Attributes
    ----------
    applied : bool
        True when an EKF measurement update changed the state (``outcome is UPDATED``).
    outcome : UpdateOutcome
    reason : str
        Why, in words (skips, initialisations and divergence name their cause).
    n_matches : int
        Rows passed in.
    n_used : int
        Rows used (finite, gated in; the RANSAC inliers for an initialisation).
    inliers : ndarray, shape (n_matches,), bool
        Which rows were used.
    nis : float or None
        Normalised innovation squared ``y^T S^-1 y`` (chi-square with ``dof`` degrees of freedom
        when the filter is consistent).
    dof : int
        ``3 * n_used`` when applied, else 0.
    log_likelihood : float or None
        ``log N(D | H(mu_bar), C Sigma_bar C^T + Sigma_m)``: Eq. (9)'s data likelihood of the used
        matches (None when no update was applied).
    estimate : PoseEstimate or None
        The state after the call.
    """

    applied: bool
    outcome: UpdateOutcome
    reason: str
    n_matches: int = 0
    n_used: int = 0
    inliers: np.ndarray = field(default_factory=lambda: np.zeros(0, bool), repr=False)
    nis: float | None = None
    dof: int = 0
    log_likelihood: float | None = None
    estimate: PoseEstimate | None = field(default=None, repr=False)


class PoseEKF:
    """EKF on the object's 6-DOF pose in the camera frame for one database model.

    Parameters
    ----------
    config : EKFConfig, optional
    rng : numpy.random.Generator
        Seeded generator for the RANSAC (re-)initialisations.

    Attributes
    ----------
    mu : ndarray, shape (6,) or None
        Current state ``X`` [m, rad]; None before initialisation.
    P : ndarray, shape (6, 6) or None
        The covariance the filter propagates, in its chart (``config.chart``): over ``X`` (EULER) or
        over ``[x_r, phi]`` (ROTATION_VECTOR). :attr:`Sigma` and :attr:`Sigma_rv` give both views.
    t : float [s]
        Filter time (advanced by ``predict``'s ``dt``).
    divergence : str or None
        Why the filter is considered diverged; it is re-initialised from the next update's matches
        (when ``config.auto_initialize``) or by :meth:`initialize`.
    n_reinit : int
        How many times it was re-initialised.
    last_result : UpdateResult or None

    Notes
    -----
    Never raises for bad data (NaN measurements, too few or degenerate matches, a failed
    factorisation): the update is skipped, the state stays finite and the reason is recorded.
    Wrong shapes or types raise ``ValueError``.
    """

    def __init__(self, config: EKFConfig | None = None, *, rng: np.random.Generator):
        if not isinstance(rng, np.random.Generator):
            raise ValueError(f"rng must be a numpy.random.Generator (seeded), got {type(rng).__name__}")
        self.config = config or EKFConfig()
        self.rng = rng
        self.mu: np.ndarray | None = None
        self.P: np.ndarray | None = None
        self.P_xc = self._no_cross_covariance()
        self.Sigma_m = np.zeros((6, 6))  # the database offset's, over the last update's points
        self.t = 0.0
        self.divergence: str | None = None
        self.n_reinit = 0
        self.last_result: UpdateResult | None = None
        self._huge_nis_run = 0
        self._gated_out_run = 0

    # ------------------------------------------------------------------ state
    def _no_cross_covariance(self) -> np.ndarray:
        """``P_xc`` of a state that knows nothing of the calibration error: zeros (6, m)."""
        return np.zeros((6, len(calibration_columns(self.config.calibration))))

    @property
    def euler_chart(self) -> bool:
        """True when the covariance is over the Euler angles (``config.chart`` is ``EULER``, the papers'
        filter), False over a small rotation vector; the health check needs it (gimbal lock)."""
        return self.config.chart is OrientationChart.EULER

    @property
    def initialized(self) -> bool:
        return self.mu is not None

    @property
    def Sigma(self) -> np.ndarray | None:
        """Covariance (6, 6) over the Euler state ``X`` (derived from :attr:`P` in the rotation-vector
        chart, where it blows up near gimbal lock)."""
        if self.P is None or self.euler_chart:
            return self.P
        T_inv = rv_to_euler_jacobian(self.mu)
        Sigma = T_inv @ self.P @ T_inv.T
        return 0.5 * (Sigma + Sigma.T)

    @property
    def Sigma_rv(self) -> np.ndarray | None:
        """Covariance (6, 6) over ``[x_r, phi]``, ``phi`` a small rotation vector in C."""
        if self.P is None or not self.euler_chart:
            return self.P
        T = euler_to_rv_jacobian(self.mu)
        Sigma_rv = T @ self.P @ T.T
        return 0.5 * (Sigma_rv + Sigma_rv.T)

    @property
    def estimate(self) -> PoseEstimate | None:
        """The current estimate (a read-only snapshot), or None before initialisation."""
        if self.mu is None:
            return None
        return PoseEstimate(self.mu, self.Sigma, self.t, self.Sigma_rv)

    @property
    def object_estimate(self) -> PoseEstimate | None:
        """Where the object is: :attr:`estimate` (the pose its features say) with the database's own
        error added, ``Sigma_rv + blockdiag(R_CO, R_CO) Sigma_m blockdiag(R_CO, R_CO)^T`` (see
        :class:`ModelUncertainty`). The same as :attr:`estimate` for an exact database."""
        est = self.estimate
        if est is None or not self.Sigma_m.any():
            return est
        J = np.zeros((6, 6))
        J[:3, :3] = J[3:, 3:] = est.G_CO[:3, :3]  # tau moves the origin by R_CO tau, rho turns it in C
        Sigma_rv = est.Sigma_rv + J @ self.Sigma_m @ J.T
        Sigma_rv = 0.5 * (Sigma_rv + Sigma_rv.T)
        T_inv = rv_to_euler_jacobian(self.mu)
        return PoseEstimate(self.mu, T_inv @ Sigma_rv @ T_inv.T, self.t, Sigma_rv)

    @property
    def log_likelihood(self) -> float | None:
        """Eq. (9)'s log data likelihood of the last update (None if it applied no update)."""
        return None if self.last_result is None else self.last_result.log_likelihood

    def initialize(self, mu, Sigma, t: float | None = None, *, Sigma_rv=None) -> None:
        """Set the state explicitly (a prior, or a pose from elsewhere); clears any divergence.

        ``Sigma`` is over the Euler state; alternatively pass ``Sigma=None`` and ``Sigma_rv`` over
        ``[x_r, phi]`` (what a rotation-vector filter propagates; converted for an Euler one).
        """
        mu = np.asarray(mu, dtype=float)
        given = Sigma if Sigma is not None else Sigma_rv
        if given is None or (Sigma is not None and Sigma_rv is not None):
            raise ValueError("initialize needs exactly one of Sigma and Sigma_rv")
        given = np.asarray(given, dtype=float)
        if mu.shape != (6,) or given.shape != (6, 6):
            raise ValueError(
                f"initialize needs mu (6,) and a (6, 6) covariance, got {mu.shape} and {given.shape}"
            )
        if not (np.all(np.isfinite(mu)) and np.all(np.isfinite(given))):
            raise ValueError("initialize needs a finite mu and covariance")
        try:
            np.linalg.cholesky(given)
        except np.linalg.LinAlgError:
            raise ValueError("initialize needs a symmetric positive definite covariance") from None
        given = 0.5 * (given + given.T)
        in_rv = Sigma is None
        if in_rv == self.euler_chart:  # convert to the filter's chart
            T = rv_to_euler_jacobian(mu) if in_rv else euler_to_rv_jacobian(mu)
            given = T @ given @ T.T
        if self.euler_chart:
            self.mu, self.P = canonical_state(mu, given)
        else:
            self.mu, self.P = retract_rv(mu, np.zeros(6)), given  # canonical Euler angles, same rotation
        self.P_xc = self._no_cross_covariance()
        self.Sigma_m = np.zeros((6, 6))
        if t is not None:
            self.t = float(t)
        self.divergence = None
        self._huge_nis_run = 0
        self._gated_out_run = 0

    def reset(self) -> None:
        """Forget the state (the next update initialises again)."""
        self.mu = self.P = None
        self.P_xc = self._no_cross_covariance()
        self.Sigma_m = np.zeros((6, 6))
        self.divergence = None
        self._huge_nis_run = 0
        self._gated_out_run = 0

    def _health(self, mu, P) -> str | None:
        """Why (mu, P) is not a usable estimate, or None."""
        return health_many(self.config.divergence, self.euler_chart, mu[None], P[None])[0]

    # ---------------------------------------------------------------- predict
    def predict(
        self, G_RC_prev, G_RC, G_odom, dt: float, *, G_OO=None, Sigma_odom=None
    ) -> PoseEstimate | None:
        r"""Prediction, Eqs. (1)-(2): ``mu_bar = F(mu, u)``, ``Sigma_bar = F Sigma F^T + Q``.

        Parameters
        ----------
        G_RC_prev, G_RC : ndarray, shape (4, 4)
            Camera in robot at the previous and the current step (``StereoCamera.G_RC(pan, tilt)``).
        G_odom : ndarray, shape (4, 4)
            Odometry increment ``G_{R(k-1) R(k)}`` (``lab.geometry.relative_pose2d(prev, now)``).
        dt : float [s]
            Time since the previous step (>= 0).
        G_OO : ndarray, shape (4, 4), optional
            The object's own expected motion ``G_{O(k-1) O(k)}``; identity if omitted.
        Sigma_odom : ndarray, shape (6, 6), optional
            Odometry error covariance (twist in R(k)); from ``config.process`` if omitted.

        Returns
        -------
        PoseEstimate or None
            ``(mu_bar, Sigma_bar)``, or None while the filter is not initialised.
        """
        return self._predict_motion(checked_motion(G_RC_prev, G_RC, G_odom, dt, G_OO), Sigma_odom)

    def _predict_motion(self, motion: Motion, Sigma_odom=None) -> PoseEstimate | None:
        """:meth:`predict` with its inputs checked (:func:`checked_motion`; a bank checks them once)."""
        staged = self.predict_staged(motion, Sigma_odom)
        if staged is not None:
            self.commit_prediction(*staged, self._health(staged[0], staged[2]))
        return self.estimate

    def predict_staged(self, motion: Motion, Sigma_odom=None):
        """The prediction of Eqs. (1)-(2) before its health check, from a checked ``motion``
        (:func:`~lab.estimation.kernel.checked_motion`): ``(mu_bar, F, P_bar)``, ``mu_bar = F(mu, u)``,
        its Jacobian and ``Sigma_bar = F Sigma F^T + Q`` in the filter's chart; or None when there is
        none to make (not initialised, or the motion is unknown: then the filter is marked diverged).
        Advances :attr:`t`; the state changes only in :meth:`commit_prediction`."""
        self.t += motion.dt
        if self.mu is None:
            return None
        if motion.bad:  # the robot's motion is unknown: we no longer know where the object is
            self.divergence = f"prediction impossible: non-finite or absurd (> 1 km) {', '.join(motion.bad)}"
            return None
        chart = self.config.chart
        mats = motion.mats
        G_RC, G_odom = mats["G_RC"], mats["G_odom"]
        mu_bar, F = motion_step(
            self.mu, motion.A, mats.get("G_OO"), jacobian=True, chart=chart
        )  # mu_bar = F(mu, u)
        Q = process_noise_covariance(mu_bar, G_RC, G_odom, motion.dt, self.config.process, Sigma_odom, chart)
        P_bar = F @ self.P @ F.T + Q  # Sigma_bar = F Sigma F^T + Q
        P_bar = 0.5 * (P_bar + P_bar.T)
        return mu_bar, F, P_bar

    def commit_prediction(self, mu_bar, F, P_bar, problem: str | None) -> None:
        """Keep a staged prediction (:meth:`predict_staged`'s ``mu_bar, F, P_bar``) as the state unless
        its health ``problem`` (:func:`lab.estimation.health.health_many`'s verdict on ``mu_bar, P_bar``)
        makes it unusable; a covariance blow-up or gimbal lock is kept but marks the filter diverged.
        The cross-covariance with the calibration error follows, ``P_xc <- F P_xc``."""
        if problem is None or problem.startswith(("covariance blow-up", "gimbal")):
            self.mu, self.P = mu_bar, P_bar  # finite and SPD: keep it, even if it is lost
            self.P_xc = F @ self.P_xc  # the calibration error c stays what it was
        if problem is not None and self.divergence is None:
            self.divergence = problem

    # ----------------------------------------------------------------- update
    def _skip(self, reason, n, inliers=None) -> UpdateResult:
        res = UpdateResult(
            False,
            UpdateOutcome.SKIPPED,
            reason,
            n,
            0,
            np.zeros(n, bool) if inliers is None else inliers,
            estimate=self.estimate,
        )
        self.last_result = res
        return res

    def _try_initialize(self, d, b, S, n) -> UpdateResult:
        was = self.divergence
        init = ransac_pose(d, b, S, self.rng, self.config.ransac)
        if not init.success:
            why = f"not initialised: {init.reason}"
            if was is not None:
                why = f"diverged ({was}); re-initialisation failed: {init.reason}"
            return self._skip(why, n)
        self.initialize(init.mu, None, Sigma_rv=init.Sigma_rv)
        self.Sigma_m = model_offset_covariance(b[init.inliers], self.config.model.point_std_m)
        problem = self._health(self.mu, self.P)
        if problem is not None:  # e.g. an Euler filter initialised at gimbal lock
            self.divergence = problem
        if was is None:
            outcome, why = UpdateOutcome.INITIALIZED, init.reason
        else:
            self.n_reinit += 1
            outcome, why = (
                UpdateOutcome.REINITIALIZED,
                f"re-initialised after divergence ({was}): {init.reason}",
            )
        res = UpdateResult(
            False, outcome, why, n, init.n_inliers, init.inliers.copy(), estimate=self.estimate
        )
        self.last_result = res
        return res

    def update(self, d_C, b_O, Sigma_d) -> UpdateResult:
        r"""Measurement update with one frame's matched features, Eq. (3), after the feasibility check.

        Parameters
        ----------
        d_C : array_like, shape (n, 3) [m]
            Measured 3D features in the camera frame C (the ``d_j`` of Eq. (3)).
        b_O : array_like, shape (n, 3) [m]
            Their matched database features ``b_{J(j)}`` in the object frame O.
        Sigma_d : array_like, shape (n, 3, 3) [m^2]
            Covariance of each measured feature (the diagonal blocks of ``Sigma_m``).

        Returns
        -------
        UpdateResult
            Rows with non-finite values or a covariance that is not positive definite are dropped
            (``inliers`` False); fewer than ``gate.min_matches`` usable rows, degenerate geometry or a
            failed factorisation skip the update with the reason. While the filter is not initialised
            or has diverged, the matches initialise it by RANSAC instead (``auto_initialize``).
        """
        pending = self.begin_update(d_C, b_O, Sigma_d)
        if isinstance(pending, UpdateResult):
            return pending
        try:
            y_w, C_w, logdet_m = whitened(pending.r, pending.C, pending.S)  # innovation y = D - H(mu_bar)
            out = information_update(pending.prior, y_w, C_w, logdet_m)
        except np.linalg.LinAlgError:
            return self.fail_update(pending)
        return self._end_update(pending, *out)

    def begin_update(self, d_C, b_O, Sigma_d, valid=None, gated=None) -> UpdateResult | PendingUpdate:
        """:meth:`update` (Eq. (3)) up to its linear algebra: the input checks, the gate (search paper
        Sec. III-C), and the prior ``Sigma_bar`` and Jacobian ``C`` with the calibration error, as a
        :class:`~lab.estimation.kernel.PendingUpdate`; or the :class:`UpdateResult`, when the update is
        skipped or the matches (re-)initialise the filter. ``valid``: the rows'
        :func:`~lab.estimation.fit.valid_rows`, ``gated``: :func:`~lab.estimation.gate.gate_rows`'
        output on the valid rows, when already known (a bank shares and batches them)."""
        d, b, S = check_matches(d_C, b_O, Sigma_d)
        n = d.shape[0]
        valid = valid_rows(d, b, S) if valid is None else valid
        n_valid = int(np.count_nonzero(valid))
        dropped = n - n_valid
        note = f" ({dropped} non-finite or invalid rows dropped)" if dropped else ""

        if self.mu is None or self.divergence is not None:
            if not self.config.auto_initialize:
                why = "not initialised" if self.mu is None else f"diverged: {self.divergence}"
                return self._skip(why, n)
            return self._try_initialize(d, b, S, n)

        gc = self.config.gate
        if n_valid < gc.min_matches:
            return self._skip(f"too few matches: {n_valid} usable < {gc.min_matches}{note}", n)
        idx = np.flatnonzero(valid)
        d, b, S = d[idx], b[idx], S[idx]

        keep, r, C, inliers, why_not = self._feasible_matches(d, b, S, idx, n, n_valid, note, gated)
        if why_not is not None:
            return self._skip(why_not, n, inliers)
        cal = self.config.calibration
        prior, C_c = with_calibration(self.P, self.P_xc, r[keep], C[keep], d[keep], cal)
        return PendingUpdate(n, n_valid, note, keep, inliers, prior, r[keep], C_c, S[keep], b[keep])

    def fail_update(self, pending: PendingUpdate) -> UpdateResult:
        """End a pending update whose factorisation failed (the information update raised
        ``LinAlgError``): skipped, and the filter marked diverged (its covariance is not SPD)."""
        self.divergence = "covariance is not positive definite"
        return self._skip("update failed: a covariance factorisation failed", pending.n, pending.inliers)

    def _end_update(self, pending: PendingUpdate, dx, P, nis: float, loglik: float) -> UpdateResult:
        """:meth:`update` after its linear algebra (``information_update``'s outputs)."""
        mu, P, P_xc = self.corrected_state(dx, P)
        return self.finish_update(pending, mu, P, P_xc, nis, loglik, self._health(mu, P))

    def corrected_state(self, dx, P):
        """``(mu, P, P_xc)`` after the update from :func:`lab.estimation.kernel.information_update`'s
        correction ``dx = K y`` and Joseph-form covariance ``P``: ``mu = mu_bar + K y`` in the filter's
        chart (wrapped Euler angles, or ``R <- Exp(phi) R``), the state's covariance (6, 6) and its
        cross-covariance with the calibration error (a consider update: ``c`` itself is not updated).
        The filter is unchanged until :meth:`finish_update`."""
        dx = dx[:6]  # consider update: the estimate of c stays 0 (module docstring)
        mu, P = self._corrected(self.mu, dx, P)  # P still (6 + m, 6 + m): the chart acts on its rows
        return mu, P[:6, :6], P[:6, 6:]  # and Sigma_c stays Sigma_c

    def finish_update(
        self, pending: PendingUpdate, mu, P, P_xc, nis: float, loglik: float, problem: str | None
    ) -> UpdateResult:
        """Apply a corrected state (:meth:`corrected_state`'s ``mu, P, P_xc``, the update's ``nis`` and
        Eq. (9)'s ``loglik``) unless its health ``problem`` (:func:`lab.estimation.health.health_many`)
        rejects it; then watch the NIS for divergence and record the :class:`UpdateResult`."""
        n, inliers = pending.n, pending.inliers
        if problem is not None and not problem.startswith(("covariance blow-up", "gimbal")):
            self.divergence = problem
            return self._skip(f"update rejected: {problem}", n, inliers)
        self.mu, self.P, self.P_xc = mu, P, P_xc
        self.Sigma_m = model_offset_covariance(pending.b, self.config.model.point_std_m)
        n_used = int(np.count_nonzero(pending.keep))
        dof = 3 * n_used
        self._watch_divergence(nis, dof, problem)
        why = f"updated with {n_used} of {pending.n_valid} matches{pending.note}"
        res = UpdateResult(
            True, UpdateOutcome.UPDATED, why, n, n_used, inliers, nis, dof, loglik, self.estimate
        )
        self.last_result = res
        return res

    def _feasible_matches(self, d, b, S, idx, n: int, n_valid: int, note: str, gated=None):
        """The geometric feasibility check before an update: which usable matches pass the gate.

        Returns ``(keep, r, C, inliers, why_not)``: the gate's verdict, residuals and Jacobians on the
        usable rows (``gate_rows``), the verdict on all ``n`` input rows, and the reason to skip the update
        (None to go on): too few matches passed (``gating_patience`` such frames in a row mean the
        track is lost) or their model points are collinear.
        """
        gc = self.config.gate
        keep, r, C = gate_rows(self.mu, self.P, d, b, S, gc, self.config.chart) if gated is None else gated
        inliers = np.zeros(n, bool)
        inliers[idx[keep]] = True
        n_used = int(np.count_nonzero(keep))
        if n_used < gc.min_matches:
            self._gated_out_run += 1
            if self._gated_out_run >= self.config.divergence.gating_patience:
                self.divergence = (
                    f"track lost: the gate rejected the matches {self._gated_out_run} frames in a row"
                )
            return keep, r, C, inliers, f"gating kept {n_used} of {n_valid} matches < {gc.min_matches}{note}"
        self._gated_out_run = 0
        if point_spread(b[keep]) < gc.min_spread_m:
            why = f"degenerate geometry: the matched model points are collinear or coincident{note}"
            return keep, r, C, inliers, why
        return keep, r, C, inliers, None

    def _corrected(self, mu_bar, dx, P):
        """``mu = mu_bar + K y`` in the filter's chart, with its covariance ``P`` (6 + m, 6 + m): the
        state's rows and columns follow the chart, the calibration error's stay."""
        if self.euler_chart:
            return canonical_state(mu_bar + dx, P)  # alpha, gamma wrapped, beta in range
        return retract_rv(mu_bar, dx), P  # x_r + dx_r, R <- Exp(phi) R (the reset's Jacobian ~ I is ignored)

    def _watch_divergence(self, nis: float, dof: int, problem: str | None) -> None:
        """After an update: a health problem the update was still applied with, or ``nis_patience``
        updates in a row whose NIS exceeds its chi-square(``dof``) ``nis_prob`` quantile, mark the filter
        diverged (the next frame re-initialises it)."""
        dcfg = self.config.divergence
        self._huge_nis_run = self._huge_nis_run + 1 if nis > chi2_quantile(dcfg.nis_prob, dof) else 0
        if problem is not None:
            self.divergence = problem
        elif self._huge_nis_run >= dcfg.nis_patience:
            self.divergence = (
                f"NIS above its chi-square({dof}) {dcfg.nis_prob} quantile "
                f"{self._huge_nis_run} updates in a row (last {nis:.1f})"
            )
