"""Synergy discovery (SPEC section 3): affinity propagation in JAX, structure, ΔQ."""

from solar_jax.synergy.affinity_propagation import (
    Clustering,
    affinity_propagation,
    sklearn_noise,
)

__all__ = ["Clustering", "affinity_propagation", "sklearn_noise"]
