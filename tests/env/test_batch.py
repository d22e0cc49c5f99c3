"""The padded multi-morphology batch: every registered robot steps, shapes, padding,
auto-reset, truncation, NaN guard, environments apart.

One env of all registered robots (38, from a 2-agent walker to the 9-agent humanoids,
so most are padded) in two union worlds (every robot a variant of one model,
``env.union``: the 23 RK4 robots on humanoid_2d_9_full's tree grown to hold the walkers
and hoppers, the 15 Euler cheetahs on cheetah_7_full's), at B = 1 (the paper's
setting), compiled once for the module; episodes are cut at 6 steps to reach the time
limit. The vmapped batch
(B = 2) is checked on the tests' Euler hopper: environments apart, and each equal to
one stepped alone.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from solar_jax.config import EnvConfig
from solar_jax.env.batch import MultiEnv
from solar_jax.morphology import ROBOTS, load
from solar_jax.synergy.discovery import SuiteAffinity
from solar_jax.training.trainer import check_masks
from tests.env.oracle import reference_observation, reference_step
from tests.guards import check_keys_used_once, no_retracing
from tests.tiny import NAME as TINY_NAME
from tests.tiny import ROBOT as TINY_ROBOT
from tests.unoptimised import jit_physics

T_MAX = 6


@functools.cache
def _env():
    """All registered robots at B = 1: the env, its jitted reset and step, step's traces."""
    config = EnvConfig(max_episode_steps=T_MAX)
    env = MultiEnv(list(ROBOTS), 1, config)
    traces = []

    def counted_step(state, actions):
        traces.append(1)  # runs only while tracing
        return env.step(state, actions)

    return env, jit_physics(env.reset), jit_physics(counted_step), traces


@functools.cache
def _hopper(batch_size: int):
    """The tests' Euler hopper (the cheapest to compile) in ``batch_size`` environments:
    the env, its jitted reset and step."""
    env = MultiEnv([str(TINY_ROBOT)], batch_size, EnvConfig(max_episode_steps=T_MAX))
    return env, jit_physics(env.reset), jit_physics(env.step)


def _random_actions(seed, env):
    return jax.random.uniform(
        jax.random.key(seed), (env.num_morphs, env.batch_size, env.n_max), minval=-1, maxval=1
    )


def test_every_registered_robot_resets_and_steps_without_nan():
    env, reset, step, _ = _env()
    assert len(env.worlds) == 2  # a union per physics setting
    assert [env.names[g[0]] for g in env.groups] == ["humanoid_2d_9_full", "cheetah_7_full"]
    # The masks the networks read (the env's) are those the clustering reads (the parents').
    check_masks(
        env.names, env.agent_mask, SuiteAffinity([m.parents for m in env.morphs], env.n_max).mask
    )
    state = reset(jax.random.key(0))
    for t in range(3):
        state, transition = step(state, _random_actions(100 + t, env))
        assert transition.valid.all()
        assert np.isfinite(transition.next_obs).all() and np.isfinite(transition.reward).all()
    assert np.isfinite(state.obs).all() and (state.nonfinite_resets == 0).all()
    # Real agents have a body position (z > 0 at least); padding stays zero.
    real = np.broadcast_to(env.agent_mask[:, None, :], state.obs.shape[:3])
    assert (np.abs(state.obs[..., :3]).sum(-1)[real] > 0).all()
    np.testing.assert_array_equal(state.obs[~real], 0.0)


def test_shapes_mask_and_padding():
    env, reset, step, _ = _env()
    state = reset(jax.random.key(0))
    m, b = len(ROBOTS), env.batch_size
    assert b == 1 and env.n_max == 9 and state.obs.shape == (m, b, 9, 19)
    agents = [load(name).num_agents for name in env.names]
    assert min(agents) == 2  # walker_2 and cheetah_2: 7 padded agents
    np.testing.assert_array_equal(env.agent_mask, np.arange(9)[None] < np.array(agents)[:, None])
    state, tr = step(state, _random_actions(1, env))
    for field in ("reward", "terminated", "truncated", "valid", "episode_return"):
        assert getattr(tr, field).shape == (m, b)
    assert tr.next_obs.shape == (m, b, 9, 19) and tr.action.shape == (m, b, 9)
    for i, n in enumerate(agents):
        np.testing.assert_array_equal(state.obs[i, :, n:], 0.0)
        np.testing.assert_array_equal(tr.next_obs[i, :, n:], 0.0)


def test_torso_and_padded_actions_are_ignored():
    env, reset, step, _ = _env()
    state = reset(jax.random.key(0))
    actions = _random_actions(2, env)
    padding = ~env.agent_mask[:, None, :]
    junk = jnp.where(padding, -123.0, actions.at[:, :, 0].set(0.9))  # padding, torso
    _, a = step(state, actions)
    _, b = step(state, junk)
    for x, y in zip(
        jax.tree.leaves(a.replace(action=0)), jax.tree.leaves(b.replace(action=0)), strict=True
    ):
        np.testing.assert_array_equal(x, y)


