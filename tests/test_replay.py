"""The on-device replay: masked writes, per-morphology ring overwrite, sampling."""

import jax
import jax.numpy as jnp
import numpy as np

from solar_jax.replay import Batch, add, append, grow, init_replay, sample, sample_each


def _batch(values: np.ndarray) -> Batch:
    """Rows tagged by value: ``values [M, B]`` fills every field of each row."""
    m, b = values.shape
    v = jnp.asarray(values, jnp.float32)
    return Batch(
        obs=jnp.broadcast_to(v[..., None, None], (m, b, 3, 2)),
        action=jnp.broadcast_to(v[..., None], (m, b, 3)),
        reward=v,
        next_obs=jnp.broadcast_to(-v[..., None, None], (m, b, 3, 2)),
        terminated=v > 100,
    )


def test_masked_writes_fill_each_morphology_at_its_own_rate_and_wrap():
    replay = init_replay(num_morphs=2, capacity=4, n_max=3, obs_size=2)
    add_jit = jax.jit(add)
    # Step 1: morphology 0 keeps rows 1 and 2, morphology 1 keeps row 0.
    replay = add_jit(
        replay, _batch(np.array([[1, 2, 3], [4, 5, 6]])), jnp.array([[0, 1, 1], [1, 0, 0]], bool)
    )
    np.testing.assert_array_equal(replay.size, [2, 1])
    np.testing.assert_array_equal(replay.position, [2, 1])
    np.testing.assert_array_equal(replay.reward[0, :2], [2, 3])
    np.testing.assert_array_equal(replay.reward[1, :1], [4])
    # Step 2: morphology 0 writes 3 more rows into 4 slots: the oldest (2) is overwritten.
    replay = add_jit(
        replay,
        _batch(np.array([[107, 108, 109], [0, 0, 0]])),
        jnp.array([[1, 1, 1], [0, 0, 0]], bool),
    )
    np.testing.assert_array_equal(replay.size, [4, 1])
    np.testing.assert_array_equal(replay.position, [1, 1])
    np.testing.assert_array_equal(replay.reward[0], [109, 3, 107, 108])
    np.testing.assert_array_equal(replay.terminated[0], [True, False, True, True])
    np.testing.assert_array_equal(replay.next_obs[0, :, 0, 0], [-109, -3, -107, -108])
    np.testing.assert_array_equal(replay.obs[0, :, 2, 1], [109, 3, 107, 108])
    np.testing.assert_array_equal(replay.reward[1], [4, 0, 0, 0])  # untouched


def test_sampling_reads_only_filled_slots_of_the_asked_morphology():
    replay = init_replay(num_morphs=2, capacity=8, n_max=3, obs_size=2)
    replay = add(
        replay, _batch(np.array([[1, 2, 3], [4, 5, 6]])), jnp.array([[1, 1, 1], [1, 1, 0]], bool)
    )
    batch = jax.jit(sample, static_argnums=3)(replay, jax.random.PRNGKey(0), jnp.int32(1), 200)
    assert set(np.unique(batch.reward)) == {4.0, 5.0}  # both, and never an empty slot
    np.testing.assert_array_equal(batch.obs[:, 0, 0], batch.reward)  # rows stay whole
    both = jax.jit(sample_each, static_argnums=3)(replay, jax.random.PRNGKey(1), jnp.arange(2), 50)
    assert both.obs.shape == (2, 50, 3, 2)
    assert set(np.unique(both.reward[0])) == {1.0, 2.0, 3.0}
    assert set(np.unique(both.reward[1])) == {4.0, 5.0}


def test_a_grown_ring_holds_and_samples_what_a_full_size_one_does():
    # trainer.replay_slots grows a ring that has not wrapped; from then on every write and
    # sample must be the full-size ring's (the run's results do not depend on it).
    rng = np.random.default_rng(0)
    small = init_replay(num_morphs=2, capacity=8, n_max=3, obs_size=2)
    full = init_replay(num_morphs=2, capacity=32, n_max=3, obs_size=2)
    for step in range(5):
        if step == 2:
            small = grow(small, 32)
        values = rng.integers(1, 99, (2, 3))
        mask = jnp.asarray(rng.random((2, 3)) < 0.7)
        small, full = add(small, _batch(values), mask), add(full, _batch(values), mask)
    assert small.capacity == 32
    jax.tree.map(np.testing.assert_array_equal, small, full)
    key = jax.random.PRNGKey(3)
    jax.tree.map(
        np.testing.assert_array_equal,
        sample_each(small, key, jnp.arange(2), 16),
        sample_each(full, key, jnp.arange(2), 16),
    )
    # Lane-stacked replays ([S, M, C, ...]) grow along their slot axis.
    stacked = jax.tree.map(lambda x: jnp.stack([x, x]), init_replay(2, 8, 3, 2))
    assert grow(stacked, 16).obs.shape == (2, 2, 16, 3, 2)


def test_appending_a_staged_round_equals_writing_it_directly():
    # A round collects into its own ring (the trainer's: num_envs x max_episode_steps
    # slots), then appends it: the replay must be what step-by-step writes would have
    # made, also when one round alone overfills the ring (only its newest rows stay).
    rng = np.random.default_rng(1)
    append_jit = jax.jit(append)
    overfilled = set()  # capacities that one round alone overfilled
    for capacity in (5, 8, 64):
        direct = init_replay(num_morphs=2, capacity=capacity, n_max=3, obs_size=2)
        appended = direct
        for _ in range(3):  # rounds of 4 steps of 3 environments
            staged = init_replay(num_morphs=2, capacity=4 * 3, n_max=3, obs_size=2)
            for _ in range(4):
                values = rng.integers(1, 200, (2, 3))
                mask = jnp.asarray(rng.random((2, 3)) < 0.8)
                direct = add(direct, _batch(values), mask)
                staged = add(staged, _batch(values), mask)
            appended = append_jit(appended, staged)
            jax.tree.map(np.testing.assert_array_equal, appended, direct)
            overfilled |= {capacity} if int(staged.size.max()) > capacity else set()
    assert overfilled == {5, 8}  # both cases were met: an overfilling and a roomy ring
