"""Affinity propagation against scikit-learn (algorithm.md §3).

1140 random problems (sizes 2-20, five families, many exact ties), all padded to 20
points with garbage in the padding and solved in a few vmapped calls:
- float64 with scikit-learn's noise: bit-for-bit the same labels, exemplars, iteration
  count and convergence flag, except where XLA flushes subnormals (counted);
- float32 (the default dtype): the same partition and exemplars in 97% of the
  converged cases. The rest are exact ties (tree affinities tie everywhere) that
  float32 rounding breaks the other way: scikit-learn itself returns our answer for
  another ``random_state``, except in problems with exact zeros (subnormals again).
"""

import dataclasses
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from solar_jax.synergy import affinity_propagation
from solar_jax.synergy.affinity_propagation import sklearn_noise
from tests import unoptimised
from tests.synergy.oracle import FAMILIES, random_case, random_parents, sklearn_ap, tree_affinity

N_MAX = 20
SIZES = range(2, 21)
PER_SIZE = 60
# float32 mismatches (converged cases) measured 34 of 1129 (3.0%: 16 exemplar-only, 18
# partition); the bound leaves little room.
MAX_FLOAT32_MISMATCH_RATE = 0.035
# How many other random_states to try when explaining a float32 mismatch as a tie.
EXPLAIN_SEEDS = 200


@dataclasses.dataclass(frozen=True)
class Case:
    n: int
    family: str
    similarity: np.ndarray  # [n, n] float64
    preference: np.ndarray | None  # [n] float64, None for the median
    seed: int  # scikit-learn's random_state


@pytest.fixture(scope="module")
def cases() -> list[Case]:
    rng = np.random.default_rng(2022)
    out = []
    for n in SIZES:
        for c in range(PER_SIZE):
            family = FAMILIES[c % len(FAMILIES)]
            s, p = random_case(rng, n, family)
            out.append(Case(n, family, s, p, int(rng.integers(2**31))))
    return out


@pytest.fixture(scope="module")
def sklearn_results(cases):
    return [sklearn_ap(c.similarity, c.preference, c.seed) for c in cases]


def _pad(x: np.ndarray, n_max: int, fill) -> np.ndarray:
    out = np.full((n_max,) * x.ndim, fill, x.dtype)
    out[tuple(slice(0, d) for d in x.shape)] = x
    return out


def _solve_all(cases: list[Case], dtype, noise=None) -> list[tuple]:
    """Our (labels, exemplars, n_iter, converged) per case, in two vmapped calls."""
    noise = noise or (lambda c: sklearn_noise(c.seed, N_MAX * N_MAX))
    results: list[tuple | None] = [None] * len(cases)
    for median in (True, False):
        group = [i for i, c in enumerate(cases) if (c.preference is None) == median]
        garbage = [np.nan, np.inf, -1e30, 7.0]  # padded contents must not matter
        sim = [_pad(cases[i].similarity, N_MAX, garbage[i % 4]) for i in group]
        sim = np.stack(sim).astype(dtype)
        mask = np.stack([np.arange(N_MAX) < cases[i].n for i in group])
        z = np.stack([noise(cases[i]) for i in group]).astype(dtype)
        if median:
            median_ap = jax.vmap(lambda s, m, z: affinity_propagation(s, None, m, noise=z))
            out = unoptimised.jit(median_ap)(sim, mask, z)
        else:
            pref = np.stack([_pad(cases[i].preference, N_MAX, np.nan) for i in group])
            given_ap = jax.vmap(lambda s, p, m, z: affinity_propagation(s, p, m, noise=z))
            out = unoptimised.jit(given_ap)(sim, pref.astype(dtype), mask, z)
        out = jax.device_get(out)
        for row, i in enumerate(group):
            n, k = cases[i].n, out.num_clusters[row]
            assert (out.labels[row, n:] == -1).all() and (out.exemplars[row, k:] == -1).all()
            results[i] = (
                out.labels[row, :n],
                out.exemplars[row, :k],
                int(out.n_iter[row]),
                bool(out.converged[row]),
            )
    return results


