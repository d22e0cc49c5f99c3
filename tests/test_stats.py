"""``solar_jax.stats``: the interval of a difference between two sets of seeds."""

import numpy as np
import pytest
from scipy import stats

from solar_jax.stats import welch_interval


def test_welch_interval_equals_scipys():
    rng = np.random.default_rng(0)
    a, b = rng.normal(500, 200, 14), rng.normal(450, 350, 9)
    expected = stats.ttest_ind(a, b, equal_var=False).confidence_interval(0.90)
    np.testing.assert_allclose(welch_interval(a, b), expected, rtol=1e-12)


def test_welch_interval_of_constant_seeds_is_the_difference():
    assert welch_interval([3.0, 3.0], [1.0, 1.0]) == (2.0, 2.0)


def test_welch_interval_needs_two_seeds_a_side():
    with pytest.raises(ValueError, match="at least two seeds on each side, got 1 and 3"):
        welch_interval([1.0], [1.0, 2.0, 3.0])
