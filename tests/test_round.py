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
from solar_jax.training.lanes import SingleLane
from solar_jax.training.programs import RoundPrograms
from solar_jax.training.trainer import Trainer
from tests.guards import check_keys_used_once, no_retracing

CONFIG = TrainConfig(
    morph="hopper_3",
    net="tiny",
    num_envs=2,
    total_steps=10_000,
    replay_capacity=2048,
    progress=False,
)


def _collect(programs: RoundPrograms, state, key: jax.Array):
    """One training round's collection of a single run (its one lane, not evaluating)."""
    no = np.zeros(1, bool)
    return programs.collect(state, key[None], no, no)


def _round(config: TrainConfig, warmup_steps: int):
    config = dataclasses.replace(
        config, td3=dataclasses.replace(config.td3, warmup_steps=warmup_steps)
    )
    programs = RoundPrograms(SingleLane(Trainer(config)))
    state = programs.trainer.init(0)
    state, stats = _collect(programs, state, jax.random.PRNGKey(0))
    return programs, state, jax.device_get(stats)


@pytest.fixture(scope="module")
def policy_round():
    """A round after the warm-up (warmup_steps=0): the policy acts, with noise."""
    return _round(CONFIG, warmup_steps=0)


def test_continued_transitions_are_stored_and_not_counted(policy_round):
    programs, state, stats = policy_round
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
    state, metrics = jax.jit(programs.trainer.train)(state, stats.steps)
    assert int(metrics["iterations"]) == int(state.updates) == counted


def test_the_torso_action_is_stored(policy_round):
    _, state, _ = policy_round
    stored = int(state.replay.size[0])
    torso = np.asarray(state.replay.action[0, :stored, 0])
    assert np.all(np.abs(torso) > 0) and np.all(np.abs(torso) <= 1)  # policy + noise, clipped


def test_a_second_round_retraces_nothing_and_the_update_reuses_no_key(policy_round):
    programs, state, stats = policy_round
    copy = jax.tree.map(jnp.copy, state)  # collect donates its state
    with no_retracing("a second round of the same shapes"):
        _collect(programs, copy, jax.random.PRNGKey(1))
    # The update program traced with a typed key (``jax.random.key``): every key it
    # splits or folds in is consumed once. (The episodes program selects between the
    # evaluation key and the round's, which the checker cannot follow.)
    check_keys_used_once(programs.trainer.train, state.replace(key=jax.random.key(0)), stats.steps)


@pytest.mark.slow
def test_replay_continued_false_stores_first_episodes_only():
    config = dataclasses.replace(CONFIG, replay_continued=False)
    _, state, stats = _round(config, warmup_steps=0)
    assert int(state.replay.size[0]) == int(round(stats.episode_length[0] * 2))
    assert int(stats.steps[0]) == int(state.replay.size[0]) - 2
