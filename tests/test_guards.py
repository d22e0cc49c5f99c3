"""The test guards catch what they are for (``tests/guards.py``)."""

import jax
import jax.numpy as jnp
import pytest

from tests.guards import check_keys_used_once, key_reuse_checked, no_retracing


def test_no_retracing_fails_on_a_new_shape_or_static_value_only():
    @jax.jit
    def double(x):
        return 2 * x

    scale = jax.jit(lambda x, k: k * x, static_argnums=1)
    double(jnp.ones(3))
    scale(jnp.ones(3), 2)
    with no_retracing("the same calls"):
        double(jnp.zeros(3))
        scale(jnp.zeros(3), 2)
    with pytest.raises(AssertionError, match="double"):
        with no_retracing("a new shape"):
            double(jnp.ones(4))
    with pytest.raises(AssertionError, match="traced again"):
        with no_retracing("a new static value"):
            scale(jnp.ones(3), 3)


def test_key_reuse_is_an_error_inside_the_guard():
    def twice(key):
        return jax.random.normal(key) + jax.random.normal(key)

    twice(jax.random.key(0))  # unchecked outside the guard
    with key_reuse_checked(), pytest.raises(jax.errors.KeyReuseError):
        jax.jit(twice)(jax.random.key(1))
    with key_reuse_checked():  # one use per key passes
        jax.jit(lambda k: jax.random.normal(k, (2,)))(jax.random.key(2))


def test_a_reused_key_is_found_by_tracing_alone():
    def twice(key):
        return jax.random.normal(key) + jax.random.normal(key)

    def split(key):
        a, b = jax.random.split(key)
        return jax.random.normal(a) + jax.random.normal(b)

    with pytest.raises(jax.errors.KeyReuseError):
        check_keys_used_once(twice, jax.random.key(0))
    check_keys_used_once(split, jax.random.key(0))
