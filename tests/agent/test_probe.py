"""Probe tasks with known optima, learned by the real TD3 update and tiny SOLAR networks
(one layer).

- One step (a contextual bandit with one state): reward -Σ (a_i - c_i)² over the
  actuated agents, then the episode terminates. Q* = reward, π* = c.
- Two steps: s0 -> s1 with reward 0, then s1 -> end with reward 1. Q*(s0) = γ,
  Q*(s1) = 1, whatever the actions: the bootstrap and the terminal mask.
The data are uniform random actions, as in the warm-up (the torso's too: the actor acts
for it, algorithm.md §2, though no reward reads it).
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np

from solar_jax.agent import Hyper, make_td3
from solar_jax.config import NetworkConfig, TD3Config
from solar_jax.networks import Structure, make_networks
from solar_jax.replay import Batch
from tests import unoptimised
from tests.networks.inputs import robot

N_MAX = 4
SIZE = 1000
TARGET = np.array([0.0, 0.5, -0.3, 0.0], np.float32)  # torso, two motors, padding
ACTUATED = np.array([False, True, True, False])
TD3 = TD3Config(lr=1e-3)
ITERATIONS = 1500


@functools.cache
def _setup():
    nets = make_networks("solar", NetworkConfig.tiny(num_layers=1), n_max=N_MAX)  # compiles faster
    td3 = make_td3(nets, TD3)
    obs, _, mask, synergy, traversal = robot("hopper_3", N_MAX, batch=2)
    structure = Structure(agent_mask=mask, synergy=synergy, traversal=traversal)

    @functools.partial(jax.jit, static_argnums=3)
    def learn(state, data, key, iterations):
        def body(i, carry):
            state, key = carry
            key, sample_key, noise_key = jax.random.split(key, 3)
            index = jax.random.randint(sample_key, (TD3.batch_size,), 0, SIZE)
            batch = jax.tree.map(lambda x: x[index], data)
            state, _ = td3.update(state, batch, structure, i, noise_key, Hyper.from_config(TD3))
            return state, key

        return jax.lax.fori_loop(0, iterations, body, (state, key))[0]

    @jax.jit
    def values(state, obs, action):
        """(deterministic actions [B, N], twin Q [2, B]) of a few states."""
        act = nets.act(state.actor, obs, mask, synergy, traversal)
        return act, nets.q(state.critic, obs, action, mask, synergy)

    return td3, obs, learn, values


def _random_actions(rng, size=SIZE):
    actions = rng.uniform(-1, 1, (size, N_MAX)).astype(np.float32)
    return actions * np.array([1, 1, 1, 0], np.float32)


def _learn(data, seed):
    td3, _, learn, _ = _setup()
    state = unoptimised.jit(td3.init)(jax.random.PRNGKey(0))
    return learn(state, data, jax.random.PRNGKey(seed), ITERATIONS)


def test_one_step_probe_learns_the_optimal_action_and_value():
    _, obs, _, values = _setup()
    rng = np.random.default_rng(0)
    action = _random_actions(rng)
    s = np.broadcast_to(obs[0], (SIZE, *obs.shape[1:]))
    data = Batch(
        obs=s,
        action=action,
        reward=-np.sum(((action - TARGET) ** 2)[:, ACTUATED], axis=1),
        next_obs=s,
        terminated=np.ones(SIZE, bool),
    )
    state = _learn(data, seed=1)
    two = jnp.stack([obs[0], obs[0]])  # the one state, with the optimum and a zero action
    act, q = values(state, two, jnp.stack([jnp.asarray(TARGET), jnp.zeros(N_MAX)]))
    print("one-step probe: action", act[0], "Q(optimum), Q(0)", q)
    # The torso's action is free (no reward reads it); the motors' optimum is TARGET.
    np.testing.assert_allclose(act[0][ACTUATED], TARGET[ACTUATED], atol=0.1)
    np.testing.assert_allclose(q[:, 0], 0.0, atol=0.1)  # the optimum's value
    np.testing.assert_allclose(q[:, 1], -np.sum(TARGET**2), atol=0.1)


def test_two_step_probe_learns_the_discounted_value():
    _, obs, _, values = _setup()
    rng = np.random.default_rng(1)
    first = rng.random(SIZE) < 0.5  # half the transitions leave s0, half leave s1
    s0, s1 = np.asarray(obs[0]), np.asarray(obs[1])
    data = Batch(
        obs=np.where(first[:, None, None], s0, s1),
        action=_random_actions(rng),
        reward=np.where(first, 0.0, 1.0).astype(np.float32),
        next_obs=np.where(first[:, None, None], s1, s0),  # after s1: ignored (terminal)
        terminated=~first,
    )
    state = _learn(data, seed=2)
    _, q = values(state, jnp.stack([s0, s1]), jnp.asarray(_random_actions(rng, 2)))
    print("two-step probe: Q(s0), Q(s1)", q)
    np.testing.assert_allclose(q[:, 0], 0.99, atol=0.05)
    np.testing.assert_allclose(q[:, 1], 1.0, atol=0.05)
