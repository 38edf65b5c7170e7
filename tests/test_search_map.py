"""The probability map M_p against a brute-force loop written straight from the paper's Eqs. (1)-(3),
and the properties a Bayes filter over cells must have (sums to 1, mass leaves a searched empty cell
for the others in proportion to what they hold, updates commute)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lab.errors import ConfigError
from lab.navigation import GridSpec
from lab.search.probability_map import (
    ColourPeakDetection,
    DetectionModel,
    LocalSearchDetection,
    ProbabilityMap,
    bayes_update,
    cells_within,
    constant_beta_field,
    detection_likelihood,
    growing_beta_field,
    map_peaks,
    region_prior,
    uniform_prior,
    update,
    update_global,
)


# --- the brute-force peer: one cell at a time, Eq. (2) case by case ---------------------------------
def eq2(y, measured, cell, alpha, beta):
    """P(y_uv = y | h_ij = 1), Eq. (2), for a single cell."""
    if measured == cell:
        return beta if y == 0 else 1.0 - beta
    return 1.0 - alpha if y == 0 else alpha


def brute_force_update(P, measured, y, alpha, beta_of_cell):
    """Eqs. (1) and (3) by loops; ``beta_of_cell(i, j)`` gives the beta used for cell (i, j) when it is
    (or counts as) the measured one, None for 'another cell'."""
    nx, ny = P.shape

    def likelihood(i, j):
        b = beta_of_cell(i, j)
        if b is None:
            return eq2(y, measured, (-1, -1), alpha, 0.5)  # (u, v) != (i, j)
        return eq2(y, (i, j), (i, j), alpha, b)  # (u, v) == (i, j), with this cell's beta

    evidence = 0.0  # Eq. (3)
    for m in range(nx):
        for n in range(ny):
            evidence += likelihood(m, n) * P[m, n]
    out = np.zeros_like(P)
    for i in range(nx):
        for j in range(ny):
            out[i, j] = likelihood(i, j) * P[i, j] / evidence  # Eq. (1)
    return out


def random_map(rng, shape):
    P = rng.random(shape) ** 3 + 1e-6
    return P / P.sum()


def test_constant_update_matches_brute_force():
    rng = np.random.default_rng(0)
    for trial in range(20):
        shape = (int(rng.integers(1, 9)), int(rng.integers(1, 9)))
        P = random_map(rng, shape)
        cell = (int(rng.integers(shape[0])), int(rng.integers(shape[1])))
        alpha, beta = rng.uniform(0.01, 0.45), rng.uniform(0.01, 0.45)
        for y in (0, 1):
            fast = update(P, cell, y, alpha, beta)
            slow = brute_force_update(
                P, cell, y, alpha, lambda i, j, b=beta, c=cell: b if (i, j) == c else None
            )
            np.testing.assert_allclose(fast, slow, rtol=1e-12, atol=1e-15, err_msg=f"trial {trial} y={y}")


def test_growing_beta_update_matches_brute_force():
    """The global search's update: beta(d) = min(1 - alpha, beta0 exp(d / lambda)) per cell, with the
    cell centres computed here by hand from the grid's origin and resolution."""
    rng = np.random.default_rng(1)
    for _ in range(10):
        res = float(rng.choice([0.1, 0.2, 0.25]))
        spec = GridSpec((float(rng.uniform(-3, 0)), float(rng.uniform(-3, 0))), res, (7, 9))
        P = random_map(rng, spec.shape)
        cell = (int(rng.integers(7)), int(rng.integers(9)))
        alpha, P_n, lam = rng.uniform(0.05, 0.3), rng.uniform(0.4, 0.95), rng.uniform(0.05, 0.5)
        beta0 = max(0.1, 1 - P_n)

        def beta_of(i, j, cell=cell, res=res, spec=spec, beta0=beta0, lam=lam, alpha=alpha):
            xi, yj = spec.origin_xy[0] + (i + 0.5) * res, spec.origin_xy[1] + (j + 0.5) * res
            xu, yv = spec.origin_xy[0] + (cell[0] + 0.5) * res, spec.origin_xy[1] + (cell[1] + 0.5) * res
            b = beta0 * math.exp(math.hypot(xi - xu, yj - yv) / lam)
            return None if b >= 1 - alpha else b  # capped at 1 - alpha: "another cell" of Eq. (2)

        fast = update_global(P, spec, cell, P_n, alpha, lam, beta_min=0.1)
        slow = brute_force_update(P, cell, 1, alpha, beta_of)
        np.testing.assert_allclose(fast, slow, rtol=1e-12, atol=1e-15)


