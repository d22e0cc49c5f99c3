"""One collection round and its update count, checked by hand (SPEC section 5).

hopper_3 with two environments: the one that finishes first keeps stepping after its
auto-reset until the other finishes. The reference stores those continued transitions
and does not count them; an episode of L steps counts L - 1; the round then gives
(counted steps of all morphologies) // M_all iterations.
"""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from solar_jax.config import TrainConfig
from solar_jax.training.trainer import Trainer

CONFIG = TrainConfig(
    morph="hopper_3",
    net="tiny",
    num_envs=2,
    total_steps=10_000,
    replay_capacity=2048,
    progress=False,
)


def _round(config: TrainConfig, warmup_steps: int):
    config = dataclasses.replace(
        config, td3=dataclasses.replace(config.td3, warmup_steps=warmup_steps)
    )
    trainer = Trainer(config)
    state = trainer.init(0)
    state, stats = trainer.collect(state, jax.random.PRNGKey(0), jnp.bool_(False))
    return trainer, state, jax.device_get(stats)


@pytest.fixture(scope="module")
def policy_round():
    """A round after the warm-up (warmup_steps=0): the policy acts, with noise."""
    return _round(CONFIG, warmup_steps=0)


def test_continued_transitions_are_stored_and_not_counted(policy_round):
    trainer, state, stats = policy_round
    lengths = stats.episode_length[0] * 2  # mean over the two environments -> sum
    counted = int(stats.steps[0])
    # Each environment's episode of L steps counts L - 1.
    assert counted == int(round(lengths)) - 2
    assert int(state.env_steps) == counted and int(state.heldout_steps) == 0
    # Both environments stepped until the longer episode ended, and every step was stored.
    stored = int(state.replay.size[0])
    assert stored % 2 == 0 and stored > round(lengths)  # the shorter one continued
    longest = stored // 2
    assert longest <= CONFIG.env.max_episode_steps
    # The iterations that follow: counted steps of all morphologies // M_all (M = 1).
    state, metrics = jax.jit(trainer._train)(state, stats.steps)
    assert int(metrics["iterations"]) == int(state.updates) == counted


def test_the_torso_action_is_stored(policy_round):
    _, state, _ = policy_round
    stored = int(state.replay.size[0])
    torso = np.asarray(state.replay.action[0, :stored, 0])
    assert np.all(np.abs(torso) > 0) and np.all(np.abs(torso) <= 1)  # policy + noise, clipped


@pytest.mark.slow
def test_replay_continued_false_stores_first_episodes_only():
    config = dataclasses.replace(CONFIG, replay_continued=False)
    _, state, stats = _round(config, warmup_steps=0)
    assert int(state.replay.size[0]) == int(round(stats.episode_length[0] * 2))
    assert int(stats.steps[0]) == int(state.replay.size[0]) - 2
