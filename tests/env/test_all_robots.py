"""Every registered robot resets and steps in MJX without NaN.

All 38 robots in one MultiEnv: merged worlds (31 robots at most, one per physics
setting) are exact unions of the robots (private floors and collision bits), so two
world compiles cover every robot's MJX model.
"""

import jax
import numpy as np

from solar_jax.compilation_cache import jit_physics
from solar_jax.config import EnvConfig
from solar_jax.env.batch import MultiEnv
from solar_jax.morphology import ROBOTS, load
from solar_jax.synergy.discovery import SuiteAffinity
from solar_jax.training.trainer import check_masks


def test_every_registered_robot_resets_and_steps_without_nan():
    robots = [load(name) for name in ROBOTS]
    env = MultiEnv(robots, 2, EnvConfig(robots_per_world=31))
    assert len(env.worlds) == 2  # 23 RK4 robots at dt 0.002, 15 Euler cheetahs at 0.01
    # The masks the networks read (the env's) are those the clustering reads (the parents').
    check_masks(
        env.names, env.agent_mask, SuiteAffinity([m.parents for m in robots], env.n_max).mask
    )
    state = jit_physics(env.reset)(jax.random.key(0))
    step = jit_physics(env.step)
    key = jax.random.key(1)
    for _ in range(5):
        key, k = jax.random.split(key)
        actions = jax.random.uniform(k, (env.num_morphs, 2, env.n_max), minval=-1, maxval=1)
        state, transition = step(state, actions)
        assert transition.valid.all()
        assert np.isfinite(transition.next_obs).all() and np.isfinite(transition.reward).all()
    assert np.isfinite(state.obs).all() and (state.nonfinite_resets == 0).all()
    # Real agents have a body position (z > 0 at least); padding stays zero.
    assert (np.abs(state.obs[..., :3]).sum(-1)[env.agent_mask[:, None, :].repeat(2, 1)] > 0).all()
    np.testing.assert_array_equal(state.obs[~env.agent_mask[:, None, :].repeat(2, 1)], 0.0)
