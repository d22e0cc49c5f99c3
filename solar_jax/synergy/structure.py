"""The synergy structure of one morphology: torso rule, membership, pooling, attention.

Everything is padded to ``N_max`` agents and ``K_max = N_max`` synergies: affinity
propagation finds at most N clusters, and the torso rule adds one only when the torso
shared a cluster (so there were at most N - 1). Agent 0 is the torso (algorithm.md §1).

The synergy count K is the length of ``exemplars``; everything derived follows it. A
structure cut to fewer synergy slots (``Synergy.with_slots``, at least K of them) gives
the networks the same numbers with fewer padded tokens: the update compiles a few such
slot counts (``slot_buckets``) and runs the smallest that holds K (the reference runs its
inter-synergy layers on the K tokens alone).
"""

from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from solar_jax.morphology.graph import hop_distances, validate_parents
from solar_jax.synergy.affinity_propagation import Clustering

_TORSO = 0


@struct.dataclass
class Synergy:
    """A clustering after the torso rule (algorithm.md §3); the rest is derived.

    Only integer labels and masks are stored (cheap to carry and checkpoint); the
    matrices the networks consume are properties computed on demand.
    """

    labels: jax.Array
    """``[N_max]`` int32: one-hot synergy of each agent (the torso alone in its own); -1 padded."""
    exemplars: jax.Array
    """``[K_max]`` int32: exemplar agent of each valid synergy (torso for its own); -1 after.
    Its length is the number of synergy slots every derived matrix has."""
    num_synergies: jax.Array
    """``[]`` int32."""
    torso_synergy: jax.Array
    """``[]`` int32: the synergy every real agent also belongs to."""
    agent_mask: jax.Array
    """``[N_max]`` bool."""

    def with_slots(self, slots: int) -> "Synergy":
        """The same structure with ``slots`` synergy slots (static; at least
        ``num_synergies``, which the caller guarantees): valid synergies keep their index,
        padded ones beyond ``slots`` are dropped."""
        return self.replace(exemplars=self.exemplars[..., :slots])

    @property
    def synergy_mask(self) -> jax.Array:
        """``[K_max]`` bool: valid synergies."""
        return jnp.arange(self.exemplars.shape[-1]) < self.num_synergies[..., None]

    @property
    def membership(self) -> jax.Array:
        """W ``[N_max, K_max]`` float32: one-hot labels, torso column all ones (real agents)."""
        k = jnp.arange(self.exemplars.shape[-1])
        one_hot = self.labels[..., :, None] == k
        torso_col = k == self.torso_synergy[..., None, None]
        return ((one_hot | torso_col) & self.agent_mask[..., :, None]).astype(jnp.float32)

    @property
    def pool_weights(self) -> jax.Array:
        """``[N_max, K_max]``: column k averages synergy k's members (torso: all real agents).

        Synergy token k = ``sum_i pool_weights[i, k] * h_i`` (algorithm.md §4, pooling);
        invalid columns are zero.
        """
        w = self.membership
        return w / jnp.maximum(w.sum(axis=-2, keepdims=True), 1.0)

    @property
    def attention_bias(self) -> jax.Array:
        """``[N_max, N_max]`` float32 log(Ŵ Ŵᵀ), Ŵ = W with L2-normalised rows (algorithm.md §4).

        0 within a synergy, log(1/√2) between the torso and others, log(1/2) across
        synergies. Entries involving padded agents are 0 (finite); mask padded keys
        with the agent mask.
        """
        w = self.membership
        w_hat = w / jnp.maximum(jnp.linalg.norm(w, axis=-1, keepdims=True), 1e-12)
        gram = jnp.matmul(w_hat, jnp.swapaxes(w_hat, -1, -2), precision="highest")
        pair = self.agent_mask[..., :, None] & self.agent_mask[..., None, :]
        return jnp.where(pair, jnp.log(jnp.where(pair, gram, 1.0)), 0.0)

    @property
    def hard_mask(self) -> jax.Array:
        """``[N_max, N_max]`` bool, the paper-text variant: False across synergies.

        True where the soft bias is above log(1/2): same synergy, or either agent is the
        torso. False for padded agents.
        """
        li = self.labels[..., :, None]
        lj = self.labels[..., None, :]
        ts = self.torso_synergy[..., None, None]
        pair = self.agent_mask[..., :, None] & self.agent_mask[..., None, :]
        return pair & ((li == lj) | (li == ts) | (lj == ts))


