"""Torso rule, membership, pooling and attention masks; the algorithm.md §3 fixtures."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from solar_jax.morphology.graph import hop_distances
from solar_jax.synergy import (
    Clustering,
    affinity_propagation,
    padded_affinity,
    slot_bucket,
    slot_buckets,
    synergy_structure,
)

N_MAX = 9

# algorithm.md §3: labels / exemplars after the torso rule. "median": the first
# clustering's preference; "uniform": 1.2 / N. scikit-learn gives these with
# random_state=0, the default noise here.
FIXTURES = {
    "walker_7_main": ((-1, 0, 1, 2, 0, 4, 5), "median", [2, 0, 0, 0, 1, 1, 1], [1, 5, 0]),
    "humanoid_2d_9_full": (
        (-1, 0, 1, 0, 3, 0, 5, 0, 7),
        "median",
        [4, 0, 0, 1, 1, 2, 2, 3, 3],
        [2, 3, 6, 7, 0],
    ),
    "hopper_4": ((-1, 0, 1, 2), "median", [2, 0, 1, 1], [0, 3, 0]),
    "walker_3_main": ((-1, 0, 0), "median", [1, 0, 0], [0, 0]),
    "humanoid_2d_8_left_knee": (
        (-1, 0, 1, 0, 0, 4, 0, 6),
        "median",
        [1, 0, 0, 0, 0, 0, 0, 0],
        [0, 0],
    ),
    "humanoid_2d_9_full/uniform": (
        (-1, 0, 1, 0, 3, 0, 5, 0, 7),
        "uniform",
        [4, 0, 0, 1, 1, 2, 2, 3, 3],
        [1, 3, 5, 7, 0],
    ),
    "hopper_5/uniform": ((-1, 0, 1, 2, 3), "uniform", [2, 0, 0, 1, 1], [1, 3, 0]),
}


@functools.cache
def _discover_all(n_max: int, dtype) -> dict:
    """Affinity propagation on exp(-D) padded to n_max, then the torso rule, for every
    fixture: one vmapped call per preference kind. Returns name -> (Clustering, Synergy)."""
    out = {}
    for kind in ("median", "uniform"):
        names = [name for name, f in FIXTURES.items() if f[1] == kind]
        sims, masks, prefs = [], [], []
        for name in names:
            parents = FIXTURES[name][0]
            s, m = padded_affinity(parents, n_max, dtype)
            sims.append(s)
            masks.append(m)
            prefs.append(np.where(m, 1.2 / len(parents), 0.0).astype(dtype))
        pref = None if kind == "median" else np.stack(prefs)

        @jax.jit
        @functools.partial(jax.vmap, in_axes=(0, None if pref is None else 0, 0))
        def discover(s, p, m):
            clustering = affinity_propagation(s, p, m)
            return clustering, synergy_structure(clustering, m)

        with jax.enable_x64(dtype == np.float64):
            clusterings, synergies = jax.device_get(discover(np.stack(sims), pref, np.stack(masks)))
        for b, name in enumerate(names):
            out[name] = jax.tree.map(lambda x, b=b: x[b], (clusterings, synergies))
    return out


@pytest.mark.parametrize("name", FIXTURES)
def test_spec_fixtures_in_float64(name):
    parents, _, labels, exemplars = FIXTURES[name]
    n = len(parents)
    _, syn = _discover_all(N_MAX, np.float64)[name]
    assert syn.labels[:n].tolist() == labels
    assert (syn.labels[n:] == -1).all()
    k = int(syn.num_synergies)
    assert syn.exemplars[:k].tolist() == exemplars
    assert (syn.exemplars[k:] == -1).all()


@pytest.mark.parametrize("name", FIXTURES)
def test_spec_fixtures_in_float32_up_to_exact_ties(name):
    """float32 gives the fixtures' partitions; an exemplar may be another member whose
    within-cluster similarity sum ties exactly (3 of 7 fixtures): float32 rounding, not
    the noise, decides such a tie (see the affinity propagation module docstring)."""
    parents, kind, labels, _ = FIXTURES[name]
    n = len(parents)
    ours, syn = _discover_all(N_MAX, np.float32)[name]
    assert syn.labels[:n].tolist() == labels
    ref, _ = _discover_all(N_MAX, np.float64)[name]
    np.testing.assert_array_equal(ours.labels, ref.labels)
    # Noise-free S with the preference on the diagonal, in float64.
    s = np.exp(-hop_distances(parents).astype(np.float64))
    np.fill_diagonal(s, np.median(s) if kind == "median" else 1.2 / n)
    for k in range(int(ref.num_clusters)):
        members = np.flatnonzero(np.asarray(ref.labels[:n]) == k)
        mine, theirs = int(ours.exemplars[k]), int(ref.exemplars[k])
        assert mine in members
        np.testing.assert_allclose(s[members, mine].sum(), s[members, theirs].sum(), rtol=1e-12)


def _clustering(labels, exemplars, n_max=6):
    labels = np.asarray(labels + [-1] * (n_max - len(labels)), np.int32)
    k = len(exemplars)
    exemplars = np.asarray(exemplars + [-1] * (n_max - k), np.int32)
    false = jnp.bool_(False)
    return Clustering(labels, exemplars, jnp.int32(k), jnp.bool_(True), jnp.int32(20), false, false)


def test_torso_rule_moves_a_shared_torso_to_a_new_last_synergy():
    mask = np.arange(6) < 4
    syn = synergy_structure(_clustering([0, 0, 1, 1], [0, 3]), mask)  # hopper_4-like
    assert syn.labels.tolist() == [2, 0, 1, 1, -1, -1]
    assert syn.exemplars.tolist() == [0, 3, 0, -1, -1, -1]  # cluster 0 keeps the torso
    assert int(syn.num_synergies) == 3 and int(syn.torso_synergy) == 2


def test_torso_rule_keeps_a_torso_alone():
    mask = np.arange(6) < 3
    syn = synergy_structure(_clustering([0, 1, 1], [0, 2]), mask)
    assert syn.labels.tolist() == [0, 1, 1, -1, -1, -1]
    assert syn.exemplars.tolist() == [0, 2, -1, -1, -1, -1]
    assert int(syn.num_synergies) == 2 and int(syn.torso_synergy) == 0


@pytest.fixture
def walker_7():
    """walker_7_main's fixture structure padded to 9 agents: synergies {1,2,3} {4,5,6} {0}."""
    mask = np.arange(N_MAX) < 7
    labels = [0, 0, 0, 0, 1, 1, 1]
    return synergy_structure(_clustering(labels, [1, 5], N_MAX), mask)


