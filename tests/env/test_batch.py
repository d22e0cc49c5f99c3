"""The padded multi-morphology batch: every registered robot steps, shapes, padding,
auto-reset, truncation, NaN guard.

One env of all registered robots (38, from a 2-agent walker to the 9-agent humanoids,
so most are padded) in two merged worlds (23 RK4 robots at dt 0.002, 15 Euler cheetahs
at 0.01; a merged world is an exact union of its robots: private floors and collision
bits), compiled once for the module; episodes are cut at 6 steps to reach the time
limit.
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
from tests.tiny import ROBOT as TINY_ROBOT
from tests.unoptimised import jit_physics

B, T_MAX = 2, 6  # B > 1: the vmapped path, environments apart


@functools.cache
def _env():
    config = EnvConfig(max_episode_steps=T_MAX, robots_per_world=31)
    env = MultiEnv(list(ROBOTS), B, config)
    traces = []

    def counted_step(state, actions):
        traces.append(1)  # runs only while tracing
        return env.step(state, actions)

    return env, jit_physics(env.reset), jit_physics(counted_step), traces


def _random_actions(seed, env):
    return jax.random.uniform(
        jax.random.key(seed), (env.num_morphs, B, env.n_max), minval=-1, maxval=1
    )


def test_every_registered_robot_resets_and_steps_without_nan():
    env, reset, step, _ = _env()
    assert len(env.worlds) == 2  # one per physics setting
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
    m = len(ROBOTS)
    assert env.n_max == 9 and state.obs.shape == (m, B, 9, 19)
    agents = [load(name).num_agents for name in env.names]
    assert min(agents) == 2  # walker_2 and cheetah_2: 7 padded agents
    np.testing.assert_array_equal(env.agent_mask, np.arange(9)[None] < np.array(agents)[:, None])
    state, tr = step(state, _random_actions(1, env))
    for field in ("reward", "terminated", "truncated", "valid", "episode_return"):
        assert getattr(tr, field).shape == (m, B)
    assert tr.next_obs.shape == (m, B, 9, 19) and tr.action.shape == (m, B, 9)
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
    # with typed keys, took 7 s): two worlds, so the per-world keys are checked too.
    env = MultiEnv(["cheetah_2_back", "walker_2_main"], B, EnvConfig(max_episode_steps=T_MAX))
    assert len(env.worlds) == 2
    check_keys_used_once(env.reset, jax.random.key(0))


def test_one_environment_steps_as_the_vmapped_batch_of_one():
    # B = 1 (the paper's setting) calls a world's functions on the one environment,
    # without vmap (MJX traces 1.7x faster): the same computation, up to float rounding.
    # The Euler hopper of the tiny runs, the cheapest to compile.
    robots, config = [load(TINY_ROBOT)], EnvConfig(max_episode_steps=T_MAX)
    one, vmapped = MultiEnv(robots, 1, config), MultiEnv(robots, 1, config)
    vmapped._over_batch = jax.vmap  # the B > 1 path, at B = 1
    key, actions = jax.random.key(0), jax.random.uniform(jax.random.key(1), (3, 1, 1, one.n_max))

    def lowered(env):  # reset, then a scan of steps: one program
        def rollout(key, actions):
            return jax.lax.scan(env.step, env.reset(key), actions)

        return jit_physics(rollout).lower(key, actions)

    programs = [lowered(env) for env in (one, vmapped)]
    assert programs[0].as_text() != programs[1].as_text()  # not the vmapped program
    runs = [program.compile()(key, actions) for program in programs]
    for x, y in zip(jax.tree.leaves(runs[0]), jax.tree.leaves(runs[1]), strict=True):
        assert x.shape == y.shape and x.dtype == y.dtype
        if jnp.issubdtype(x.dtype, jax.dtypes.prng_key):
            x, y = jax.random.key_data(x), jax.random.key_data(y)
        np.testing.assert_allclose(x, y, rtol=1e-5, atol=1e-5)


def test_time_limit_truncates_and_auto_resets_with_true_final_obs():
    env, reset, step, _ = _env()
    state = reset(jax.random.key(4))
    zeros = jnp.zeros((env.num_morphs, B, env.n_max))
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
        world, robot = _locate(env, name)
        layout = env.worlds[world]
        q_sel, v_sel = layout.qpos_robot == robot, layout.dof_robot == robot
        for b in range(B):
            # The stored next_obs is the observation one C step after the previous state.
            qpos = np.asarray(previous.worlds[world].data.qpos[b])[q_sel]
            qvel = np.asarray(previous.worlds[world].data.qvel[b])[v_sel]
            qpos, qvel, _, _ = reference_step(morph, qpos, qvel, np.zeros(morph.num_actuators))
            expected = reference_observation(morph, qpos, qvel)
            np.testing.assert_allclose(tr.next_obs[i, b, : morph.num_agents], expected, atol=1e-3)
            # The new state is a fresh reset: qpos0 plus at most the reset noise.
            new_qpos = np.asarray(state.worlds[world].data.qpos[b])[q_sel]
            deviation = np.abs(new_qpos - morph.model.qpos0).max()
            assert deviation <= morph.task.reset_qpos_noise + 1e-6
            assert np.abs(new_qpos - qpos).max() > 1e-3  # it did not just continue
    for w in state.worlds:
        np.testing.assert_array_equal(w.steps, 0)
        np.testing.assert_array_equal(w.episode_return, 0.0)


def test_termination_is_per_robot_and_not_a_truncation():
    env, reset, step, _ = _env()
    state = reset(jax.random.key(5))
    world, robot = _locate(env, "walker_2_main")
    w = state.worlds[world]
    z_adr = env.worlds[world].root_qpos[robot] + 1
    qpos = w.data.qpos.at[1, z_adr].set(0.2)  # env 1's walker is below its healthy range
    state = _replace_world(state, world, w.replace(data=w.data.replace(qpos=qpos)))
    state, tr = step(state, jnp.zeros((env.num_morphs, B, env.n_max)))
    walker = env.names.index("walker_2_main")
    assert tr.terminated[walker].tolist() == [False, True]
    others = np.arange(env.num_morphs) != walker
    assert not tr.terminated[others].any() and not tr.truncated.any() and tr.valid.all()
    assert state.worlds[world].steps[1, robot] == 0 and state.worlds[world].steps[0, robot] == 1


def test_nonfinite_state_is_reset_flagged_and_counted():
    env, reset, step, _ = _env()
    state = reset(jax.random.key(6))
    world, robot = _locate(env, "hopper_3")
    w = state.worlds[world]
    dofs = jnp.asarray(env.worlds[world].dof_robot == robot)
    qvel = w.data.qvel.at[1].set(jnp.where(dofs, jnp.nan, w.data.qvel[1]))  # env 1's hopper
    state = _replace_world(state, world, w.replace(data=w.data.replace(qvel=qvel)))
    state, tr = step(state, _random_actions(7, env))
    hopper = env.names.index("hopper_3")
    assert not tr.valid[hopper, 1] and tr.valid[:, 0].all()  # env 0 untouched
    # The other world's robots are untouched (a merged world's robots share the solver,
    # so the hopper's world-mates may blow up with it: robots_per_world=1 isolates them).
    other_world = np.isin(np.arange(env.num_morphs), env.groups[1 - world])
    assert tr.valid[other_world].all()
    assert tr.done[hopper, 1] and not tr.terminated[hopper, 1]
    assert np.isfinite(tr.next_obs).all() and np.isfinite(tr.reward).all()
    assert np.isfinite(state.obs).all()
    for leaf in jax.tree.leaves(state.worlds[world].data):
        if jnp.issubdtype(leaf.dtype, jnp.floating):
            assert np.isfinite(leaf).all()
    assert state.nonfinite_resets[hopper] == 1
    state, tr = step(state, _random_actions(8, env))
    assert tr.valid.all()


def test_observations_equal_reference_at_reset():
    env, reset, _, _ = _env()
    state = reset(jax.random.key(9))
    for i, name in enumerate(env.names):
        world, robot = _locate(env, name)
        w, layout = state.worlds[world], env.worlds[world]
        morph = load(name)
        for b in range(B):
            qpos = np.asarray(w.data.qpos[b])[layout.qpos_robot == robot]
            qvel = np.asarray(w.data.qvel[b])[layout.dof_robot == robot]
            expected = reference_observation(morph, qpos, qvel)
            n = morph.num_agents
            np.testing.assert_allclose(state.obs[i, b, :n], expected, atol=2e-5)


def test_bad_batch_size():
    with pytest.raises(ValueError, match="batch_size must be >= 1"):
        MultiEnv(["hopper_3"], 0)


def _locate(env, name):
    i = env.names.index(name)
    for world, group in enumerate(env.groups):
        if i in group:
            return world, group.index(i)
    raise AssertionError(name)


def _replace_world(state, world, new):
    worlds = list(state.worlds)
    worlds[world] = new
    return state.replace(worlds=tuple(worlds))
