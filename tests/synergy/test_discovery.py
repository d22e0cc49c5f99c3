"""Clustering a whole suite inside a float32 jit, in float64 (nested ``enable_x64``)."""

import jax
import jax.numpy as jnp
import numpy as np

from solar_jax.morphology import load
from solar_jax.synergy.discovery import SuiteAffinity
from tests import unoptimised

# algorithm.md §3 fixtures (labels / exemplars after the torso rule), median preference.
MEDIAN = {
    "walker_7_main": ([2, 0, 0, 0, 1, 1, 1], [1, 5, 0]),
    "humanoid_2d_9_full": ([4, 0, 0, 1, 1, 2, 2, 3, 3], [2, 3, 6, 7, 0]),
    "hopper_4": ([2, 0, 1, 1], [0, 3, 0]),
    "walker_3_main": ([1, 0, 0], [0, 0]),
    "humanoid_2d_8_left_knee": ([1, 0, 0, 0, 0, 0, 0, 0], [0, 0]),
}
# With the uniform preference 1.2 / N (what ΔQ = 0 gives): 1.2 · softmax(0).
UNIFORM = {
    "humanoid_2d_9_full": ([4, 0, 0, 1, 1, 2, 2, 3, 3], [1, 3, 5, 7, 0]),
    "hopper_5": ([2, 0, 0, 1, 1], [1, 3, 0]),
}


def _check(synergy, fixtures):
    for i, (labels, exemplars) in enumerate(fixtures.values()):
        n, k = len(labels), len(exemplars)
        np.testing.assert_array_equal(synergy.labels[i, :n], labels)
        np.testing.assert_array_equal(synergy.labels[i, n:], -1)
        np.testing.assert_array_equal(synergy.exemplars[i, :k], exemplars)
        assert int(synergy.num_synergies[i]) == k
    assert synergy.labels.dtype == jnp.int32


def test_median_fixtures_inside_a_float32_jit():
    suite = SuiteAffinity([load(name).parents for name in MEDIAN], n_max=9)
    synergy = jax.jit(lambda x: (x * 2.0, suite.cluster()))(jnp.float32(1.0))[1]
    _check(synergy, MEDIAN)


def test_uniform_preference_fixtures():
    """algorithm.md §3's uniform-preference fixtures use 1.2 / N in float64."""
    suite = SuiteAffinity([load(name).parents for name in UNIFORM], n_max=9)
    n = suite.mask.sum(axis=1, keepdims=True)
    with jax.enable_x64(True):  # the preference enters the jit in float64
        synergy = unoptimised.jit(suite.cluster)(np.where(suite.mask, 1.2 / n, 0.0))
    _check(synergy, UNIFORM)


def test_float32_delta_q_preference_clusters_as_scikit_learn():
    """The trainer's path: ΔQ and the softmax in float32 (as the reference's torch code),
    the clustering in float64. 1.2 · softmax(0) rounded to float32 differs from 1.2 / N
    in float64 by an ulp, which breaks humanoid_2d_9_full's exact tie the other way; the
    answer is scikit-learn's for that same float32 preference."""
    from sklearn.cluster import AffinityPropagation

    names = list(UNIFORM)
    suite = SuiteAffinity([load(name).parents for name in names], n_max=9)
    mask = jnp.asarray(suite.mask)

    @jax.jit
    def from_delta_q(delta_q):
        logits = jnp.where(mask, delta_q, -jnp.inf)
        preference = jnp.where(mask, 1.2 * jax.nn.softmax(logits, axis=-1), 0.0)
        return preference, suite.cluster(preference)

    preference, synergy = from_delta_q(jnp.zeros((2, 9), jnp.float32))
    for i in range(len(names)):
        n = int(suite.mask[i].sum())
        ap = AffinityPropagation(
            affinity="precomputed",
            preference=np.asarray(preference[i, :n], np.float64),
            random_state=0,
        ).fit(suite.similarity[i, :n, :n])
        # scikit-learn's clusters before the torso rule: compare as partitions + exemplars.
        ours = np.asarray(synergy.labels[i, :n])
        same_cluster = ours[:, None] == ours[None, :]
        theirs = ap.labels_[:, None] == ap.labels_[None, :]
        np.testing.assert_array_equal(same_cluster[1:, 1:], theirs[1:, 1:])
        exemplars = set(np.asarray(synergy.exemplars[i, : int(synergy.num_synergies[i])]).tolist())
        assert exemplars - {0} == set(ap.cluster_centers_indices_.tolist()) - {0}