def test_step_traces_once():
    env, reset, step, traces = _env()
    state = reset(jax.random.key(3))
    before = len(traces)
    for k in range(2):
        state, _ = step(state, _random_actions(10 + k, env))
    jax.block_until_ready(state)
    assert len(traces) - before <= 1 and len(traces) == 1
    with no_retracing("the batch's step"):
        state, _ = step(state, _random_actions(20, env))


def test_reset_consumes_each_key_once():
    # The same code with one robot per world kind (tracing all 38 robots' reset again,
    # with typed keys, took 7 s): two worlds and two environments, so the per-world and
    # per-environment keys are checked too.
    env = MultiEnv(["cheetah_2_back", "walker_2_main"], 2, EnvConfig(max_episode_steps=T_MAX))
    assert len(env.worlds) == 2
    check_keys_used_once(env.reset, jax.random.key(0))


def test_each_environment_of_the_vmapped_batch_steps_as_one_alone(monkeypatch):
    # B = 1 (the paper's setting) calls a world's functions on the one environment,
    # without vmap (MJX traces it in half the time): the same computation, up to float
    # rounding, as the vmapped batch (B = 2) does for each of its environments.
    (batch, reset, step_batch), (one, _, step_one) = _hopper(2), _hopper(1)
    vmapped = []
    with monkeypatch.context() as patch:
        patch.setattr(jax, "vmap", lambda fn: vmapped.append(fn) or fn)
        one._over_batch(jnp.sum)
        batch._over_batch(jnp.mean)
    assert vmapped == [jnp.mean]  # the batch's path only: B = 1 is not vmapped
    state = reset(jax.random.key(0))
    alone = [_environment(state, b) for b in range(2)]
    for t in range(3):
        actions = _random_actions(30 + t, batch)
        state, transition = step_batch(state, actions)
        for b in range(2):
            alone[b], expected = step_one(alone[b], actions[:, b : b + 1])
            got = jax.tree.map(lambda x, b=b: x[:, b : b + 1], transition)
            _assert_close((_environment(state, b), got), (alone[b], expected))


def test_time_limit_truncates_and_auto_resets_with_true_final_obs():
    env, reset, step, _ = _env()
    state = reset(jax.random.key(4))
    zeros = jnp.zeros((env.num_morphs, env.batch_size, env.n_max))
    for t in range(T_MAX):
        previous = state
        state, tr = step(state, zeros)
        if t < T_MAX - 1:
            assert not tr.truncated.any() and not tr.terminated.any()
    assert tr.truncated.all() and not tr.terminated.any() and tr.valid.all()
    np.testing.assert_array_equal(tr.episode_length, T_MAX)
    assert np.isfinite(tr.episode_return).all() and (tr.episode_return != 0).all()
    for i, name in enumerate(env.names):
        morph = load(name)
        place = env.locate(i)
        q_sel, v_sel = place.qpos, place.dofs
        for b in range(env.batch_size):
            # The stored next_obs is the observation one C step after the previous state.
            qpos = np.asarray(previous.worlds[place.world].data.qpos[b])[place.data][q_sel]
            qvel = np.asarray(previous.worlds[place.world].data.qvel[b])[place.data][v_sel]
            qpos, qvel, _, _ = reference_step(morph, qpos, qvel, np.zeros(morph.num_actuators))
            expected = reference_observation(morph, qpos, qvel)
            np.testing.assert_allclose(tr.next_obs[i, b, : morph.num_agents], expected, atol=1e-3)
            # The new state is a fresh reset: qpos0 plus at most the reset noise.
            new_qpos = np.asarray(state.worlds[place.world].data.qpos[b])[place.data][q_sel]
            deviation = np.abs(new_qpos - morph.model.qpos0).max()
            assert deviation <= morph.task.reset_qpos_noise + 1e-6
            assert np.abs(new_qpos - qpos).max() > 1e-3  # it did not just continue
    for w in state.worlds:
        np.testing.assert_array_equal(w.steps, 0)
        np.testing.assert_array_equal(w.episode_return, 0.0)


# The last environment is broken (B = 1: the one; B = 2: the second, the first untouched).
BROKEN = {
    "all robots, B = 1": (lambda: _env()[:3], "walker_2_main"),
    "hopper, B = 2": (lambda: _hopper(2), TINY_NAME),
}


def _broken(setup: str):
    """The env of ``setup``, its jitted reset and step, its robot to break and where."""
    make, name = BROKEN[setup]
    env, reset, step = make()
    i = env.names.index(name)
    return env, reset, step, i, env.locate(i), env.batch_size - 1


