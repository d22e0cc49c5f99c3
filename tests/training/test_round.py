"""One collection round and its update count, checked by hand (algorithm.md §5).

The session's tiny run (``tests.tiny``: an Euler hopper_3, two environments): the one
that finishes first keeps stepping after its auto-reset until the other finishes. The
reference stores those continued transitions and does not count them; an episode of L
steps counts L - 1; the round then gives (counted steps of all morphologies) // M_all
iterations.
"""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from solar_jax.training.lanes import SingleLane
from solar_jax.training.programs import RoundPrograms
from solar_jax.training.trainer import Trainer, round_iterations
from tests import unoptimised
from tests.guards import check_keys_used_once, no_retracing
from tests.tiny import CONFIG


def _collect(programs: RoundPrograms, state, key: jax.Array):
    """One training round's collection of a single run (its one lane, not evaluating)."""
    no = np.zeros(1, bool)
    programs.compile(state)  # its replay size's programs (compiled once per session)
    return programs.collect(state, key[None], no, no)


def _policy_round(programs: RoundPrograms):
    """A round of a fresh state past the warm-up: the policy acts, with noise (0.3, so
    that the untrained hopper falls, one environment before the other, before the
    200-step limit)."""
    state = programs.trainer.init(0)
    hyper = state.hyper.replace(exploration_noise=jnp.float32(0.3))
    state = state.replace(env_steps=jnp.int32(CONFIG.td3.warmup_steps), hyper=hyper)
    state, stats = _collect(programs, state, jax.random.PRNGKey(0))
    return programs, state, jax.device_get(stats)


@pytest.fixture(scope="module")
def policy_round(tiny_run):
    return _policy_round(tiny_run)


def test_continued_transitions_are_stored_and_not_counted(policy_round):
    programs, state, stats = policy_round
    lengths = stats.episode_length[0] * 2  # mean over the two environments -> sum
    counted = int(stats.steps[0])
    # Each environment's episode of L steps counts L - 1.
    assert counted == int(round(lengths)) - 2
    assert int(state.env_steps) == CONFIG.td3.warmup_steps + counted
    assert int(state.heldout_steps) == 0
    # Both environments stepped until the longer episode ended, and every step was stored.
    stored = int(state.replay.size[0])
    assert stored % 2 == 0 and stored > round(lengths)  # the shorter one continued
    longest = stored // 2
    assert longest <= CONFIG.env.max_episode_steps
    # The iterations that follow: counted steps of all morphologies // M_all (M = 1).
    live = np.ones(1, bool)
    trained, metrics = programs.train(unoptimised.copy(state), stats.steps, live)
    assert int(metrics["iterations"]) == int(trained.updates) == counted
    # The state it returns goes back in as it came (shapes, dtypes, weak types): a jitted
    # update fed it would not trace again (checked by tracing alone, no compile).
    train = jax.jit(programs.trainer.train)
    returned, _ = train.eval_shape(state, stats.steps)
    with no_retracing("an update of the state the update returned"):
        train.eval_shape(returned, stats.steps)


def test_update_every_divides_the_round_s_iterations():
    # 3 morphologies (2 training) counted 7 + 5 + 12 = 24 steps: the paper's 24 // 3 = 8
    # iterations per training morphology; one per 3 counted steps, 24 // 9 = 2; per 25, 0.
    steps = jnp.array([7, 5, 12], jnp.int32)
    for every, iterations in {1: 8, 3: 2, 4: 2, 25: 0}.items():
        assert int(round_iterations(steps, 3, every)) == iterations, every


def test_per_environment_noise_scales(tiny_trainer):
    # td3.exploration_noise_min: each environment's std uniform in [min, exploration_noise],
    # drawn per round from the round's key; None: the one std, as a scalar.
    state = tiny_trainer.init(0)
    ids = np.arange(tiny_trainer.num_morphs)
    assert tiny_trainer._exploration_scale(state, ids).shape == ()
    td3 = dataclasses.replace(CONFIG.td3, exploration_noise=0.4, exploration_noise_min=0.1)
    trainer = Trainer(dataclasses.replace(CONFIG, td3=td3), tiny_trainer.env)
    state = trainer.init(0)
    scales = np.asarray(trainer._exploration_scale(state, ids))
    assert scales.shape == (1, CONFIG.num_envs, 1)
    assert np.all((scales >= 0.1) & (scales <= 0.4)) and scales[0, 0, 0] != scales[0, 1, 0]
    again = np.asarray(trainer._exploration_scale(state, ids))
    later = np.asarray(trainer._exploration_scale(state.replace(key=jax.random.PRNGKey(7)), ids))
    np.testing.assert_array_equal(scales, again)  # one round's stds: the same at every step
    assert np.all(later != scales)  # another round's key, other stds
    with pytest.raises(ValueError, match=r"td3.exploration_noise_min must be in \[0, "):
        dataclasses.replace(CONFIG.td3, exploration_noise_min=0.5)


def test_the_torso_action_is_stored(policy_round):
    _, state, _ = policy_round
    stored = int(state.replay.size[0])
    torso = np.asarray(state.replay.action[0, :stored, 0])
    assert np.all(np.abs(torso) > 0) and np.all(np.abs(torso) <= 1)  # policy + noise, clipped


def test_the_update_reuses_no_key(policy_round):
    programs, state, stats = policy_round
    # The update program traced with a typed key (``jax.random.key``): every key it
    # splits or folds in is consumed once. (The episodes program selects between the
    # evaluation key and the round's, which the checker cannot follow.)
    check_keys_used_once(programs.trainer.train, state.replace(key=jax.random.key(0)), stats.steps)


@pytest.mark.slow
def test_replay_continued_false_stores_first_episodes_only():
    config = dataclasses.replace(CONFIG, replay_continued=False)
    _, state, stats = _policy_round(RoundPrograms(SingleLane(Trainer(config))))
    assert int(state.replay.size[0]) == int(round(stats.episode_length[0] * 2))
    assert int(stats.steps[0]) == int(state.replay.size[0]) - 2
