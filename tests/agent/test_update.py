"""One TD3 iteration (algorithm.md §5): what steps on which iteration, and the targets."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from solar_jax.agent import Hyper, make_td3
from solar_jax.agent.state import flat, split_actor
from solar_jax.config import NetworkConfig, TD3Config
from solar_jax.networks import GATE, TRANSFORM, Structure, make_networks
from solar_jax.replay import Batch
from tests import unoptimised
from tests.guards import check_keys_used_once
from tests.networks.inputs import robot

N_MAX = 4


@functools.cache
def _setup(method: str = "solar", gate_group: str = "actor"):
    # One layer: which parameters step when does not depend on depth (compiles faster).
    nets = make_networks(method, NetworkConfig.tiny(num_layers=1), n_max=N_MAX)
    td3 = make_td3(nets, TD3Config(gate_group=gate_group))
    obs, action, mask, synergy, traversal = robot("hopper_3", N_MAX, batch=4)
    next_obs = robot("hopper_3", N_MAX, batch=4, seed=1)[0]
    batch = Batch(obs, action, jnp.arange(4.0), next_obs, jnp.array([False, True, False, False]))
    structure = Structure(agent_mask=mask, synergy=synergy, traversal=traversal)
    state = unoptimised.jit(td3.init)(jax.random.PRNGKey(0))  # eager Flax init is 2x slower
    return td3, state, batch, structure, unoptimised.jit(td3.update)


def _changed(a, b) -> bool:
    return any(
        not np.array_equal(x, y)
        for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True)
    )


def _step(iteration: int, tau: float = 0.046, method: str = "solar", gate_group: str = "actor"):
    _, before, batch, structure, update = _setup(method, gate_group)
    hyper = Hyper.from_config(TD3Config(tau=tau))
    after, metrics = update(
        before, batch, structure, jnp.int32(iteration), jax.random.PRNGKey(1), hyper
    )
    return before, after, metrics


@pytest.mark.parametrize("iteration", [0, 1, 2, 3, 4, 6])
def test_actor_and_transform_step_only_on_their_iterations(iteration):
    before, after, metrics = _step(iteration)
    actor_iteration = iteration % 2 == 0
    assert _changed(before.critic, after.critic)  # every iteration
    # The gate belongs to the actor (algorithm.md §4): it steps with the trunk.
    for group in ("trunk", GATE):
        assert _changed(before.actor[group], after.actor[group]) == actor_iteration
    assert _changed(before.actor[TRANSFORM], after.actor[TRANSFORM]) == (iteration % 4 == 0)
    assert _changed(before.target_critic, after.target_critic) == actor_iteration
    assert _changed(before.target_actor, after.target_actor) == actor_iteration
    assert bool(metrics["actor_step"]) == actor_iteration
    # Adam's step counts: the critic's always, the actor's and synergy's on their turns.
    count = lambda opt: int(opt[1].inner_state[0].count)  # noqa: E731
    assert count(after.critic_opt) == 1
    assert count(after.actor_opt) == int(actor_iteration)
    assert count(after.synergy_opt) == int(iteration % 4 == 0)


def test_targets_copy_the_online_networks_at_tau_one():
    _, after, _ = _step(0, tau=1.0)
    policy, _ = split_actor(after.actor, TD3Config())
    assert set(after.target_actor) == {"trunk", GATE}  # the gate has a target copy
    assert TRANSFORM not in after.target_actor  # the synergy module has none
    for online, target in [(policy, after.target_actor), (after.critic, after.target_critic)]:
        jax.tree.map(np.testing.assert_array_equal, online, target)


def test_the_td_target_uses_the_target_gate():
    # The critic loss reads the target actor's gate: perturbing it moves the loss, while
    # the online gate does not enter the TD target (it enters only the actor loss).
    td3, state, batch, structure, _ = _setup()
    hyper = Hyper.from_config(TD3Config())
    key = jax.random.PRNGKey(1)

    @jax.jit  # one program for the three losses (eagerly, each op compiles apart)
    def critic_loss(agent):
        _, synergy = split_actor(agent.actor, TD3Config())
        target_actor = {**agent.target_actor, **synergy}
        return td3.losses.critic(
            agent.critic, target_actor, agent.target_critic, batch, structure, key, hyper
        )[0]

    def bump(tree):
        return jax.tree.map(lambda x: x + 0.5, tree)

    base = critic_loss(state)
    moved_target = state.replace(
        target_actor={**state.target_actor, GATE: bump(state.target_actor[GATE])}
    )
    moved_online = state.replace(actor={**state.actor, GATE: bump(state.actor[GATE])})
    assert critic_loss(moved_target) != base
    assert critic_loss(moved_online) == base


def test_gate_group_switch_puts_the_gate_with_the_synergy_module():
    # td3.gate_group=synergy (this project before): the gate steps every 4th iteration
    # with the synergy module, and has no target copy.
    for iteration in (2, 4):
        before, after, _ = _step(iteration, gate_group="synergy")
        assert _changed(before.actor[GATE], after.actor[GATE]) == (iteration % 4 == 0)
        assert _changed(before.actor["trunk"], after.actor["trunk"])
        assert set(after.target_actor) == {"trunk"}


def test_targets_move_by_tau():
    before, after, _ = _step(0, tau=0.25)
    expected = jax.tree.map(lambda o, t: 0.25 * o + 0.75 * t, after.critic, before.target_critic)
    jax.tree.map(
        lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-7),
        after.target_critic,
        expected,
    )


@pytest.mark.parametrize("iteration", [0, 1])  # a critic-only and an actor iteration
def test_an_update_consumes_each_key_once(iteration):
    td3, before, batch, structure, _ = _setup()
    hyper = Hyper.from_config(TD3Config())

    def step(key):  # traced inside the checker's jit: the update itself, not a jitted one
        return td3.update(before, batch, structure, jnp.int32(iteration), key, hyper)

    check_keys_used_once(step, jax.random.key(1))


def test_the_flat_optimiser_steps_as_on_the_tree_and_takes_an_empty_group():
    # Adam with the reference's global-norm clip (0.1: every step here is clipped), on a
    # tree of odd shapes and on its flat vector: the same steps up to the rounding of the
    # norm's sum; the flat states hold one vector per moment.
    def adam():
        return optax.chain(optax.clip_by_global_norm(0.1), optax.adam(1e-2))

    rng = np.random.default_rng(0)
    params = {"b": jnp.ones(3), "a": {"w": jnp.ones((2, 5)), "s": jnp.ones(())}}
    tree_params, flat_params = params, params
    tree_state, flat_state = adam().init(params), flat(adam()).init(params)
    moments = flat_state[1][0]  # chain(clip, adam): adam is chain(scale_by_adam, lr)
    assert [m.shape for m in (moments.mu, moments.nu)] == [(14,), (14,)]
    for _ in range(3):
        grads = jax.tree.map(lambda x: jnp.asarray(rng.normal(size=x.shape), jnp.float32), params)
        step, tree_state = adam().update(grads, tree_state, tree_params)
        tree_params = optax.apply_updates(tree_params, step)
        step, flat_state = flat(adam()).update(grads, flat_state, flat_params)
        assert jax.tree.structure(step) == jax.tree.structure(params)
        flat_params = optax.apply_updates(flat_params, step)
    jax.tree.map(lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-6), flat_params, tree_params)
    assert _changed(flat_params, params)
    # Methods without an action transformation have an empty synergy group: its state
    # holds no zero-size array (orbax refuses to save one).
    state = flat(adam()).init({})
    assert all(np.size(leaf) > 0 for leaf in jax.tree.leaves(state))
    assert flat(adam()).update({}, state, {})[0] == {}
