"""The training round's update phase on a suite with held-out robots (walker++)."""

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from solar_jax.config import TrainConfig
from solar_jax.replay import Replay
from solar_jax.training.trainer import Trainer, check_masks, replay_capacity, replay_slots
from tests import unoptimised

ITERS = 6  # per training morphology


@pytest.fixture(scope="module")
def walker_trainers() -> dict[str, Trainer]:
    # Two synergy-slot buckets, (5, 7), not the default three, (4, 6, 7): every switch
    # over buckets is the same code, and the update compiles in 13.9 s at -O0 instead of
    # 21.4 (a branch per bucket). The three buckets' choice is checked apart, untrained.
    base = dict(
        morph="walker++", net="tiny", total_steps=4000, replay_capacity=64, synergy_buckets=2
    )
    return {mode: Trainer(TrainConfig(update=mode, **base)) for mode in ("sequential", "fused")}


@functools.cache
def _train(trainer: Trainer):
    """``trainer.train`` at -O0, traced and compiled once for the module (tests of one
    trainer share it)."""
    return unoptimised.jit(trainer.train)


def _filled(trainer: Trainer, replay: Replay, held_out_value: float) -> Replay:
    """Every buffer full of random finite transitions; the held-out ones hold
    ``held_out_value`` (NaN: any read would poison the parameters)."""
    rng = np.random.default_rng(0)
    m, c = replay.reward.shape
    held_out = np.arange(m) >= trainer.num_train

    def fill(x):
        values = rng.uniform(-1, 1, x.shape).astype(np.float32)
        values[held_out] = held_out_value
        return jnp.asarray(values)

    return replay.replace(
        obs=fill(replay.obs),
        next_obs=fill(replay.next_obs),
        action=fill(replay.action),
        reward=fill(replay.reward),
        terminated=jnp.zeros((m, c), bool),
        size=jnp.full(m, c, jnp.int32),
    )


@pytest.mark.parametrize("mode", [pytest.param("sequential", marks=pytest.mark.slow), "fused"])
def test_held_out_morphologies_give_no_gradients(walker_trainers, mode):
    trainer = walker_trainers[mode]
    assert trainer.names[trainer.num_train :] == ("walker_3_main", "walker_6_main")
    state = trainer.init(0)
    state = state.replace(replay=_filled(trainer, state.replay, np.nan))
    # Counted steps of the round, held-out ones included: the reference divides their sum
    # by M_all = 6 (36 // 6 = ITERS), not the training ones' by M_train (12 // 4 = 3).
    steps = jnp.asarray([3, 3, 3, 3, 12, 12], jnp.int32)
    before = jax.tree.map(np.asarray, state.agent)
    synergy_before = jax.device_get(state.synergy)
    state, metrics = _train(trainer)(state, steps)
    for leaf in jax.tree.leaves(state.agent):
        assert np.all(np.isfinite(leaf))
    assert np.isfinite(metrics["critic_loss"]) and np.isfinite(metrics["actor_loss"])
    # ITERS iterations per training morphology.
    per_mode = {"sequential": ITERS * trainer.num_train, "fused": ITERS}
    assert int(metrics["iterations"]) == int(state.updates) == per_mode[mode]
    assert int(state.rounds) == 1
    changed = [
        not np.array_equal(a, b)
        for a, b in zip(jax.tree.leaves(before), jax.tree.leaves(state.agent), strict=True)
    ]
    assert any(changed)
    # Re-clustered from ΔQ: the first clustering is the median preference's, and ΔQ's
    # preference moves some training morphologies' synergies away from it (walker_5 and
    # walker_7 here, in both modes); without re-clustering every one would stay.
    synergy = jax.device_get(state.synergy)
    moved = [
        not np.array_equal(synergy.labels[i], synergy_before.labels[i])
        or not np.array_equal(synergy.exemplars[i], synergy_before.exemplars[i])
        for i in range(trainer.num_train)
    ]
    assert any(moved), "no training morphology was re-clustered"


def test_replay_ring_is_the_reference_s_and_allocated_as_it_fills():
    assert replay_capacity(TrainConfig(morph="humanoid++"), 8) == 1_000_000
    assert replay_capacity(TrainConfig(morph="whh++"), 17) == 588_235  # 1e7 / M_all
    assert replay_capacity(TrainConfig(total_steps=3000, replay_capacity=77), 1) == 77
    # Powers of two from twice one round's most writes (1000 per environment), always
    # more than the held transitions plus one round: no round can wrap a partial ring.
    config = TrainConfig(morph="hopper_3")
    assert [replay_slots(config, 1, size) for size in (0, 1047, 1048, 3000)] == [
        2048,
        2048,
        4096,
        4096,
    ]
    assert replay_slots(dataclasses.replace(config, num_envs=4), 1, 0) == 8192
    assert replay_slots(config, 1, 999_999) == 1_000_000  # the full ring, which wraps
    assert replay_slots(dataclasses.replace(config, replay_capacity=77), 1, 0) == 77  # whole


