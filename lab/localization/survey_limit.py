r"""How well a surveyed map can place the robot at best: the error its posters' surveys leave.

A poster map measured with a tape is off by ``sigma_m`` per coordinate and ``sigma_rad`` in yaw per
poster (:attr:`~lab.localization.landmarks.Landmark.survey_sigma_m`). The localizer holds the posters in
its state and refines them from its sightings (:mod:`lab.localization.posters`), but sightings only
measure where the posters are *relative to each other and to the robot*: the frame they fix together
stays off the room's by what their surveys share. Even with perfect sightings, a robot that sees the
posters ``S`` from the point ``p`` is placed wrong by the rigid turn-and-shift that best maps the true
posters onto their surveyed poses, about ``p``. For small errors, each poster's survey error
``e_i = [dx_i, dy_i, dpsi_i]`` is::

    e_i = A_i [t_x, t_y, phi]^T + noise,     A_i = [[1, 0, -(y_i - p_y)],
                                                   [0, 1,  (x_i - p_x)],
                                                   [0, 0,  1          ]]

(``t``: the robot's position error at ``p``, ``phi``: its heading error), and the weighted least squares
fit with ``W = diag(1/sigma_m^2, 1/sigma_m^2, 1/sigma_rad^2)`` per poster gives::

    [t; phi] = (sum A_i^T W A_i)^-1 sum A_i^T W e_i,     Cov = (sum A_i^T W A_i)^-1

This is the floor no estimator of the robot's pose can go below with those posters and that survey
(the Cramer-Rao bound of the linear-Gaussian problem); a real run adds its sightings' errors and its
odometry's. :func:`survey_frame_error` is the fit for given errors (to replay a simulated survey),
:func:`survey_frame_covariance` the covariance, and :func:`posters_in_view` the posters a robot at ``p``
can see, best first, by the localizer's rules (:meth:`~lab.localization.LocalizedRobot.landmark_views`).
``benchmarks/survey_limit.py`` tabulates them for the lab room; docs/tuning/survey-limit.md says what
they mean for issue 52's bars.
"""

from __future__ import annotations

import numpy as np

from lab.localization.filter import LocalizerConfig
from lab.localization.landmarks import LandmarkMap

__all__ = ["posters_in_view", "survey_frame_covariance", "survey_frame_error"]


def _design(posters_xy, at) -> np.ndarray:
    """The stacked ``A_i`` (3k, 3) of the module docstring for the posters' positions (k, 2) about ``at``."""
    q = np.asarray(posters_xy, float).reshape(-1, 2) - np.asarray(at, float)[:2]
    A = np.zeros((3 * len(q), 3))
    A[0::3, 0] = 1.0
    A[0::3, 2] = -q[:, 1]
    A[1::3, 1] = 1.0
    A[1::3, 2] = q[:, 0]
    A[2::3, 2] = 1.0
    return A


def _weights(k: int, sigma_m: float, sigma_rad: float) -> np.ndarray:
    if not (sigma_m > 0 and sigma_rad > 0):
        raise ValueError(f"the survey's sigmas must be > 0, got sigma_m={sigma_m!r}, sigma_rad={sigma_rad!r}")
    return np.tile([sigma_m**-2, sigma_m**-2, sigma_rad**-2], k)


def survey_frame_covariance(posters_xy, at, sigma_m: float, sigma_rad: float) -> np.ndarray:
    """The covariance (3, 3) of the robot's ``[x, y, theta]`` error at ``at`` that the surveys of the
    posters at ``posters_xy`` (k, 2) [m] leave with perfect sightings of them all (the module docstring).

    Raises
    ------
    ValueError
        No poster, or a sigma that is not above 0.
    """
    A = _design(posters_xy, at)
    if len(A) == 0:
        raise ValueError("survey_frame_covariance needs at least one poster")
    w = _weights(len(A) // 3, sigma_m, sigma_rad)
    return np.linalg.inv(A.T @ (w[:, None] * A))


def survey_frame_error(posters_xy, errors, at, sigma_m: float, sigma_rad: float) -> np.ndarray:
    """The robot's ``[x, y, theta]`` error at ``at`` (3,) when the posters at ``posters_xy`` (k, 2) [m]
    are surveyed off by ``errors`` (k, 3): ``[dx, dy, dyaw]`` [m, m, rad] each, and seen perfectly: the
    weighted least squares turn-and-shift of the module docstring."""
    A = _design(posters_xy, at)
    e = np.asarray(errors, float).reshape(-1, 3).ravel()
    if len(e) != len(A) or len(A) == 0:
        raise ValueError(
            f"survey_frame_error needs one error (3,) per poster, got {len(e) // 3} for {len(A) // 3}"
        )
    w = _weights(len(A) // 3, sigma_m, sigma_rad)
    return np.linalg.solve(A.T @ (w[:, None] * A), A.T @ (w * e))


def posters_in_view(landmarks: LandmarkMap, at, config: LocalizerConfig | None = None) -> list[str]:
    """The landmarks a robot at ``at`` = (x, y) can sight, best first: within ``config.max_range_m`` and
    at most ``acos(config.min_facing)`` off their face's normal (default: the localizer's defaults),
    ordered by facing x width / range as :meth:`~lab.localization.LocalizedRobot.landmark_views` orders
    its views (the pan range is left out: a robot can turn to any of them)."""
    c = config or LocalizerConfig()
    p = np.asarray(at, float)[:2]
    scored = []
    for lm in landmarks:
        r = float(np.hypot(*(np.asarray(lm.centre_W[:2]) - p)))
        facing = lm.facing(p)
        if r <= c.max_range_m and facing >= c.min_facing:
            scored.append((-facing * lm.width_m / max(r, 0.5), lm.name))
    return [name for _, name in sorted(scored)]