def test_membership_and_synergy_mask(walker_7):
    w = np.asarray(walker_7.membership)
    expected = np.zeros((N_MAX, N_MAX), np.float32)
    expected[[1, 2, 3], 0] = 1
    expected[[4, 5, 6], 1] = 1
    expected[:7, 2] = 1  # torso synergy: every real agent
    np.testing.assert_array_equal(w, expected)
    assert walker_7.synergy_mask.tolist() == [True] * 3 + [False] * 6


def test_pool_weights_are_member_means(walker_7):
    h = np.random.default_rng(0).normal(size=(N_MAX, 5)).astype(np.float32)
    pooled = np.asarray(walker_7.pool_weights).T @ h
    np.testing.assert_allclose(pooled[0], h[[1, 2, 3]].mean(0), rtol=1e-6)
    np.testing.assert_allclose(pooled[1], h[[4, 5, 6]].mean(0), rtol=1e-6)
    np.testing.assert_allclose(pooled[2], h[:7].mean(0), rtol=1e-6)  # global mean
    np.testing.assert_array_equal(pooled[3:], 0)


def test_attention_bias_values(walker_7):
    bias = np.asarray(walker_7.attention_bias)
    assert np.isfinite(bias).all()
    legs = [[1, 2, 3], [4, 5, 6]]
    for a in legs:
        for b in legs:
            value = 0.0 if a == b else np.log(0.5)
            np.testing.assert_allclose(bias[np.ix_(a, b)], value, atol=1e-6)
    np.testing.assert_allclose(bias[0, 1:7], np.log(1 / np.sqrt(2)), atol=1e-6)
    np.testing.assert_allclose(bias[1:7, 0], np.log(1 / np.sqrt(2)), atol=1e-6)
    assert bias[0, 0] == 0
    assert (bias[7:] == 0).all() and (bias[:, 7:] == 0).all()  # padded: finite zeros
    # The definition: log(Ŵ Ŵᵀ) with W's rows L2-normalised (real block).
    w = np.asarray(walker_7.membership)[:7]
    w_hat = w / np.linalg.norm(w, axis=1, keepdims=True)
    np.testing.assert_allclose(bias[:7, :7], np.log(w_hat @ w_hat.T), atol=1e-6)