def _has_zero(case: Case) -> bool:
    pref = np.median(case.similarity) if case.preference is None else case.preference
    return bool((case.similarity == 0).any() or (pref == 0).any())


def _same_partition(ours, theirs) -> bool:
    return np.array_equal(ours[0], theirs[0]) and np.array_equal(ours[1], theirs[1])


def _is_sklearn_outcome(case: Case, ours, skip: int) -> bool:
    """True if scikit-learn returns our answer for some other random_state."""
    for seed in range(EXPLAIN_SEEDS):
        if seed != skip and _same_partition(
            ours, sklearn_ap(case.similarity, case.preference, seed)
        ):
            return True
    return False


def test_float64_matches_sklearn_bit_for_bit(cases, sklearn_results):
    with jax.enable_x64(True):
        ours = _solve_all(cases, np.float64)
    exceptions = []
    for i, (mine, theirs) in enumerate(zip(ours, sklearn_results, strict=True)):
        same = _same_partition(mine, theirs) and mine[2:] == (theirs[2], theirs[3])
        if not same:
            exceptions.append(i)
    # The only exceptions: real blocks with exact zeros, whose noise is 100 * tiny * N(0,1)
    # (~1e-306): the messages then pass through subnormals, which XLA on CPU flushes to
    # zero and NumPy keeps. Measured: 2 of 1140 ("integer_ties"): one stops one iteration
    # later with the same partition; in the other an evidence of 1.8e-308 makes an
    # exemplar for NumPy and 0 for XLA (one cluster fewer).
    for i in exceptions:
        assert _has_zero(cases[i]), (i, cases[i])
    assert len(exceptions) <= 5, exceptions
    assert sum(r[3] for r in sklearn_results) >= 0.95 * len(cases)


def test_float32_matches_sklearn_up_to_ties(cases, sklearn_results):
    ours = _solve_all(cases, np.float32)
    converged = [i for i, r in enumerate(sklearn_results) if r[3]]
    mismatches = [i for i in converged if not _same_partition(ours[i], sklearn_results[i])]
    assert len(mismatches) <= MAX_FLOAT32_MISMATCH_RATE * len(converged), len(mismatches)
    unexplained = [i for i in mismatches if not _is_sklearn_outcome(cases[i], ours[i], -1)]
    # Measured: 2, both "integer_ties" problems with zeros (subnormals, as in float64).
    for i in unexplained:
        assert _has_zero(cases[i]), (i, cases[i])
    assert len(unexplained) <= 3, unexplained


@pytest.mark.slow
def test_other_noise_disagrees_no_more_than_sklearn_with_itself(cases, sklearn_results):
    """A JAX noise stream breaks ties differently, as another random_state would."""
    key = jax.random.key(0)

    def jax_noise(c):
        return np.asarray(jax.random.normal(jax.random.fold_in(key, c.seed), (N_MAX * N_MAX,)))

    ours = _solve_all(cases, np.float32, noise=jax_noise)
    converged = [i for i, r in enumerate(sklearn_results) if r[3]]
    ours_differ = sum(not _same_partition(ours[i], sklearn_results[i]) for i in converged)
    sklearn_differs = sum(
        not _same_partition(
            sklearn_ap(cases[i].similarity, cases[i].preference, cases[i].seed + 1),
            sklearn_results[i],
        )
        for i in converged
    )
    print(f"converged {len(converged)}: ours {ours_differ}, sklearn seed+1 {sklearn_differs}")
    assert ours_differ <= 1.2 * sklearn_differs


# Scalars (damping, max_iter, ...) are traced: one compile per shape and preference kind.
_AP = unoptimised.jit(affinity_propagation, static_argnames="seed")
_AP_BATCH = unoptimised.jit(
    jax.vmap(
        lambda s, p, m, z, damping, max_iter, convergence_iter: affinity_propagation(
            s, p, m, noise=z, damping=damping, max_iter=max_iter, convergence_iter=convergence_iter
        ),
        in_axes=(0, 0, 0, None, None, None, None),
    )
)


