"""Synergy discovery (SPEC section 3): affinity propagation in JAX, structure, ΔQ.

Per morphology: ``padded_affinity`` (exp(-D)), a preference (the median by default, then
``delta_q_preference``), ``affinity_propagation``, then ``synergy_structure`` (torso rule)
whose properties give the membership, pooling weights and attention masks.
"""

from solar_jax.synergy.affinity_propagation import Clustering, affinity_propagation
from solar_jax.synergy.preference import (
    PREFERENCE_SCALE,
    delta_q,
    delta_q_preference,
    preference_from_delta_q,
)
from solar_jax.synergy.structure import Synergy, padded_affinity, synergy_structure

__all__ = [
    "PREFERENCE_SCALE",
    "Clustering",
    "Synergy",
    "affinity_propagation",
    "delta_q",
    "delta_q_preference",
    "padded_affinity",
    "preference_from_delta_q",
    "synergy_structure",
]
