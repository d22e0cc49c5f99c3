"""ΔQ preference (algorithm.md §3) against a per-agent Python loop."""

import jax
import jax.numpy as jnp
import numpy as np

from solar_jax.synergy import (
    PREFERENCE_SCALE,
    delta_q,
    delta_q_preference,
    preference_from_delta_q,
)

B, N_MAX, F = 32, 9, 19


def _critic(params):
    """A small nonlinear stand-in critic: q(obs [B, N, F], act [B, N]) -> [B]."""
    w_obs, w_act, w_out = params

    def q(obs, act):
        h = jnp.tanh(obs @ w_obs + act[..., None] * w_act)  # [B, N, H]
        return jnp.sum(h @ w_out, axis=(-1, -2)) + jnp.sum(act**2, axis=-1)

    return q


def _problem(seed=0, n=7):
    rng = np.random.default_rng(seed)
    params = (
        rng.normal(size=(F, 16)).astype(np.float32),
        rng.normal(size=(16,)).astype(np.float32),
        rng.normal(size=(16, 1)).astype(np.float32),
    )
    obs = rng.normal(size=(B, N_MAX, F)).astype(np.float32)
    act = rng.uniform(-1, 1, size=(B, N_MAX)).astype(np.float32)
    return _critic(params), obs, act, np.arange(N_MAX) < n


def test_delta_q_equals_a_loop_over_agents():
    q, obs, act, mask = _problem()
    dq = np.asarray(jax.jit(delta_q, static_argnums=0)(q, obs, act, mask))
    base = np.asarray(q(obs, act))
    for i in range(N_MAX):
        zeroed = act.copy()
        zeroed[:, i] = 0
        expected = np.mean(base - np.asarray(q(obs, zeroed))) if mask[i] else 0.0
        np.testing.assert_allclose(dq[i], expected, rtol=1e-5, atol=1e-5)
    assert (dq[~mask] == 0).all()


def test_preference_is_scaled_softmax_over_real_agents():
    dq = np.array([0.3, -1.0, 2.0, 0.0, 0.5, 9.0, -9.0], np.float32)
    mask = np.array([True] * 5 + [False] * 2)
    pref = np.asarray(preference_from_delta_q(dq, mask))
    e = np.exp(dq[:5] - dq[:5].max())
    np.testing.assert_allclose(pref[:5], 1.2 * e / e.sum(), rtol=1e-6)
    assert (pref[5:] == 0).all()
    np.testing.assert_allclose(pref.sum(), PREFERENCE_SCALE, rtol=1e-6)
    # Equal ΔQ gives the uniform preference of algorithm.md §3, 1.2 / N.
    np.testing.assert_allclose(preference_from_delta_q(np.zeros(7), mask)[:5], 1.2 / 5)


def test_padded_actions_do_not_matter():
    """The critic masks padded agents itself; ΔQ of a padded agent is reported as 0."""
    q, obs, act, mask = _problem()
    a = delta_q_preference(q, obs, act, mask)
    assert np.isfinite(np.asarray(a)).all() and (np.asarray(a)[~mask] == 0).all()


def test_vectorised_not_looped_and_vmappable_over_morphologies():
    q, obs, act, _ = _problem()
    calls = []

    def counting_q(o, a):
        calls.append(1)
        return q(o, a)

    masks = np.stack([np.arange(N_MAX) < n for n in (3, 5, 9)])
    batched = jax.jit(jax.vmap(lambda m: delta_q_preference(counting_q, obs, act, m)))(masks)
    assert len(calls) == 1  # one pass: Q(s, a) and every ablation in one batch
    for b, m in enumerate(masks):
        np.testing.assert_allclose(
            batched[b], delta_q_preference(q, obs, act, m), rtol=1e-5, atol=1e-7
        )