def test_hard_mask_blocks_exactly_across_synergies(walker_7):
    hard = np.asarray(walker_7.hard_mask)
    bias = np.asarray(walker_7.attention_bias)
    real = np.zeros((N_MAX, N_MAX), bool)
    real[:7, :7] = True
    np.testing.assert_array_equal(hard, real & ~np.isclose(bias, np.log(0.5)))


def test_fewer_slots_keep_every_valid_synergy_s_matrices(walker_7):
    cut = walker_7.with_slots(4)  # K = 3 of 9 slots
    assert cut.synergy_mask.tolist() == [True] * 3 + [False]
    for name in ("membership", "pool_weights"):
        np.testing.assert_array_equal(getattr(cut, name), getattr(walker_7, name)[:, :4], name)
    for name in ("labels", "attention_bias", "hard_mask"):  # agent by agent: unchanged
        np.testing.assert_array_equal(getattr(cut, name), getattr(walker_7, name), name)


def test_slot_buckets_split_the_range_of_k_evenly():
    assert [slot_buckets(9, count) for count in (1, 2, 3)] == [(9,), (6, 9), (5, 7, 9)]
    assert slot_buckets(9, 7) == (3, 4, 5, 6, 7, 8, 9)  # K >= 2: the torso rule's least
    assert slot_buckets(9, 20) == (3, 4, 5, 6, 7, 8, 9)  # never more than there are counts
    assert slot_buckets(7, 3) == (4, 6, 7) and slot_buckets(3, 3) == (3,)
    with pytest.raises(ValueError, match="synergy_buckets"):
        slot_buckets(9, 0)
    # The smallest bucket holding K (of a stack of morphologies: the largest K).
    index = jax.jit(slot_bucket, static_argnums=1)
    expected = [0, 0, 0, 0, 0, 1, 1, 2, 2]  # K = 1 .. 9 in buckets (5, 7, 9)
    assert [int(index(jnp.int32(k), (5, 7, 9))) for k in range(1, 10)] == expected
    assert int(index(jnp.asarray([2, 6, 3], jnp.int32), (5, 7, 9))) == 1


def test_structure_is_vmappable():
    """vmap the torso rule over morphologies; properties work on the batched struct."""
    clusterings = [
        _clustering([0, 0, 0, 0, 1, 1, 1], [1, 5], N_MAX),  # walker_7: torso shares
        _clustering([0, 1, 1, 2, 2], [0, 2, 4], N_MAX),  # torso alone
        _clustering([0, 0, 0], [0], N_MAX),  # one cluster
    ]
    masks = np.stack([np.arange(N_MAX) < n for n in (7, 5, 3)])
    stacked = jax.tree.map(lambda *x: np.stack(x), *clusterings)
    batch = jax.jit(jax.vmap(synergy_structure))(stacked, masks)
    for b, (c, m) in enumerate(zip(clusterings, masks, strict=True)):
        one = synergy_structure(c, m)
        for name in ("labels", "membership", "pool_weights", "attention_bias", "hard_mask"):
            np.testing.assert_array_equal(getattr(batch, name)[b], getattr(one, name), name)


def test_padded_affinity():
    similarity, mask = padded_affinity((-1, 0, 1, 0), 6)
    assert similarity.shape == (6, 6) and similarity.dtype == np.float32
    s64, _ = padded_affinity((-1, 0, 1, 0), 6, np.float64)
    assert s64.dtype == np.float64 and s64[0, 2] == np.exp(-2.0)
    assert mask.tolist() == [True] * 4 + [False] * 2
    d = hop_distances((-1, 0, 1, 0))
    np.testing.assert_allclose(similarity[:4, :4], np.exp(-d), rtol=1e-7)
    assert (similarity[4:] == 0).all() and (similarity[:, 4:] == 0).all()
    with pytest.raises(ValueError, match="n_max"):
        padded_affinity((-1, 0, 1, 0), 3)
