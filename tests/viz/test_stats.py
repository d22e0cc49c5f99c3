"""Across-seed statistics: known numbers and scipy's own t interval as the oracle."""

import numpy as np
import pytest
from scipy import stats

from solar_jax.viz.stats import common_grid, mean_ci, on_grid


def test_mean_ci_of_known_numbers():
    values = np.array([[1.0, 10.0], [2.0, 10.0], [3.0, 10.0], [4.0, 10.0]])  # [seeds, T]
    mean, low, high = mean_ci(values)
    half = 3.182446 * 1.290994 / 2  # t_{0.975, 3} * s / sqrt(4)
    np.testing.assert_allclose(mean, [2.5, 10.0])
    np.testing.assert_allclose(high - mean, [half, 0.0], rtol=1e-6)
    np.testing.assert_allclose(mean - low, [half, 0.0], rtol=1e-6)
    assert half == pytest.approx(2.0543, abs=1e-4)


@pytest.mark.parametrize("level", [0.9, 0.95, 0.99])
def test_mean_ci_matches_scipy_t_interval(level):
    values = np.random.default_rng(0).normal(size=(5, 7))
    _, low, high = mean_ci(values, level)
    ref_low, ref_high = stats.t.interval(
        level, 4, loc=values.mean(axis=0), scale=stats.sem(values, axis=0)
    )
    np.testing.assert_allclose(low, ref_low)
    np.testing.assert_allclose(high, ref_high)


def test_one_seed_has_no_band():
    mean, low, high = mean_ci(np.array([[1.0, 2.0, 3.0]]))
    np.testing.assert_array_equal(mean, [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(low, mean)
    np.testing.assert_array_equal(high, mean)


def test_runs_are_interpolated_onto_a_common_grid():
    first = (np.array([0.0, 10.0, 20.0, 30.0]), np.array([0.0, 10.0, 20.0, 30.0]))  # y = x
    second = (np.array([0.0, 12.0, 25.0]), np.array([0.0, 24.0, 50.0]))  # y = 2x
    grid, values = on_grid([first, second])
    # 0 to the shorter run's end (25) at the logged spacing (median gap 10): 3 points.
    np.testing.assert_allclose(grid, [0.0, 12.5, 25.0])
    np.testing.assert_allclose(values, [[0.0, 12.5, 25.0], [0.0, 25.0, 50.0]])


def test_grid_starts_where_every_run_has_data_and_is_capped():
    steps = [np.arange(47, 10_000, 50.0), np.arange(60, 9_000, 45.0)]
    grid = common_grid(steps, max_points=100)
    assert grid[0] == 60 and grid[-1] == steps[1][-1] and len(grid) == 100
    assert common_grid([np.array([0.0])]).tolist() == [0.0]  # only the first evaluation
