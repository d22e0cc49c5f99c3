"""Synergy discovery (algorithm.md §3): affinity propagation in JAX, structure, ΔQ.

Per morphology: ``padded_affinity`` (exp(-D)), a preference (the median by default, then
``delta_q_preference``), ``affinity_propagation``, then ``synergy_structure`` (torso rule)
whose properties give the membership, pooling weights and attention masks. Run the
clustering in float64 (``jax.enable_x64``) to reproduce scikit-learn, hence the
reference, exactly; float32 breaks some exact ties differently.
"""

from solar_jax.synergy.affinity_propagation import (
    Clustering,
    affinity_propagation,
    sklearn_noise,
)
from solar_jax.synergy.preference import (
    PREFERENCE_SCALE,
    delta_q,
    delta_q_preference,
    preference_from_delta_q,
)
from solar_jax.synergy.structure import (
    Synergy,
    padded_affinity,
    slot_bucket,
    slot_buckets,
    synergy_structure,
)

__all__ = [
    "PREFERENCE_SCALE",
    "Clustering",
    "Synergy",
    "affinity_propagation",
    "delta_q",
    "delta_q_preference",
    "padded_affinity",
    "preference_from_delta_q",
    "sklearn_noise",
    "slot_bucket",
    "slot_buckets",
    "synergy_structure",
]
