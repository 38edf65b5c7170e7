"""The probability map's prediction step (lab/search/motion.py) on hand-made maps, against peers:
scipy.ndimage for the open-grid convolution, the random walk's variance, and the speed bound; with
surface labels (Eq. (P2)), mass stays on its surface (a table's top) and spreads over it."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import ndimage

from lab.errors import ConfigError
from lab.navigation.costmap import CellState
from lab.navigation.grid import GridSpec
from lab.search.motion import (
    FLOOR,
    RAISED,
    MotionModel,
    diffuse_step,
    diffusion_coefficient,
    passable_from_costmap,
    predict,
    surfaces_from_costmap,
)
from lab.search.probability_map import DetectionModel, LocalSearchDetection, ProbabilityMap

R = 0.2  # cell side [m]


def point_mass(shape=(41, 41), cell=(20, 20)) -> np.ndarray:
    P = np.zeros(shape)
    P[cell] = 1.0
    return P


def test_open_grid_step_is_the_5_point_convolution():
    q = 0.2
    kernel = np.array([[0, q, 0], [q, 1 - 4 * q, q], [0, q, 0]])
    rng = np.random.default_rng(3)
    P = np.zeros((30, 30))
    P[8:22, 8:22] = rng.random((14, 14))  # away from the edges: no reflection
    P /= P.sum()
    ours = diffuse_step(P, np.ones(P.shape, bool), q)
    np.testing.assert_allclose(ours, ndimage.convolve(P, kernel, mode="constant"), atol=1e-15)


def test_point_mass_spreads_as_the_diffusion_of_the_speed_bound():
    model = MotionModel(speed_mps=0.1)
    dt = 30.0  # 15 cells at 0.1 m/s: far from the edges of a 41 x 41 grid
    P = predict(point_mass(), np.ones((41, 41), bool), dt, model, R)
    i = (np.arange(41) - 20) * R
    var_x = float((P.sum(axis=1) * i**2).sum())
    var_y = float((P.sum(axis=0) * i**2).sum())
    expected = 2 * diffusion_coefficient(model, R) * dt  # sigma^2 = 2 D dt per axis
    assert var_x == pytest.approx(expected, rel=1e-9)
    assert var_y == pytest.approx(expected, rel=1e-9)
    # and the central limit: close to a Gaussian of that variance (scipy's sampled Gaussian filter)
    gauss = ndimage.gaussian_filter(point_mass(), sigma=math.sqrt(expected) / R, mode="constant", truncate=6)
    assert np.abs(P - gauss).sum() < 0.03


def test_the_spread_does_not_depend_on_how_time_is_cut():
    model = MotionModel(speed_mps=0.13)
    passable = np.ones((41, 41), bool)
    once = predict(point_mass(), passable, 12.0, model, R)
    P = point_mass()
    for _ in range(12):
        P = predict(P, passable, 1.0, model, R)
    i = (np.arange(41) - 20) * R
    for Q in (once, P):
        assert float((Q.sum(axis=1) * i**2).sum()) == pytest.approx(
            2 * diffusion_coefficient(model, R) * 12.0
        )


@given(speed=st.floats(0.01, 0.5), dt=st.floats(0.1, 20.0))
@settings(max_examples=40, deadline=None)
def test_mass_moves_no_farther_than_the_speed_bound(speed, dt):
    P = predict(point_mass(), np.ones((41, 41), bool), dt, MotionModel(speed_mps=speed), R)
    reach = math.ceil(speed * dt / R)  # cells of 4-neighbour steps
    ii, jj = np.nonzero(P > 0)
    assert np.all(np.abs(ii - 20) + np.abs(jj - 20) <= reach)
    assert P.sum() == pytest.approx(1.0, abs=1e-12)
    assert np.all(P >= 0)


def wall_map():
    """A 20 x 20 room split by a wall along i = 10 with no gap, and a block of obstacle cells."""
    passable = np.ones((20, 20), bool)
    passable[10, :] = False
    passable[3:5, 14:17] = False
    return passable


@given(seed=st.integers(0, 2**31 - 1), dt=st.floats(0.5, 60.0))
@settings(max_examples=30, deadline=None)
def test_mass_is_conserved_and_never_enters_obstacles_or_crosses_walls(seed, dt):
    passable = wall_map()
    rng = np.random.default_rng(seed)
    P = rng.random((20, 20)) * passable
    P[11:, :] = 0.0  # everything on the low side of the wall
    P /= P.sum()
    out = predict(P, passable, dt, MotionModel(speed_mps=0.3), R)
    assert out.sum() == pytest.approx(1.0, abs=1e-12)
    assert np.all(out >= 0)
    assert np.all(out[~passable] == 0.0)  # no mass flowed into an obstacle
    assert np.all(out[11:, :] == 0.0)  # none crossed the wall
    assert out[:10, :].sum() == pytest.approx(1.0, abs=1e-12)


def test_a_blocked_cell_keeps_what_it_holds():
    passable = wall_map()
    P = np.full((20, 20), 1.0 / 400)
    out = predict(P, passable, 10.0, MotionModel(speed_mps=0.3), R)
    np.testing.assert_array_equal(out[~passable], P[~passable])


def test_speed_zero_or_no_time_is_bit_for_bit_the_static_map():
    P = np.random.default_rng(1).random((15, 12))
    P /= P.sum()
    passable = np.ones(P.shape, bool)
    assert predict(P, passable, 10.0, MotionModel(speed_mps=0.0), R) is P
    assert predict(P, passable, 0.0, MotionModel(speed_mps=0.2), R) is P


def test_mass_flows_back_into_a_missed_cell():
    spec = GridSpec((0.0, 0.0), R, (15, 15))
    pmap = ProbabilityMap(spec)
    cell = (7, 7)
    pmap.observe(LocalSearchDetection(cell, 0, DetectionModel(alpha=0.05, beta=0.1, neighbour_radius_m=0.2)))
    after_miss = pmap.P[cell]
    assert after_miss < 1.0 / spec.n_cells / 5  # the miss lowered the cell it covered
    passable = np.ones(spec.shape, bool)
    model = MotionModel(speed_mps=0.05)
    values = [after_miss]
    P = pmap.P
    for _ in range(6):
        P = predict(P, passable, 10.0, model, R)
        values.append(P[cell])
    assert all(b > a for a, b in zip(values, values[1:], strict=False))  # mass flows back, monotonically here
    assert values[-1] < 1.0 / spec.n_cells  # but not beyond the uniform level it left
    assert values[-1] > 0.5 / spec.n_cells


def test_passable_from_the_robots_costmap_not_the_truth():
    costmap = GridSpec((0.0, 0.0), 0.1, (8, 6))
    pmap = GridSpec((0.0, 0.0), 0.2, (4, 3))
    state = np.full(costmap.shape, CellState.UNKNOWN, dtype=np.int8)
    state[0:2, 0:2] = CellState.OBSTACLE  # all four costmap cells of map cell (0, 0)
    state[2, 2] = CellState.OBSTACLE  # one of four of map cell (1, 1): a quarter, passes at 0.5
    state[4:6, 2:4] = CellState.FREE
    state[6:8, 4] = CellState.OBSTACLE  # half of map cell (3, 2)
    passable = passable_from_costmap(state, costmap, pmap)
    expected = np.ones(pmap.shape, bool)
    expected[0, 0] = False
    expected[3, 2] = False
    np.testing.assert_array_equal(passable, expected)
    assert passable_from_costmap(state, costmap, pmap, blocked_share=0.25)[1, 1] == np.False_


def test_bad_inputs_are_one_clear_error():
    with pytest.raises(ConfigError, match="speed_mps"):
        MotionModel(speed_mps=-0.1)
    with pytest.raises(ConfigError, match="q_max"):
        MotionModel(speed_mps=0.1, q_max=0.3)
    with pytest.raises(ConfigError, match="dt_s"):
        predict(point_mass(), np.ones((41, 41), bool), -1.0, MotionModel(0.1), R)
    with pytest.raises(ConfigError, match="shape"):
        predict(point_mass(), np.ones((4, 4), bool), 1.0, MotionModel(0.1), R)


def test_the_map_method_is_the_function():
    spec = GridSpec((0.0, 0.0), R, (15, 15))
    pmap = ProbabilityMap(spec, point_mass((15, 15), (7, 7)))
    passable = wall_map()[:15, :15]
    pmap.predict(8.0, passable, MotionModel(speed_mps=0.1))
    np.testing.assert_array_equal(
        pmap.P, predict(point_mass((15, 15), (7, 7)), passable, 8.0, MotionModel(0.1), R)
    )


def table_room():
    """A 20 x 20 floor with a 6 x 3 table (the raised cells the costmap saw) and a wall cell of 0."""
    s = np.full((20, 20), FLOOR, dtype=np.int8)
    s[5:11, 8:11] = RAISED
    s[15, 15] = 0
    return s


def test_a_mask_is_the_surfaces_1_and_0_bit_for_bit():
    P = np.random.default_rng(5).random((20, 20))
    P /= P.sum()
    mask = wall_map()
    a = predict(P, mask, 17.0, MotionModel(0.2), R)
    b = predict(P, mask.astype(np.int8), 17.0, MotionModel(0.2), R)
    np.testing.assert_array_equal(a, b)


@given(seed=st.integers(0, 2**31 - 1), dt=st.floats(0.5, 60.0))
@settings(max_examples=30, deadline=None)
def test_each_surface_keeps_its_mass_and_a_label_0_cell_its_own(seed, dt):
    rng = np.random.default_rng(seed)
    labels = rng.integers(0, 3, (12, 12))  # any layout of surfaces and blocked cells
    P = rng.random((12, 12))
    P /= P.sum()
    out = predict(P, labels, dt, MotionModel(speed_mps=0.3), R)
    assert np.all(out >= 0)
    for k in (1, 2):
        assert out[labels == k].sum() == pytest.approx(P[labels == k].sum(), abs=1e-12)
    np.testing.assert_array_equal(out[labels == 0], P[labels == 0])


def test_a_table_tops_mass_spreads_over_the_top_and_stays_on_it():
    """A point mass on the table's top (raised cells): it never reaches the floor, and over a long time
    it spreads to the uniform distribution over the top (the random walk's stationary one on a
    connected region it cannot leave); with the passable mask of (P1) it stayed frozen in its cell."""
    surfaces = table_room()
    table = surfaces == RAISED
    P = point_mass((20, 20), (6, 9))
    model = MotionModel(speed_mps=0.1)
    soon = predict(P, surfaces, 4.0, model, R)
    assert soon[~table].sum() == 0.0 and soon.sum() == pytest.approx(1.0, abs=1e-12)
    assert soon[6, 9] < 1.0 and soon[7, 9] > 0  # it moved over the top
    late = predict(P, surfaces, 2000.0, model, R)
    np.testing.assert_allclose(late[table], 1.0 / table.sum(), rtol=1e-6)
    frozen = predict(P, surfaces == FLOOR, 2000.0, model, R)
    np.testing.assert_array_equal(frozen, P)


def test_a_miss_on_the_top_fills_in_from_the_top_not_from_the_floor():
    surfaces = table_room()
    table = surfaces == RAISED
    spec = GridSpec((0.0, 0.0), R, (20, 20))
    pmap = ProbabilityMap(spec)
    pmap.observe(
        LocalSearchDetection((7, 9), 0, DetectionModel(alpha=0.05, beta=0.1, neighbour_radius_m=0.0))
    )
    before = pmap.P.copy()
    after = predict(before, surfaces, 10.0, MotionModel(speed_mps=0.05), R)
    assert after[7, 9] > before[7, 9]  # mass flowed back into the missed cell
    assert after[table].sum() == pytest.approx(before[table].sum(), abs=1e-15)  # from the top only


def test_surfaces_are_the_costmaps_passable_cells_and_its_raised_ones():
    costmap = GridSpec((0.0, 0.0), 0.1, (8, 6))
    pmap = GridSpec((0.0, 0.0), 0.2, (4, 3))
    state = np.full(costmap.shape, CellState.FREE, dtype=np.int8)
    state[0:4, 0:2] = CellState.OBSTACLE  # map cells (0, 0) and (1, 0): a table's top, seen
    state[6:8, 4:6] = CellState.UNKNOWN
    got = surfaces_from_costmap(state, costmap, pmap)
    expected = np.full(pmap.shape, FLOOR)
    expected[0:2, 0] = RAISED
    np.testing.assert_array_equal(got, expected)
    np.testing.assert_array_equal(got == FLOOR, passable_from_costmap(state, costmap, pmap))
