"""Synergy discovery for every morphology of a suite at once (algorithm.md §3).

The similarity exp(-D) is a constant of the suite; the preference is the median (the
first clustering, and always for methods without ΔQ) or 1.2 · softmax(ΔQ). Affinity
propagation runs in float64 inside a nested ``jax.enable_x64`` block, so the trainer's
jitted float32 round clusters exactly as scikit-learn (hence the reference) does;
float32 would break some of the trees' exact ties differently.
"""

from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np

from solar_jax.synergy.affinity_propagation import affinity_propagation
from solar_jax.synergy.structure import Synergy, padded_affinity, synergy_structure


class SuiteAffinity:
    """The padded similarities ``[M, N_max, N_max]`` (float64) and masks of a suite."""

    def __init__(self, parents: Sequence[Sequence[int]], n_max: int):
        pairs = [padded_affinity(p, n_max, np.float64) for p in parents]
        self.similarity = np.stack([s for s, _ in pairs])
        self.mask = np.stack([m for _, m in pairs])

    def cluster(self, preference: jax.Array | None = None) -> Synergy:
        """Clusters every morphology; ``preference [M, N_max]`` or None for the median.

        Traceable (jit, vmap over seeds); float inputs are cast to float64 inside.
        """
        with jax.enable_x64(True):
            similarity = jnp.asarray(self.similarity, jnp.float64)
            mask = jnp.asarray(self.mask)
            if preference is None:
                clusterings = jax.vmap(lambda s, m: affinity_propagation(s, None, m))(
                    similarity, mask
                )
            else:
                preference = jnp.asarray(preference).astype(jnp.float64)
                clusterings = jax.vmap(affinity_propagation)(similarity, preference, mask)
            synergy = jax.vmap(synergy_structure)(clusterings, mask)
        return jax.tree.map(_to_32_bit, synergy)

    def cluster_one(self, morph: jax.Array, preference: jax.Array) -> Synergy:
        """Clusters one morphology (``morph``: a traced index) with ``preference [N_max]``:
        the sequential update's re-clustering, just before that morphology's block."""
        with jax.enable_x64(True):
            similarity = jnp.asarray(self.similarity, jnp.float64)[morph]
            mask = jnp.asarray(self.mask)[morph]
            preference = jnp.asarray(preference).astype(jnp.float64)
            synergy = synergy_structure(affinity_propagation(similarity, preference, mask), mask)
        return jax.tree.map(_to_32_bit, synergy)


def _to_32_bit(x: jax.Array) -> jax.Array:
    return x.astype(jnp.int32) if jnp.issubdtype(x.dtype, jnp.integer) else x