def test_negative_detection_closed_form_and_mass_moves_to_the_others():
    """Not found in c_uv: P_uv' = beta P_uv / (beta P_uv + (1 - alpha)(1 - P_uv)); every other cell is
    scaled by the same factor > 1 (mass goes where it already was, as the paper's Fig. 6 shows)."""
    rng = np.random.default_rng(2)
    P = random_map(rng, (10, 12))
    cell = np.unravel_index(np.argmax(P), P.shape)
    alpha, beta = 0.05, 0.1
    Q = update(P, cell, 0, alpha, beta)
    expected = beta * P[cell] / (beta * P[cell] + (1 - alpha) * (1 - P[cell]))
    assert Q[cell] == pytest.approx(expected, rel=1e-12)
    assert Q[cell] < P[cell]
    others = np.ones(P.shape, bool)
    others[cell] = False
    ratio = Q[others] / P[others]
    assert np.all(ratio > 1.0)
    np.testing.assert_allclose(ratio, ratio[0], rtol=1e-12)
    assert Q.sum() == pytest.approx(1.0, abs=1e-12)
    # the mass gained by the others is exactly what the searched cell lost
    assert (Q[others] - P[others]).sum() == pytest.approx(P[cell] - Q[cell], rel=1e-9)


def test_repeated_misses_drive_a_cell_towards_zero_geometrically():
    P = uniform_prior(GridSpec((0, 0), 0.2, (5, 5)))
    alpha, beta = 0.05, 0.1
    odds = []
    for _ in range(6):
        P = update(P, (2, 2), 0, alpha, beta)
        odds.append(P[2, 2] / (1 - P[2, 2]))
    # the odds of the searched cell shrink by beta / (1 - alpha) per miss
    np.testing.assert_allclose(np.array(odds[1:]) / np.array(odds[:-1]), beta / (1 - alpha), rtol=1e-9)


def test_positive_detection_raises_the_cell_and_updates_commute():
    rng = np.random.default_rng(3)
    P = random_map(rng, (6, 6))
    Q = update(P, (1, 4), 1, 0.2, 0.1)
    assert Q[1, 4] > P[1, 4]
    a = update(update(P, (1, 4), 1, 0.2, 0.1), (3, 3), 0, 0.05, 0.1)
    b = update(update(P, (3, 3), 0, 0.05, 0.1), (1, 4), 1, 0.2, 0.1)
    np.testing.assert_allclose(a, b, rtol=1e-12)


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    alpha=st.floats(0.01, 0.45),
    beta=st.floats(0.01, 0.45),
    y=st.sampled_from([0, 1]),
    P_n=st.floats(0.0, 1.0),
    lam=st.floats(0.01, 2.0),
)
def test_properties_over_random_maps(seed, alpha, beta, y, P_n, lam):
    rng = np.random.default_rng(seed)
    spec = GridSpec((0.0, 0.0), 0.2, (int(rng.integers(1, 15)), int(rng.integers(1, 15))))
    P = random_map(rng, spec.shape)
    cell = (int(rng.integers(spec.shape[0])), int(rng.integers(spec.shape[1])))
    for Q in (update(P, cell, y, alpha, beta), update_global(P, spec, cell, P_n, alpha, lam)):
        assert np.all(np.isfinite(Q)) and np.all(Q >= 0)
        assert Q.sum() == pytest.approx(1.0, abs=1e-9)
    # the growing field: beta0 at the cell, never above 1 - alpha, non-decreasing with distance
    B = growing_beta_field(spec, cell, alpha, min(beta, 0.5 * (1 - alpha)), lam)
    assert B[cell] == pytest.approx(min(beta, 0.5 * (1 - alpha)))
    assert B.max() <= 1 - alpha + 1e-15
    X, Y = spec.cell_centers()
    d = np.hypot(X - X[cell], Y - Y[cell]).ravel()
    order = np.argsort(d, kind="stable")
    assert np.all(np.diff(B.ravel()[order]) >= -1e-15)


def test_growing_field_reaches_about_two_cells_for_a_strong_peak():
    """The defaults' reach, as the module docstring says: lambda ln((1 - alpha) / beta0)."""
    spec = GridSpec((0.0, 0.0), 0.2, (11, 11))
    B = growing_beta_field(spec, (5, 5), 0.2, 0.1, 0.2)
    L = detection_likelihood(1, B)
    assert L[5, 5] == pytest.approx(0.9)
    reach = 0.2 * math.log(0.8 / 0.1)  # 0.416 m
    X, Y = spec.cell_centers()
    d = np.hypot(X - X[5, 5], Y - Y[5, 5])
    assert np.all(L[d > reach + 1e-9] == pytest.approx(0.2))
    assert np.all(L[d < reach - 1e-9] > 0.2)
    assert L[7, 5] > 0.2 and L[8, 5] == pytest.approx(0.2)  # two cells out, not three


def test_weak_peak_changes_nothing_and_tiny_growth_is_eq2():
    spec = GridSpec((0.0, 0.0), 0.2, (4, 4))
    P = random_map(np.random.default_rng(4), spec.shape)
    np.testing.assert_array_equal(update_global(P, spec, (1, 1), 0.15, alpha=0.2, growth_m=0.2), P)
    # lambda -> 0: only the measured cell has beta0, every other cell is Eq. (2)'s 1 - alpha
    B = growing_beta_field(spec, (1, 1), 0.2, 0.3, 1e-6)
    np.testing.assert_allclose(B, constant_beta_field(spec.shape, (1, 1), 0.2, 0.3))
    np.testing.assert_allclose(
        update_global(P, spec, (1, 1), 0.7, 0.2, 1e-6, beta_min=0.0), update(P, (1, 1), 1, 0.2, 0.3)
    )


