"""Our robots behind brax's ``Env`` (``solar_jax.env.brax_env``; the ``brax`` extra): the
same task as ``make_env``'s, brax's wrappers around it, and brax's PPO training on it."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

pytest.importorskip("brax", reason="the brax extra is not installed")

from brax import envs  # noqa: E402
from brax.training.agents.ppo import train as ppo  # noqa: E402

from solar_jax.config import EnvConfig  # noqa: E402
from solar_jax.env.brax_env import BraxEnv  # noqa: E402
from solar_jax.env.single import make_env  # noqa: E402
from tests import unoptimised  # noqa: E402

CONFIG = EnvConfig(max_episode_steps=10**6)


def test_the_brax_env_is_the_single_env_flat_and_without_resets():
    env, ours = BraxEnv("hopper_3", CONFIG), make_env("hopper_3", CONFIG)
    assert (env.observation_size, env.action_size, env.backend) == (3 * 19, 2, "mjx")
    key = jax.random.PRNGKey(3)
    actions = jax.random.uniform(jax.random.PRNGKey(4), (200, 2), minval=-1, maxval=1)

    @unoptimised.jit
    def both(key, actions):
        def body(carry, action):
            state, mine = carry
            state, mine = env.step(state, action), ours.step(mine, action)
            return (state, mine), (
                state.obs,
                state.reward,
                state.done,
                mine.final_obs,
                mine.reward,
                mine.terminated,
                state.pipeline_state.data.qpos,
            )

        return jax.lax.scan(body, (env.reset(key), ours.reset(key)), actions)[1]  # fmt: skip

    obs, reward, done, my_obs, my_reward, terminated, qpos = both(key, actions)
    ended = int(np.argmax(np.asarray(terminated))) if np.any(terminated) else len(actions)
    assert 5 < ended < len(actions) - 1, ended  # uniform actions topple the hopper
    np.testing.assert_array_equal(obs[: ended + 1], my_obs[: ended + 1].reshape(ended + 1, -1))
    np.testing.assert_array_equal(reward[: ended + 1], my_reward[: ended + 1])
    assert done[ended] == 1.0 and not np.any(done[:ended])
    assert obs.dtype == jnp.float32 and obs.shape == (200, 57)
    # No reset of its own: the step after the end goes on from where the episode ended.
    assert not np.allclose(qpos[ended + 1], qpos[0], atol=0.05)


def test_brax_wrappers_reset_it_and_limit_its_episodes():
    env = envs.training.wrap(BraxEnv("hopper_3", CONFIG), episode_length=5)
    state = unoptimised.jit(env.reset)(jax.random.split(jax.random.PRNGKey(0), 2))
    step = unoptimised.jit(env.step)
    first = state.obs
    for _ in range(5):
        state = step(state, jnp.zeros((2, 2)))
    np.testing.assert_array_equal(state.info["truncation"], [1.0, 1.0])
    np.testing.assert_array_equal(state.obs, first)  # reset by the AutoResetWrapper


@pytest.mark.slow  # brax's PPO program compiles for minutes on a CPU
def test_brax_ppo_trains_on_hopper_3():
    progress = []
    _, params, metrics = ppo.train(
        environment=BraxEnv("hopper_3", CONFIG),
        num_timesteps=400,
        episode_length=20,
        num_envs=4,
        batch_size=4,
        num_minibatches=2,
        unroll_length=5,
        num_updates_per_batch=1,
        num_evals=2,
        seed=0,
        progress_fn=lambda step, m: progress.append((step, m["eval/episode_reward"])),
    )
    assert len(progress) == 2 and progress[-1][0] >= 400
    assert all(np.isfinite(reward) for _, reward in progress)
    assert np.isfinite(metrics["eval/episode_reward"])
