"""Rounds of bounded length (``round_steps``) checked by hand on the tiny hopper
(``tests.tiny.BOUNDED``: the fast schedule with 4 environments, 25 steps a round,
episodes of 40-110 steps under random actions, so they span rounds, and evaluations in
a program of their own).

Each training round steps every environment ``round_steps`` times and stores every
transition; an episode of L steps still counts L - 1 (a step counts unless an episode
ended on it); episodes go on from where the last round left them and reset on their
own; evaluations run whole episodes of fresh environments and leave the training
environments as they were.
"""

import jax
import numpy as np
import pytest

from solar_jax.env.world import OBS_SIZE
from solar_jax.training.programs import RoundPrograms
from solar_jax.training.runner import eval_key
from tests import unoptimised
from tests.tiny import BOUNDED

ROUNDS = 8  # 800 transitions, about 10 episodes


def _round(programs: RoundPrograms, state, evaluate: bool = False, key=None):
    """A round (``evaluate``: an evaluation through the collection's program, from
    ``key``) of a single run's state, its stats on the host."""
    flag, key = np.full(1, evaluate), jax.random.PRNGKey(3) if key is None else key
    programs.compile(state)
    state, stats = programs.collect(state, key[None], flag, np.zeros(1, bool))
    return state, jax.device_get(stats)


@pytest.fixture(scope="module")
def bounded_rounds(tiny_bounded):
    """``ROUNDS`` training rounds from a fresh state: (programs, the states before each
    round and after the last, each round's stats), on the host."""
    programs = tiny_bounded
    state = programs.trainer.init(0)
    states, stats = [jax.device_get(state)], []
    for _ in range(ROUNDS):
        state, round_stats = _round(programs, state)
        states.append(jax.device_get(state))
        stats.append(round_stats)
    return programs, states, stats


def test_every_environment_steps_round_steps_times_and_every_transition_is_stored(
    bounded_rounds,
):
    _, states, stats = bounded_rounds
    per_round = BOUNDED.num_envs * BOUNDED.round_steps
    assert [int(s.replay.size[0]) for s in states] == [per_round * r for r in range(ROUNDS + 1)]
    assert int(states[-1].nonfinite_resets.sum()) == 0
    for before, after, round_stats in zip(states[:-1], states[1:], stats, strict=True):
        # A step counts unless an episode ended on it: an episode of L steps counts L - 1.
        ended = int(round_stats.episodes[0])
        assert int(round_stats.steps[0]) == per_round - ended
        assert int(after.env_steps) == int(before.env_steps) + per_round - ended
        assert int(after.rounds) == int(before.rounds)  # counted by the update, not here
    assert sum(int(s.episodes[0]) for s in stats) >= 4  # episodes ended, in some rounds only
    assert any(int(s.episodes[0]) == 0 for s in stats)


def test_episodes_go_on_across_rounds_and_reset_on_their_own(bounded_rounds):
    _, states, stats = bounded_rounds
    b, r = BOUNDED.num_envs, BOUNDED.round_steps
    replay = states[-1].replay
    rows = ROUNDS * r  # the ring's rows per environment: step t of env e at t * B + e
    obs = replay.obs[0, : rows * b].reshape(rows, b, *replay.obs.shape[2:])
    next_obs = replay.next_obs[0, : rows * b].reshape(obs.shape)
    terminated = replay.terminated[0, : rows * b].reshape(rows, b)
    # Within an episode, each transition starts where the last one ended, across the
    # rounds' boundaries too (rows r - 1 and r, 2r - 1 and 2r, ...).
    # (The state's observation and the step's next_obs are computed apart: equal up to
    # float rounding; a reset moves it by far more.)
    same = np.abs(obs[1:] - next_obs[:-1]).max(axis=(2, 3)) < 1e-4  # [rows - 1, B]
    ended = terminated[:-1]
    assert np.all(same[~ended])
    assert not np.any(same[ended])  # a fresh episode after each end: a reset, not a step
    boundaries = np.arange(r, rows, r) - 1
    assert np.all(same[boundaries][~ended[boundaries]]) and same[boundaries].sum() > 0
    # Every episode that ended was counted: the task's ends (no 200-step limit reached).
    assert int(terminated.sum()) == sum(int(s.episodes[0]) for s in stats)
    # Episodes longer than a round ended, and the environments' step counters run on.
    assert max(float(s.episode_length[0]) for s in stats) > r
    steps = np.asarray(states[-1].envs.worlds[0].steps).ravel()
    assert np.any(steps > r) or np.any(steps % r != 0)