def _ap64(similarity, preference, random_state, n_max=None, **kwargs):
    """One float64 problem, padded with NaN to n_max if given."""
    kwargs = dict(damping=0.5, max_iter=200, convergence_iter=15) | kwargs  # one signature
    n = len(similarity)
    n_max = n_max or n
    if np.ndim(preference) == 1:
        preference = _pad(np.asarray(preference, np.float64), n_max, np.nan)
    with jax.enable_x64(True):
        out = _AP(
            _pad(np.asarray(similarity, np.float64), n_max, np.nan),
            preference,
            np.arange(n_max) < n,
            seed=random_state,
            **kwargs,
        )
        k = int(out.num_clusters)
        return out, (out.labels[:n], out.exemplars[:k], int(out.n_iter), bool(out.converged))


@pytest.mark.parametrize(
    "kwargs",
    [
        dict(damping=0.7),
        dict(damping=0.9, convergence_iter=5),
        dict(max_iter=10),  # stops before convergence can be declared (it >= 15)
        dict(max_iter=40, convergence_iter=30),
    ],
)
def test_parameters_match_sklearn(kwargs):
    """Other damping / max_iter / convergence_iter, traced under vmap (one compile)."""
    rng = np.random.default_rng(7)
    problems = [random_case(rng, n, f) for n in (3, 8, 15) for f in FAMILIES]
    n_max = 15
    sim = np.stack([_pad(s, n_max, np.nan) for s, _ in problems])
    pref = np.stack(
        [
            _pad(np.full(len(s), np.median(s)) if p is None else p, n_max, np.nan)
            for s, p in problems
        ]
    )
    mask = np.stack([np.arange(n_max) < len(s) for s, _ in problems])
    z = sklearn_noise(3, n_max * n_max)
    kwargs = dict(damping=0.5, max_iter=200, convergence_iter=15) | kwargs
    with jax.enable_x64(True):
        out = jax.device_get(_AP_BATCH(sim, pref, mask, z, *kwargs.values()))
    compared = 0
    for b, (s, p) in enumerate(problems):
        theirs = sklearn_ap(s, p, 3, **kwargs)
        if theirs[1].size == 0:
            continue  # no exemplar: scikit-learn gives labels -1; see the fallback test
        compared += 1
        n, k = len(s), out.num_clusters[b]
        ours = (out.labels[b, :n], out.exemplars[b, :k], int(out.n_iter[b]), bool(out.converged[b]))
        assert _same_partition(ours, theirs), b
        assert ours[2:] == (theirs[2], theirs[3]), b
    assert compared >= 12


def test_scalar_preference_equals_vector():
    s = tree_affinity((-1, 0, 1, 0, 3, 0, 5, 0, 7))
    a = _AP(s.astype(np.float32), 0.2)
    b = _AP(s.astype(np.float32), np.full(9, 0.2, np.float32))
    assert jax.tree.all(jax.tree.map(np.array_equal, a, b))


@pytest.mark.parametrize(
    "similarity,preference",
    [
        (tree_affinity((-1, 0)), None),  # walker_2 at the median: two clusters
        (tree_affinity((-1, 0)), np.array([0.1, 0.1])),  # preference below: one cluster
        (np.full((4, 4), -2.0), -1.0),  # all equal, preference above
        (np.full((4, 4), -2.0), -3.0),
        (np.array([[1.0]]), None),  # one point
        (np.array([[1.0]]), 5.0),
    ],
)
def test_degenerate_case_is_sklearns(similarity, preference):
    ours, mine = _ap64(similarity, preference, 0, n_max=4)
    theirs = sklearn_ap(similarity, preference, 0)
    assert _same_partition(mine, theirs)
    assert bool(ours.degenerate) and bool(ours.converged) and int(ours.n_iter) == 0
    assert not bool(ours.no_exemplar)


def test_no_exemplar_falls_back_to_one_cluster():
    rng = np.random.default_rng(3)
    s, _ = random_case(rng, 6, "dense_points")
    theirs = sklearn_ap(s, -1e3, 0, max_iter=5)
    assert theirs[1].size == 0 and (theirs[0] == -1).all() and not theirs[3]
    ours, mine = _ap64(s, -1e3, 0, max_iter=5)
    assert bool(ours.no_exemplar) and not bool(ours.converged) and int(ours.n_iter) == 5
    assert int(ours.num_clusters) == 1 and (mine[0] == 0).all()
    # The best-evidence point is the exemplar scikit-learn settles on with more iterations.
    np.testing.assert_array_equal(mine[1], sklearn_ap(s, -1e3, 0)[1])