@pytest.mark.parametrize("setup", BROKEN)
def test_termination_is_per_robot_and_environment_and_not_a_truncation(setup):
    env, reset, step, i, place, b = _broken(setup)
    world, robot = place.world, place.robot
    state = reset(jax.random.key(5))
    w = state.worlds[world]
    z_adr = (b, *place.data, place.qpos[1])
    qpos = w.data.qpos.at[z_adr].set(0.2)  # env b's robot is below its healthy range
    state = _replace_world(state, world, w.replace(data=w.data.replace(qpos=qpos)))
    state, tr = step(state, jnp.zeros((env.num_morphs, env.batch_size, env.n_max)))
    assert tr.terminated[i].tolist() == [False] * b + [True]
    others = np.arange(env.num_morphs) != i
    assert not tr.terminated[others].any() and not tr.truncated.any() and tr.valid.all()
    steps = state.worlds[world].steps
    assert steps[b, robot] == 0 and (steps[:b, robot] == 1).all()


@pytest.mark.parametrize("setup", BROKEN)
def test_nonfinite_state_is_reset_flagged_and_counted(setup):
    env, reset, step, i, place, b = _broken(setup)
    world = place.world
    state = reset(jax.random.key(6))
    w = state.worlds[world]
    qvel = w.data.qvel.at[(b, *place.data, place.dofs)].set(jnp.nan)  # env b's robot
    state = _replace_world(state, world, w.replace(data=w.data.replace(qvel=qvel)))
    state, tr = step(state, _random_actions(7, env))
    assert not tr.valid[i, b] and tr.valid[:, :b].all()  # the environments before untouched
    # Every other robot is untouched (a union's robots are environments of their own).
    others = np.arange(env.num_morphs) != i
    assert tr.valid[others].all()
    assert tr.done[i, b] and not tr.terminated[i, b]
    assert np.isfinite(tr.next_obs).all() and np.isfinite(tr.reward).all()
    assert np.isfinite(state.obs).all()
    for leaf in jax.tree.leaves(state.worlds[world].data):
        if jnp.issubdtype(leaf.dtype, jnp.floating):
            assert np.isfinite(leaf).all()
    assert state.nonfinite_resets[i] == 1
    state, tr = step(state, _random_actions(8, env))
    assert tr.valid.all()


def test_observations_equal_reference_at_reset():
    env, reset, _, _ = _env()
    state = reset(jax.random.key(9))
    for i, name in enumerate(env.names):
        place = env.locate(i)
        w = state.worlds[place.world]
        morph = load(name)
        for b in range(env.batch_size):
            qpos = np.asarray(w.data.qpos[b])[place.data][place.qpos]
            qvel = np.asarray(w.data.qvel[b])[place.data][place.dofs]
            expected = reference_observation(morph, qpos, qvel)
            n = morph.num_agents
            np.testing.assert_allclose(state.obs[i, b, :n], expected, atol=2e-5)


@pytest.mark.parametrize("batch_size", [1, 2])
def test_a_blank_state_has_the_reset_state_s_shapes(batch_size):
    # Programs that carry the env's state are compiled for ``blank``'s shapes.
    env = _hopper(batch_size)[0]
    key = jax.random.key_data(jax.random.key(0))
    reset, blank = jax.eval_shape(env.reset, key), jax.eval_shape(env.blank, key)
    assert jax.tree.structure(reset) == jax.tree.structure(blank)
    assert jax.tree.leaves(reset) == jax.tree.leaves(blank)  # shapes, dtypes


def test_a_part_of_the_env_is_its_worlds():
    env = _env()[0]  # two union worlds: the RK4 robots, then the Euler cheetahs
    part = env.part([1])
    assert part.world_ids == (1,) and part.n_max == env.n_max
    assert part.morph_ids == tuple(env.groups[1])
    assert part.names == tuple(env.names[i] for i in env.groups[1])
    np.testing.assert_array_equal(part.agent_mask, env.agent_mask[env.groups[1]])
    key = jax.random.key_data(jax.random.key(0))
    whole, alone = jax.eval_shape(env.blank, key), jax.eval_shape(part.blank, key)
    assert jax.tree.leaves(alone.worlds) == jax.tree.leaves(whole.worlds[1:2])


def test_bad_batch_size():
    with pytest.raises(ValueError, match="batch_size must be >= 1"):
        MultiEnv(["hopper_3"], 0)


def _assert_close(tree, expected):
    """Same structure, shapes and dtypes; values (keys' data too) equal up to rounding."""
    for x, y in zip(jax.tree.leaves(tree), jax.tree.leaves(expected), strict=True):
        assert x.shape == y.shape and x.dtype == y.dtype
        if jnp.issubdtype(x.dtype, jax.dtypes.prng_key):
            x, y = jax.random.key_data(x), jax.random.key_data(y)
        np.testing.assert_allclose(x, y, rtol=1e-5, atol=1e-5)


@functools.partial(jax.jit, static_argnums=1)  # eagerly, a program per leaf shape
def _environment(state, b: int):
    """Environment ``b`` of a batched state, as the state of one environment (B = 1)."""
    return state.replace(
        worlds=jax.tree.map(lambda x: x[b : b + 1], state.worlds), obs=state.obs[:, b : b + 1]
    )


def _replace_world(state, world, new):
    worlds = list(state.worlds)
    worlds[world] = new
    return state.replace(worlds=tuple(worlds))