def test_each_environment_s_exploration_std_is_drawn_anew_when_its_episode_ends(
    bounded_rounds,
):
    # The fast schedule's per-environment stds (td3.exploration_noise_min 0, at most 0.4),
    # held through an episode across rounds, drawn again at its end (FastTD3's).
    _, states, _ = bounded_rounds
    b, r = BOUNDED.num_envs, BOUNDED.round_steps
    terminated = states[-1].replay.terminated[0, : ROUNDS * r * b].reshape(ROUNDS, r, b)
    scales = np.stack([s.envs.noise_scale[0] for s in states[1:]])  # [rounds, B]
    assert np.all((scales >= 0) & (scales <= BOUNDED.td3.exploration_noise))
    assert len(np.unique(scales[0])) == b  # one per environment
    ended = terminated[1:].any(axis=1)  # [rounds - 1, B]: an episode ended in the round
    assert ended.any() and (~ended).any()
    assert np.all((scales[1:] == scales[:-1]) == ~ended)


def test_the_round_stats_are_each_environment_s_latest_episode(bounded_rounds):
    _, states, stats = bounded_rounds
    for state, round_stats in zip(states[1:], stats, strict=True):
        last = state.envs.last_length[0]
        finished = last > 0
        expected = state.envs.last_return[0][finished].mean() if finished.any() else 0.0
        np.testing.assert_allclose(round_stats.episode_return[0], expected, rtol=1e-6)
    # Before any episode ended: 0, not a mean over nothing.
    first = next(i for i, s in enumerate(stats) if s.episodes[0] > 0)
    assert all(float(s.episode_return[0]) == 0.0 for s in stats[:first])


def test_warm_up_rounds_act_at_random_throughout(bounded_rounds):
    programs, _, _ = bounded_rounds
    warmup = BOUNDED.td3.warmup_steps  # M = 1
    switch = programs.trainer.warmup_switch
    assert switch(0) == switch(warmup - 1) == BOUNDED.round_steps
    assert switch(warmup) == 0


def test_an_evaluation_runs_whole_episodes_and_leaves_the_environments(bounded_rounds):
    programs, states, _ = bounded_rounds
    state = programs.lanes.place([jax.device_put(states[-1])])
    evaluated, stats = _round(programs, state, evaluate=True)
    host = jax.device_get(evaluated)
    jax.tree.map(np.testing.assert_array_equal, host, states[-1])  # nothing changed
    assert np.all(stats.episode_length > BOUNDED.round_steps)  # whole episodes, not a round
    assert int(stats.episodes[0]) == BOUNDED.num_envs


def test_the_fast_schedule_s_update_after_a_round_by_hand(bounded_rounds):
    # Fused iterations, one per update_every counted steps of all morphologies (M = 1),
    # each on a batch [M_train, batch_size, N, ...]; every critic parameter moves.
    programs, states, stats = bounded_rounds
    state = programs.lanes.place([jax.device_put(states[-1])])
    steps = stats[-1].steps
    trained, metrics = programs.train(unoptimised.copy(state), steps, np.ones(1, bool))
    iterations = int(steps.sum()) // BOUNDED.td3.update_every
    assert iterations >= 40 and int(metrics["iterations"]) == iterations
    assert int(trained.updates) == int(state.updates) + iterations
    changed = jax.tree.map(
        lambda a, b: bool(np.any(a != b)), state.agent.critic, trained.agent.critic
    )
    assert all(jax.tree.leaves(changed))
    shapes = []  # traced only: each iteration's batch
    trainer = programs.trainer
    fused_update = trainer.td3.fused_update

    def recording(agent, batch, *args):
        shapes.append((batch.obs.shape, batch.action.shape, batch.reward.shape))
        return fused_update(agent, batch, *args)

    trainer.td3 = trainer.td3._replace(fused_update=recording)
    try:
        jax.eval_shape(trainer.train, state, steps)
    finally:
        trainer.td3 = trainer.td3._replace(fused_update=fused_update)
    n, batch = trainer.env.n_max, BOUNDED.td3.batch_size
    assert set(shapes) == {((1, batch, n, OBS_SIZE), (1, batch, n), (1, batch))}


def test_an_evaluation_of_its_own_equals_the_collection_s(bounded_rounds):
    # eval_envs: the evaluation's own program (no staging, no exploration); from the
    # same key and as many environments it runs the collection's evaluation episodes.
    programs, states, _ = bounded_rounds
    assert programs.trainer.config.eval_envs == BOUNDED.num_envs
    state = programs.lanes.place([jax.device_put(states[-1])])
    key = eval_key(0, 3, 0)
    ret, length = programs.evaluate(state, key[None])
    assert ret.shape == length.shape == (1, BOUNDED.num_envs)
    _, stats = _round(programs, unoptimised.copy(state), evaluate=True, key=key)
    assert np.all(length > 1) and len(np.unique(length)) > 1  # whole episodes, unequal
    np.testing.assert_array_equal(length.mean(axis=1), stats.episode_length)
    np.testing.assert_allclose(ret.mean(axis=1), stats.episode_return, rtol=1e-4)