def test_bayes_update_is_eq1_over_eq3():
    P = np.array([[0.5, 0.25], [0.125, 0.125]])
    L = np.array([[0.1, 0.9], [0.9, 0.9]])
    evidence = 0.1 * 0.5 + 0.9 * 0.5
    np.testing.assert_allclose(bayes_update(P, L), L * P / evidence)


def test_region_prior_and_map_class():
    spec = GridSpec((-1.0, -1.0), 0.5, (4, 4))  # centres at -0.75, -0.25, 0.25, 0.75
    P0 = region_prior(spec, [((0.0, 0.0, 1.0, 1.0), 4.0)], background=1.0)
    assert P0.sum() == pytest.approx(1.0)
    assert P0[3, 3] / P0[0, 0] == pytest.approx(4.0)
    m = ProbabilityMap(spec, P0)
    assert m.peak() in {(2, 2), (2, 3), (3, 2), (3, 3)}
    assert m.peak(near_xy=(0.8, 0.8)) == (3, 3)
    ex = np.zeros(spec.shape, bool)
    ex[2:, 2:] = True
    assert m.peak(exclude=ex, near_xy=(-1, -1)) == (0, 0)
    assert m.peak(exclude=np.ones(spec.shape, bool)) is None
    m.observe(LocalSearchDetection((3, 3), 0, DetectionModel(0.05, 0.1)))
    assert m.P.sum() == pytest.approx(1.0) and m.P[3, 3] < P0[3, 3]
    assert ProbabilityMap.over(-3, -4, 3, 4).spec.shape == (30, 40)


def test_bad_inputs_raise_config_errors():
    spec = GridSpec((0.0, 0.0), 0.2, (3, 3))
    P = uniform_prior(spec)
    with pytest.raises(ConfigError, match="alpha \\+ beta"):
        update(P, (0, 0), 0, 0.6, 0.5)
    with pytest.raises(ConfigError, match="outside the map"):
        update(P, (3, 0), 0, 0.05, 0.1)
    with pytest.raises(ConfigError, match="0 or 1"):
        detection_likelihood(2, P)
    with pytest.raises(ConfigError):
        DetectionModel(0.0, 0.1)
    with pytest.raises(ConfigError, match="growth_m"):
        growing_beta_field(spec, (0, 0), 0.2, 0.1, 0.0)
    with pytest.raises(ConfigError):
        ProbabilityMap(spec, -P)


def test_map_peaks_are_local_maxima_in_order():
    P = np.full((8, 8), 1.0)
    P[1, 1], P[5, 6], P[6, 2] = 5.0, 9.0, 3.0
    P[5, 5] = 4.0  # a shoulder of the (5, 6) peak, not a peak itself
    P[2, 6] = P[2, 7] = 2.0  # a plateau of two cells: one peak
    assert map_peaks(P) == [(5, 6), (1, 1), (6, 2), (2, 6)]
    assert map_peaks(P, 2) == [(5, 6), (1, 1)]
    assert map_peaks(np.ones((3, 3))) == []  # a flat map has no peak


def test_observe_applies_either_searchs_detection_as_the_update_functions_do():
    """A colour peak's detection is :func:`update_global` with the model's alpha, growth and beta floor;
    a local search's is :func:`update` of the cell and then each neighbour within the model's radius."""
    spec = GridSpec.from_bounds(0, 0, 2.0, 1.6, 0.2)
    rng = np.random.default_rng(3)
    P0 = rng.uniform(0.5, 1.5, spec.shape)
    pmap = ProbabilityMap(spec, P0)
    P = pmap.P.copy()
    colour = DetectionModel(alpha=0.05, beta=0.1, growth_m=0.2)
    pmap.observe(ColourPeakDetection((3, 4), 0.8, colour))
    P = update_global(P, spec, (3, 4), 0.8, 0.05, 0.2, 0.1)
    np.testing.assert_array_equal(pmap.P, P)
    local = DetectionModel(alpha=0.05, beta=0.1, neighbour_radius_m=0.45)
    miss = LocalSearchDetection((5, 2), 0, local)
    cells = miss.cells(spec)
    assert cells[0] == (5, 2) and len(cells) == len(set(cells)) == 21  # the cell and 20 within 0.45 m
    pmap.observe(miss)
    for c in cells:
        P = update(P, c, 0, 0.05, 0.1)
    np.testing.assert_array_equal(pmap.P, P)
    assert cells_within(spec, (0, 0), 0.0) == [(0, 0)]
    with pytest.raises(ConfigError, match="neighbour_radius_m"):
        DetectionModel(0.05, 0.1, neighbour_radius_m=-1.0)
