"""A bank of pose EKFs: one per database model, all fed from the same frames.

The identification paper runs "an Extended Kalman Filter ... for each of the plausible models in the
database" (Sec. IV). Every filter sees the same robot and pan-tilt motion, so :meth:`EKFBank.predict`
applies one motion to all of them; each model has its own correspondences ``J_i``, so updates are
per model.
"""

from __future__ import annotations

import numpy as np

from lab.estimation.ekf import EKFConfig, PoseEKF, UpdateResult
from lab.estimation.estimate import PoseEstimate

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
        return tuple(
            f.predict(G_RC_prev, G_RC, G_odom, dt, G_OO=G_OO, Sigma_odom=Sigma_odom) for f in self.filters
        )

    def update(self, i: int, d_C, b_O, Sigma_d) -> UpdateResult:
        """Update model ``i``'s filter with its matched pairs (same arguments as :meth:`PoseEKF.update`)."""
        if not 0 <= i < len(self.filters):
            raise ValueError(f"model index {i} is outside [0, {len(self.filters) - 1}]")
        return self.filters[i].update(d_C, b_O, Sigma_d)

    @property
    def estimates(self) -> tuple[PoseEstimate | None, ...]:
        """Every model's current estimate (None where not initialised)."""
        return tuple(f.estimate for f in self.filters)

    @property
    def log_likelihoods(self) -> tuple[float | None, ...]:
        """Every model's Eq. (9) log data likelihood from its last update (None where none was applied)."""
        return tuple(f.log_likelihood for f in self.filters)