def synergy_structure(clustering: Clustering, agent_mask: jax.Array) -> Synergy:
    """Applies the torso rule to a clustering (algorithm.md §3).

    If the torso shares its cluster with others it moves to a new last cluster of its
    own, with itself as exemplar; the old cluster keeps its exemplar, even when that was
    the torso. A torso already alone keeps its cluster, which becomes the torso synergy.
    """
    agent_mask = jnp.asarray(agent_mask, bool)
    labels, exemplars, k = clustering.labels, clustering.exemplars, clustering.num_clusters
    n_max = labels.shape[-1]
    idx = jnp.arange(n_max)
    torso_label = labels[_TORSO]
    shares = jnp.sum((labels == torso_label) & agent_mask) > 1
    labels = jnp.where(shares & (idx == _TORSO), k, labels)
    exemplars = jnp.where(shares & (idx == k), _TORSO, exemplars)
    return Synergy(
        labels=jnp.where(agent_mask, labels, -1).astype(jnp.int32),
        exemplars=exemplars.astype(jnp.int32),
        num_synergies=(k + shares).astype(jnp.int32),
        torso_synergy=jnp.where(shares, k, torso_label).astype(jnp.int32),
        agent_mask=agent_mask,
    )


def slot_buckets(n_max: int, count: int) -> tuple[int, ...]:
    """The synergy slot counts an update is compiled for, ascending, the last ``n_max``.

    ``count`` buckets split the range of K, 2 (the torso rule's least, with two or more
    agents) to ``n_max``, evenly: ``n_max = 9``: 1 -> (9,), 2 -> (6, 9), 3 -> (5, 7, 9),
    7 -> (3, 4, ..., 9); ``n_max = 7``, 3 -> (4, 6, 7); ``n_max = 3``, 3 -> (3,).
    """
    if count < 1:
        raise ValueError(f"synergy_buckets must be >= 1, got {count}")
    span = max(n_max - 2, 0)
    sizes = {min(n_max, 2 + -(-span * i // count)) for i in range(1, count)}
    return tuple(sorted(sizes | {n_max}))


def slot_bucket(num_synergies: jax.Array, buckets: Sequence[int]) -> jax.Array:
    """``[]`` int32 index of the smallest of ``buckets`` (ascending) holding
    ``num_synergies`` synergies (``[]`` or ``[M]``: the largest of them)."""
    k = jnp.max(num_synergies)
    return jnp.searchsorted(jnp.asarray(buckets, jnp.int32), k, side="left").astype(jnp.int32)


def padded_affinity(
    parents: Sequence[int], n_max: int, dtype=np.float32
) -> tuple[np.ndarray, np.ndarray]:
    """Affinity exp(-D) of a morphology's hop distances, padded (algorithm.md §3).

    Returns (similarity ``[n_max, n_max]`` in ``dtype``, zero where padded; mask
    ``[n_max]`` bool). Host-side NumPy: parents are static facts of a morphology. Use
    float64 to cluster exactly as scikit-learn does.
    """
    parents = validate_parents(parents)
    n = len(parents)
    if n > n_max:
        raise ValueError(f"morphology has {n} agents, more than n_max = {n_max}")
    similarity = np.zeros((n_max, n_max), dtype)
    similarity[:n, :n] = np.exp(-hop_distances(parents).astype(np.float64))
    return similarity, np.arange(n_max) < n
