"""scikit-learn as the oracle for the synergy tests, and random test problems."""

import warnings

import numpy as np
from sklearn.cluster import AffinityPropagation
from sklearn.exceptions import ConvergenceWarning

from solar_jax.morphology.graph import hop_distances


def sklearn_ap(similarity, preference, random_state, **kwargs):
    """(labels, exemplars, n_iter, converged) from scikit-learn on the float64 inputs."""
    ap = AffinityPropagation(
        affinity="precomputed", preference=preference, random_state=random_state, **kwargs
    )
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")  # degenerate and convergence warnings are expected
        ap.fit(np.array(similarity, np.float64))
    converged = not any(issubclass(w.category, ConvergenceWarning) for w in caught)
    centres = np.asarray(ap.cluster_centers_indices_, np.int64)
    return ap.labels_, centres, ap.n_iter_, converged


def random_parents(rng: np.random.Generator, n: int) -> list[int]:
    """A uniform-ish random pre-order tree: each body hangs off the path to the last one."""
    parents = [-1]
    for i in range(1, n):
        path, a = [], i - 1
        while a != -1:
            path.append(a)
            a = parents[a]
        parents.append(int(rng.choice(path)))
    return parents


def tree_affinity(parents) -> np.ndarray:
    """exp(-D), float64 ``[n, n]`` (algorithm.md §3)."""
    return np.exp(-hop_distances(parents).astype(np.float64))


FAMILIES = ("tree_median", "tree_dq", "tree_uniform", "dense_points", "integer_ties")


def random_case(rng: np.random.Generator, n: int, family: str):
    """(similarity [n, n] float64, preference [n] float64 or None) for one family."""
    if family.startswith("tree"):
        s = tree_affinity(random_parents(rng, n))
        if family == "tree_median":
            return s, None
        if family == "tree_dq":  # ΔQ-like: 1.2 * softmax of random values
            z = rng.normal(size=n) * rng.uniform(0.0, 3.0)
            return s, 1.2 * np.exp(z - z.max()) / np.exp(z - z.max()).sum()
        return s, np.full(n, 1.2 / n)
    if family == "dense_points":  # scikit-learn's usual -squared distances, no ties
        x = rng.normal(size=(n, 2))
        s = -((x[:, None] - x[None]) ** 2).sum(-1)
        return s, (None if rng.random() < 0.5 else rng.uniform(s.min(), 0.0, size=n))
    # Small integers: exact ties everywhere, zeros included, not symmetric.
    return rng.integers(-3, 1, size=(n, n)).astype(np.float64), rng.integers(-3, 1, n) * 1.0