def test_padding_invariance():
    """Same answer for the real points whatever the padding size and contents."""
    rng = np.random.default_rng(11)
    n = 7
    problems = [random_case(rng, n, FAMILIES[i % len(FAMILIES)]) for i in range(40)]
    sim = np.stack([s for s, _ in problems]).astype(np.float32)
    pref = np.stack([np.full(n, np.median(s)) if p is None else p for s, p in problems])
    pref = pref.astype(np.float32)
    noise = sklearn_noise(0, N_MAX * N_MAX).astype(np.float32)

    ap = jax.vmap(lambda s, p, m: affinity_propagation(s, p, m, noise=noise), (0, 0, None))
    fn = unoptimised.jit(ap)

    def solve(n_max, fill):
        s = np.stack([_pad(x, n_max, fill) for x in sim])
        p = np.stack([_pad(x, n_max, fill) for x in pref])
        return jax.device_get(fn(s, p, np.arange(n_max) < n))

    base = solve(n, 0.0)
    for n_max, fill in ((N_MAX, np.nan), (N_MAX, np.inf), (N_MAX, -3.0), (N_MAX, 1e30)):
        out = solve(n_max, fill)
        np.testing.assert_array_equal(out.labels[:, :n], base.labels)
        assert (out.labels[:, n:] == -1).all()
        np.testing.assert_array_equal(out.exemplars[:, :n], base.exemplars)
        for field in ("num_clusters", "n_iter", "converged", "degenerate", "no_exemplar"):
            np.testing.assert_array_equal(getattr(out, field), getattr(base, field))


def test_vmap_over_morphologies_equals_unbatched():
    rng = np.random.default_rng(5)
    n_max = 9
    parents = [random_parents(rng, int(rng.integers(2, n_max + 1))) for _ in range(12)]
    sim = np.stack([_pad(tree_affinity(p), n_max, 0.0) for p in parents]).astype(np.float32)
    mask = np.stack([np.arange(n_max) < len(p) for p in parents])

    def ap(s, m):
        return affinity_propagation(s, None, m)

    single = unoptimised.jit(ap)
    batched = jax.device_get(unoptimised.jit(jax.vmap(ap))(sim, mask))
    for b in range(len(parents)):
        one = jax.device_get(single(sim[b], mask[b]))
        for field in dataclasses.fields(one):
            np.testing.assert_array_equal(
                getattr(batched, field.name)[b], getattr(one, field.name), field.name
            )


def test_vmap_over_noise_streams_is_sklearn_per_seed():
    s = tree_affinity((-1, 0, 1, 0, 3, 0, 5, 0, 7))
    seeds = range(8)
    streams = np.stack([sklearn_noise(seed, 81) for seed in seeds])
    with jax.enable_x64(True):
        out = unoptimised.jit(jax.vmap(lambda z: affinity_propagation(s, None, noise=z)))(streams)
        out = jax.device_get(out)
    for b, seed in enumerate(seeds):
        theirs = sklearn_ap(s, None, seed)
        np.testing.assert_array_equal(out.labels[b], theirs[0])
        np.testing.assert_array_equal(out.exemplars[b, : out.num_clusters[b]], theirs[1])


def test_seed_is_static_and_noise_checked():
    s = jnp.asarray(tree_affinity((-1, 0, 1)), jnp.float32)
    with pytest.raises(TypeError, match="static"):
        unoptimised.jit(lambda seed: affinity_propagation(s, seed=seed))(0)
    with pytest.raises(ValueError, match="noise"):
        affinity_propagation(s, noise=jnp.zeros(4))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no warnings from the JAX side
        out = unoptimised.jit(affinity_propagation, static_argnames="seed")(s, seed=1)
    assert int(out.num_clusters) >= 1
