"""The floor a surveyed map puts under the robot's error (lab.localization.survey_limit), checked against
exact cases, an independent nonlinear fit (SciPy's least_squares on the rigid turn-and-shift itself)
and a Monte Carlo of the covariance."""

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import least_squares

from lab.localization import Landmark, LandmarkMap, LocalizerConfig, inward_normal
from lab.localization.survey_limit import posters_in_view, survey_frame_covariance, survey_frame_error

XY = np.array([[-2.9, -2.6], [-2.9, 0.5], [0.0, 3.9], [2.9, 1.6], [0.9, -3.9]])
AT = np.array([0.4, -0.7])
SM, SR = 0.015, math.radians(0.7)


def test_a_shift_common_to_every_poster_is_the_robots_position_error():
    """Every poster surveyed 2 cm east and 1 cm north, yaws exact: the robot is placed 2 cm east and 1 cm
    north, its heading right."""
    e = np.tile([0.02, 0.01, 0.0], (len(XY), 1))
    np.testing.assert_allclose(survey_frame_error(XY, e, AT, SM, SR), [0.02, 0.01, 0.0], atol=1e-12)


def test_a_map_turned_about_the_robot_turns_its_heading_and_leaves_its_position():
    """The true posters turned by 0.5 deg about the robot (positions and yaws alike): the heading is off
    by 0.5 deg, the position by the turn's second order only."""
    phi = math.radians(0.5)
    c, s = math.cos(phi), math.sin(phi)
    q = XY - AT
    moved = q @ np.array([[c, s], [-s, c]])  # R(phi) q, row-wise
    e = np.column_stack([moved - q, np.full(len(XY), phi)])
    t = survey_frame_error(XY, e, AT, SM, SR)
    assert t[2] == pytest.approx(phi, rel=1e-3)
    assert math.hypot(t[0], t[1]) < 1e-4  # (1 - cos phi) * 4 m = 0.15 mm


def _rigid_fit(e, at):
    """The turn-and-shift about ``at`` that best maps the true posters onto the surveyed ones, fitted
    as the nonlinear problem it is (rotation matrices, SciPy), weighted by the stated sigmas."""
    surveyed = XY + e[:, :2]

    def residuals(v):
        tx, ty, phi = v
        c, s = math.cos(phi), math.sin(phi)
        q = XY - at
        pred = at + q @ np.array([[c, s], [-s, c]]) + [tx, ty]
        return np.concatenate([((pred - surveyed) / SM).ravel(), (phi - e[:, 2]) / SR])

    return least_squares(residuals, np.zeros(3), xtol=1e-14, ftol=1e-14, gtol=1e-14).x


def test_the_linear_fit_agrees_with_the_nonlinear_rigid_fit_for_survey_sized_errors():
    rng = np.random.default_rng(7)
    for _ in range(5):
        e = rng.standard_normal((len(XY), 3)) * [SM, SM, SR]
        lin = survey_frame_error(XY, e, AT, SM, SR)
        ref = _rigid_fit(e, AT)
        np.testing.assert_allclose(lin[:2], ref[:2], atol=2e-4)  # 0.2 mm of errors of about 1 cm
        assert lin[2] == pytest.approx(ref[2], abs=math.radians(0.01))


def test_the_stated_covariance_is_the_spread_of_the_fit_over_survey_draws():
    rng = np.random.default_rng(11)
    draws = np.array(
        [
            survey_frame_error(XY, rng.standard_normal((len(XY), 3)) * [SM, SM, SR], AT, SM, SR)
            for _ in range(4000)
        ]
    )
    C = survey_frame_covariance(XY, AT, SM, SR)
    np.testing.assert_allclose(np.sqrt(np.diag(np.cov(draws.T))), np.sqrt(np.diag(C)), rtol=0.05)
    # more posters, a smaller floor; one poster alone leaves its whole survey, turned by its yaw's lever
    assert np.trace(survey_frame_covariance(XY[:2], AT, SM, SR)[:2, :2]) > np.trace(C[:2, :2])
    C1 = survey_frame_covariance(XY[:1], AT, SM, SR)
    lever = np.hypot(*(XY[0] - AT))
    assert np.trace(C1[:2, :2]) == pytest.approx(2 * SM**2 + (SR * lever) ** 2, rel=1e-9)


def test_bad_input_is_named():
    with pytest.raises(ValueError, match="sigmas must be > 0"):
        survey_frame_covariance(XY, AT, 0.0, SR)
    with pytest.raises(ValueError, match="at least one poster"):
        survey_frame_covariance(np.zeros((0, 2)), AT, SM, SR)
    with pytest.raises(ValueError, match="one error"):
        survey_frame_error(XY, np.zeros((2, 3)), AT, SM, SR)


def _poster(name, x, y, yaw):
    return Landmark(name, (x, y, 1.2), yaw, (0.02, 0.6, 0.4), inward_normal((x, y), yaw, (0.02, 0.6, 0.4)))


def test_posters_in_view_are_the_ones_in_range_and_facing_best_first():
    m = LandmarkMap(
        (
            _poster("west_far", -2.9, 3.0, 0.0),  # faces +x, 3.7 m off at 36 deg
            _poster("west_near", -2.9, 0.0, 0.0),  # faces +x, 2.9 m, head-on
            _poster("east", 2.5, 0.0, 0.0),  # faces -x, 2.5 m, head-on: the best
            _poster("far", 2.9, 7.0, 0.0),  # 7.6 m: out of range
        ),
        (6.0, 8.0),
    )
    assert posters_in_view(m, (0.0, 0.0)) == ["east", "west_near", "west_far"]
    # the localizer's own range: a robot that looks only 3 m out does not count the 4.2 m poster
    assert posters_in_view(m, (0.0, 0.0), LocalizerConfig(max_range_m=3.0)) == ["east", "west_near"]
    # a robot beside the east poster sees it edge-on: not in view
    assert posters_in_view(m, (2.4, 2.0)) == ["west_far", "west_near"]  # now the nearer, more head-on


def test_the_benchmark_tabulates_a_floor_that_falls_with_the_posters_seen():
    """``benchmarks/survey_limit.py`` on the lab room: one row per number of posters seen, its median
    falling as more are seen; a profile without a survey is refused by name."""
    root = Path(__file__).resolve().parents[1]
    script = root / "benchmarks" / "survey_limit.py"
    out = subprocess.run(
        [
            sys.executable,
            str(script),
            "--sensing",
            "benchmarks/sensing/survey_and_start.toml",
            "--draws",
            "6",
        ],
        cwd=root,
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    rows = [line for line in out.splitlines() if line.startswith("| best") or line.startswith("| all")]
    medians = [float(r.split("|")[2].split()[0]) for r in rows]
    assert len(medians) == 6 and all(a > b for a, b in zip(medians, medians[1:], strict=False))
    bad = subprocess.run(
        [sys.executable, str(script), "--sensing", "ideal", "--draws", "1"],
        cwd=root,
        capture_output=True,
        text=True,
    )
    assert bad.returncode != 0 and "has no survey error" in bad.stderr