def test_sequential_blocks_run_in_sorted_name_order(walker_trainers):
    # algorithm.md §3: the reference re-clusters and trains morphology by morphology in
    # sorted-name order, held-out ones included (they get no block of iterations).
    trainer = walker_trainers["sequential"]
    order = [trainer.names[i] for i in np.asarray(trainer.update_order)]
    assert order == sorted(trainer.names) and order != list(trainer.names)


def test_a_trainer_refuses_an_env_whose_masks_differ_from_the_clustering_s(walker_trainers):
    trainer = walker_trainers["fused"]
    np.testing.assert_array_equal(trainer.env.agent_mask, trainer.affinity.mask)
    bad = trainer.env.agent_mask.copy()
    bad[1, bad[1].sum() - 1] = False  # the second robot loses its last agent
    with pytest.raises(ValueError, match=f"{trainer.names[1]}: the env's agent mask"):
        check_masks(trainer.names, bad, trainer.affinity.mask)
    with pytest.raises(ValueError, match="agent masks: env"):
        check_masks(trainer.names, bad[:, :-1], trainer.affinity.mask)


def test_each_block_runs_in_the_smallest_slot_bucket_holding_its_synergies(walker_trainers):
    fused = walker_trainers["fused"]
    trainer = Trainer(dataclasses.replace(fused.config, synergy_buckets=3), fused.env)
    assert trainer.env.n_max == 7 and trainer.slot_buckets == (4, 6, 7)
    structure = trainer.structure(trainer.init(0).synergy)

    def slots_used(num_synergies, lane_axis=None):
        s = structure.replace(synergy=structure.synergy.replace(num_synergies=num_synergies))
        return trainer._in_slot_bucket(
            s, lambda s, carry: carry + s.synergy.exemplars.shape[-1], jnp.int32(0), lane_axis
        )

    def with_k(k: int):  # one morphology of the block with K = k, the others K = 3
        return jnp.full(6, 3, jnp.int32).at[2].set(k)

    used = jax.jit(slots_used)
    assert [int(used(with_k(k))) for k in (2, 4, 5, 6, 7)] == [4, 4, 6, 6, 7]
    # Lanes share one branch, the largest K's: a per-lane index would run every branch.
    lanes = jax.jit(jax.vmap(functools.partial(slots_used, lane_axis="lane"), axis_name="lane"))
    np.testing.assert_array_equal(lanes(jnp.stack([with_k(2), with_k(4)])), [4, 4])
    np.testing.assert_array_equal(lanes(jnp.stack([with_k(2), with_k(5)])), [6, 6])


def test_a_round_in_a_small_slot_bucket_trains_as_with_all_slots(walker_trainers):
    bucketed = walker_trainers["fused"]
    config = dataclasses.replace(bucketed.config, synergy_buckets=1)
    all_slots = Trainer(config, bucketed.env)
    assert bucketed.slot_buckets == (5, 7) and all_slots.slot_buckets == (7,)
    state = bucketed.init(0)
    state = state.replace(replay=_filled(bucketed, state.replay, 0.0))
    steps = jnp.asarray([3, 3, 3, 3, 12, 12], jnp.int32)
    results = [_train(t)(state, steps) for t in (bucketed, all_slots)]
    (cut, cut_metrics), (full, full_metrics) = jax.device_get(results)
    # The re-clustered K fit a smaller bucket than N_max: the round ran a cut branch.
    assert int(np.max(cut.synergy.num_synergies[: bucketed.num_train])) <= 5
    np.testing.assert_array_equal(cut.synergy.labels, full.synergy.labels)
    close = functools.partial(np.testing.assert_allclose, rtol=1e-4, atol=1e-5)
    jax.tree.map(close, cut.agent, full.agent)
    close(cut_metrics["critic_loss"], full_metrics["critic_loss"])


def test_domain_randomisation_evaluates_the_nominal_robots():
    """``env.variation``: a round's environments start as variants drawn from each
    robot's pool, an evaluation's as the nominal robots (the pool's first)."""
    from solar_jax.cli import parse_config
    from solar_jax.training.trainer import Control
    from tests.tiny import ARGS

    config = parse_config([*ARGS, "env.variation=gear,armature", "env.variation_pool=8"])
    trainer = Trainer(config)
    assert trainer.env.num_variants == 8 and trainer.env.redraw

    @unoptimised.jit_physics
    def variants(evaluate, seed):
        flag, zero = jnp.asarray(evaluate), jnp.int32(0)
        control = Control(
            evaluate=flag, idle=jnp.asarray(False), start=flag, switch=zero, until=zero
        )
        key = jax.random.PRNGKey(seed)
        return trainer.part_start(0, key, key, control).env.worlds[0].variant

    drawn = np.stack([np.asarray(variants(False, seed)) for seed in range(4)])
    assert drawn.shape == (4, 2, 1) and ((0 <= drawn) & (drawn < 8)).all()
    assert len(np.unique(drawn)) > 2  # drawn, not fixed
    for seed in range(4):
        np.testing.assert_array_equal(variants(True, seed), 0)
