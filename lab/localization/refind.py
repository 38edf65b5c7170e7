r"""Re-finding a lost robot: rejected sightings that agree with one another and not with the estimate.

The localizer's gate rejects a sighting whose innovation is too large for its covariance. That keeps a
wrong fit out of the estimate. But when the estimate itself is off by more than its covariance says (a
turn scale drawn far outside its prior over a long spin, a slip on a bump), the gate also rejects every
sighting that could correct it. The estimate then never comes back: the robot drives by a pose that is
metres off, and the observer stops even looking where the posters are. The lock-out recovery
(``LocalizerConfig.max_rejected_in_a_row``) widens the covariance, but only after several rejections
from several places, and a robot that sees one poster from where it stands may not get them.

Each sighting determines the whole planar pose on its own: :math:`x_z = g(z, l)` with covariance
:math:`\Sigma_z = J_z Q J_z^T` (:func:`~lab.localization.posters.sighting_pose`). :class:`Refinder` keeps
the poses that the recent rejected sightings imply, carried along by the odometry since, with the
filter's motion model, its calibration and their uncertainty (a 5-state ``[x_z, k, c]`` per sighting,
or 6 with the spin's slip, predicted like the filter's own)::

    r_i <- f(r_i, u),   C_i <- F C_i F^T + V M(u) V^T        (r_i = [x_z, k, c] at the sighting)

A new rejected sighting agrees with a kept one when their poses are within the gate, given both their
covariances and what the state's uncertain parts (the posters, the camera's yaw) do to each:

.. math:: d = x_{z,new} - r_{i,1:3}, \quad S = \Sigma_{z,new} + C_{i,1:3} + D P D^T,
          \quad D = J_{l,new} - J_{l,i}, \quad d^T S^{-1} d \le \chi^2_3(p_{gate})

(``D P D^T``: the part of the state both sightings depend on cancels, as the same poster's survey does
when it is seen twice; two posters each bring their own.) Two sightings that are independent evidence
(two posters, or one poster from two places, ``LocalizerConfig.recount_m`` / ``recount_rad`` apart) and
agree say where the robot is better than an estimate that both contradict: the localizer resets its pose
from the newer one (:meth:`~lab.localization.filter.Localizer.update`, ``kind="refound"``), as a
hand-measured start's first sighting does. Two frames of one poster from one place are one piece of
evidence (its fit may be wrong the same way in both), and never re-find the robot by themselves.

Off by default (``LocalizerConfig.refind``): the reset drops what the estimate knew from every earlier
sighting, which pays for a robot that is really lost and costs a filter that is only slightly
overconfident (docs/tuning/localizer-refind.md).

A kept sighting whose carried covariance has grown past the drive's thresholds
(``drive_sigma_m``, ``drive_sigma_rad``) no longer says where the robot is now, and is dropped; an
accepted update drops them all (the estimate is not lost).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lab.geometry import wrap_angle
from lab.localization.models import (
    calibrated_motion_jacobians,
    calibrated_motion_model,
    motion_jacobians,
    motion_model,
)

__all__ = ["Refinder", "RejectedSighting"]


@dataclass
class RejectedSighting:
    """A rejected sighting's pose, carried to now: ``r`` ``[x, y, theta]`` (with the odometry's
    calibration ``[k, c]`` after it, when estimated) and its covariance ``C``; ``Jl`` (3, n) how its pose
    depended on the state when it was seen (:func:`~lab.localization.posters.sighting_pose`); the landmark
    seen and the place it was seen from (:attr:`Refinder.place`)."""

    landmark: str
    place: int
    r: np.ndarray
    C: np.ndarray
    Jl: np.ndarray


class Refinder:
    """The recent rejected sightings, and the test of whether two of them agree (the module docstring).

    Parameters
    ----------
    gate : float
        The chi-square(3) bound two sightings' difference must be within.
    max_sigma_m, max_sigma_rad : float [m], [rad]
        A kept sighting is dropped once its carried position or heading deviation is past these.
    keep : int
        At most this many sightings are kept (the oldest go first).
    """

    def __init__(self, gate: float, max_sigma_m: float, max_sigma_rad: float, keep: int = 8):
        self.gate = float(gate)
        self.max_sigma_m = float(max_sigma_m)
        self.max_sigma_rad = float(max_sigma_rad)
        self.keep = int(keep)
        self.place = 0  # which place the robot is at: the filter counts up when it has moved on
        self.sightings: list[RejectedSighting] = []

    def clear(self) -> None:
        self.sightings.clear()

    def predict(self, u, M, turn_scale_walk: float = 0.0, half_track_m: float = 0.0) -> None:
        """Carry every kept sighting's pose by the odometry increment ``u`` with noise ``M`` (3, 3) in
        its own frame, as :meth:`Localizer.predict` does the estimate (``half_track_m`` for the spin's
        slip, when it is in the state); drop those now too uncertain."""
        kept = []
        for k in self.sightings:
            if k.r.size >= 5:
                F, V = calibrated_motion_jacobians(k.r, u, half_track_m)
                k.r = calibrated_motion_model(k.r, u, half_track_m)
                k.C = F @ k.C @ F.T + V @ M @ V.T
                k.C[3, 3] += turn_scale_walk**2 * abs(float(u[2]))
            else:
                F, V = motion_jacobians(k.r, u)
                k.r = np.asarray(motion_model(k.r, u), float)
                k.C = F @ k.C @ F.T + V @ M @ V.T
            k.C = 0.5 * (k.C + k.C.T)
            sigma_xy = math.sqrt(max(np.linalg.eigvalsh(k.C[:2, :2])))
            if sigma_xy <= self.max_sigma_m and math.sqrt(k.C[2, 2]) <= self.max_sigma_rad:
                kept.append(k)
        self.sightings = kept

    def add(self, new: RejectedSighting, P) -> RejectedSighting | None:
        """Keep a rejected sighting; the kept one it agrees with as independent evidence (the newest such),
        or None. ``P`` is the filter's covariance now (the state's uncertain parts, ``D P D^T``)."""
        agrees = None
        for old in reversed(self.sightings):
            if old.landmark == new.landmark and old.place == new.place:
                continue  # one poster from one place: one piece of evidence
            if self.nis(new, old, P) <= self.gate:
                agrees = old
                break
        self.sightings = (self.sightings + [new])[-self.keep :]
        return agrees

    @staticmethod
    def nis(a: RejectedSighting, b: RejectedSighting, P) -> float:
        """The squared Mahalanobis distance between two kept sightings' poses now (the module docstring)."""
        n = P.shape[0]
        d = a.r[:3] - b.r[:3]
        d[2] = wrap_angle(d[2])
        D = _padded(a.Jl, n) - _padded(b.Jl, n)
        S = a.C[:3, :3] + b.C[:3, :3] + D @ P @ D.T
        return float(d @ np.linalg.solve(S, d))


def _padded(J: np.ndarray, n: int) -> np.ndarray:
    """``J`` (3, m) with zero columns for the state's blocks added since (posters join at the end)."""
    if J.shape[1] == n:
        return J
    out = np.zeros((3, n))
    out[:, : J.shape[1]] = J
    return out
