"""Affinity propagation in pure JAX, with scikit-learn's semantics (algorithm.md §3).

Reproduces ``sklearn.cluster.AffinityPropagation(affinity="precomputed")``: the
preference on the diagonal, the tie-breaking noise ``(eps * S + 100 * tiny) * N(0, 1)``,
damped responsibility/availability updates, the stopping rule, the exemplar
refinement and the label order. Written for one padded problem ``[N_max, N_max]`` with
an agent mask; jit it, and vmap it over morphologies (and noise streams).

The noise matters: on tree affinities exp(-D) most similarities tie exactly, and the
partition scikit-learn returns depends on its ``random_state`` (the fixtures of
docs/algorithm.md §3 are those of ``random_state=0``). So the default noise is NumPy's
own draw for ``seed``, read on the host at trace time. With float64 (inputs in float64 under
``jax.enable_x64``) the result is scikit-learn's bit for bit, fixtures included: use
it for fidelity to the reference. (Exception: XLA flushes subnormals to zero and NumPy
does not, which matters only when similarities are exactly 0, noise 100 * tiny.)
In float32 (the default dtype) partitions and exemplars agree in 97% of converged
random problems; the rest are exact ties that float32 rounding breaks the other way
(scikit-learn itself gives those answers under another ``random_state``). Any other
standard-normal stream (e.g. from ``jax.random.normal``) is another valid tie-breaking,
as another ``random_state`` is.
"""

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct


@struct.dataclass
class Clustering:
    """Result of one affinity propagation run; padded agents get label -1."""

    labels: jax.Array
    """``[N_max]`` int32: cluster of each agent, 0..K-1 in ascending exemplar order; -1 padded."""
    exemplars: jax.Array
    """``[N_max]`` int32: agent index of cluster k's exemplar for k < K, -1 after."""
    num_clusters: jax.Array
    """``[]`` int32: K."""
    converged: jax.Array
    """``[]`` bool: scikit-learn's stopping rule fired (True in the degenerate case too)."""
    n_iter: jax.Array
    """``[]`` int32: iterations run, as scikit-learn's ``n_iter_`` (0 when degenerate)."""
    degenerate: jax.Array
    """``[]`` bool: one point, or all similarities and all preferences equal (no messages)."""
    no_exemplar: jax.Array
    """``[]`` bool: not converged and no exemplar at the end; fallback clustering used."""


def affinity_propagation(
    similarity: jax.Array,
    preference: jax.Array | float | None = None,
    mask: jax.Array | None = None,
    *,
    damping: float = 0.5,
    max_iter: int = 200,
    convergence_iter: int = 15,
    seed: int = 0,
    noise: jax.Array | None = None,
) -> Clustering:
    """Clusters the real points of a padded similarity matrix like scikit-learn.

    Args:
      similarity: ``[N_max, N_max]``; only the real block is read (padded rows and
        columns may hold anything, NaN included).
      preference: ``[N_max]``, a scalar, or None for the median of the real block's
        similarities, diagonal included (scikit-learn's default).
      mask: ``[N_max]`` bool, True for real points; None means all real.
      damping, max_iter, convergence_iter: scikit-learn's parameters (traceable).
      seed: scikit-learn's ``random_state`` (a host int, static under jit): the noise
        is ``sklearn_noise(seed, N_max**2)``, baked in as a constant.
      noise: optional 1-D stream of at least ``N_max**2`` standard normals replacing
        the seed's (traceable, so it can be vmapped). The real block of n points reads
        its first n² entries row-major, as NumPy fills ``standard_normal((n, n))``, so
        padding never changes the noise.

    Returns:
      A ``Clustering``. Fallbacks, never NaN: the degenerate case returns
      scikit-learn's answer (every point its own cluster if the preference exceeds the
      similarity, else one cluster around the first point); a run that ends with no
      exemplar (scikit-learn returns labels -1) makes the point with the largest
      evidence ``A_kk + R_kk`` the only exemplar and flags ``no_exemplar``.
    """
    similarity = jnp.asarray(similarity)
    if not jnp.issubdtype(similarity.dtype, jnp.floating):
        similarity = similarity.astype(jnp.result_type(float))
    dtype = similarity.dtype
    n_max = similarity.shape[-1]
    idx = jnp.arange(n_max)
    eye = idx[:, None] == idx[None, :]
    mask = jnp.ones(n_max, bool) if mask is None else jnp.asarray(mask, bool)
    pair = mask[:, None] & mask[None, :]
    num_real = mask.sum()

    # Padded entries are replaced before any arithmetic so that NaN cannot leak.
    raw = jnp.where(pair, similarity, 0)
    if preference is None:
        pref = jnp.broadcast_to(_masked_median(raw, pair), (n_max,))
    else:
        pref = jnp.broadcast_to(jnp.asarray(preference, dtype), (n_max,))
    pref = jnp.where(mask, pref, 0)

    # S: preference on the diagonal, plus scikit-learn's tie-breaking noise.
    if noise is None:
        if isinstance(seed, jax.core.Tracer):
            raise TypeError("seed is a host-side int (static under jit); pass noise to vary it")
        noise = sklearn_noise(seed, n_max * n_max)
    if jnp.ndim(noise) != 1 or jnp.shape(noise)[0] < n_max * n_max:
        raise ValueError(f"noise must be 1-D with >= {n_max * n_max} entries: {jnp.shape(noise)}")
    finfo = jnp.finfo(dtype)
    s = jnp.where(eye, pref[:, None], raw)
    s = s + (finfo.eps * s + finfo.tiny * 100) * _noise_matrix(noise, mask, dtype)
    s = jnp.where(pair, s, 0)

    final = _iterate(s, pair, eye, damping, max_iter, convergence_iter)
    evidence, exemplar, n_iter, converged = final
    no_exemplar = ~jnp.any(exemplar)
    best = _first_argmax(jnp.where(mask, evidence, -jnp.inf))
    exemplar = jnp.where(no_exemplar, idx == best, exemplar) & mask
    labels, exemplars, num_clusters = _assign(s, exemplar, mask)

    # scikit-learn answers the degenerate case without messages (with a warning).
    degenerate, deg = _degenerate(raw, pref, mask, eye)
    labels = jnp.where(degenerate, deg[0], labels)
    exemplars = jnp.where(degenerate, deg[1], exemplars)
    num_clusters = jnp.where(degenerate, deg[2], num_clusters)
    return Clustering(
        labels=jnp.where(mask, labels, -1).astype(jnp.int32),
        exemplars=exemplars.astype(jnp.int32),
        num_clusters=num_clusters.astype(jnp.int32),
        converged=converged | degenerate,
        n_iter=jnp.where(degenerate, 0, n_iter).astype(jnp.int32),
        degenerate=degenerate,
        no_exemplar=no_exemplar & ~degenerate & (num_real > 0),
    )


def sklearn_noise(seed: int, size: int) -> np.ndarray:
    """The first ``size`` draws of ``np.random.RandomState(seed).standard_normal``, float64.

    scikit-learn's tie-breaking noise for n points is the first n² of them, row-major.
    """
    return np.random.RandomState(seed).standard_normal(size)


def _noise_matrix(stream: jax.Array, mask: jax.Array, dtype) -> jax.Array:
    """``[N_max, N_max]``: real pair (i, j) gets ``stream[rank_i * n + rank_j]``; padded 0."""
    rank = jnp.cumsum(mask) - 1
    flat = rank[:, None] * mask.sum() + rank[None, :]
    pair = mask[:, None] & mask[None, :]
    return jnp.where(pair, jnp.asarray(stream, dtype)[jnp.where(pair, flat, 0)], 0)


def _masked_median(values: jax.Array, pair: jax.Array) -> jax.Array:
    """``np.median`` of the real block ``[n, n]`` (diagonal included)."""
    flat = jnp.sort(jnp.where(pair, values, jnp.inf).ravel())
    m = jnp.maximum(pair.sum(), 1)
    return (flat[(m - 1) // 2] + flat[m // 2]) / 2


def _iterate(s, pair, eye, damping, max_iter, convergence_iter):
    """Message passing until scikit-learn's stopping rule; returns the final state.

    Per iteration ``it`` (0-based): E = diag(A) + diag(R) > 0. scikit-learn stops at the
    first ``it >= convergence_iter`` where E was identical over the last
    ``convergence_iter`` iterations and has at least one exemplar (K > 0); it then
    reports ``n_iter = it + 1``, else ``max_iter`` and "did not converge".
    """
    n_max = s.shape[-1]
    cols = jnp.arange(n_max)[None, :]

    def body(carry):
        it, a, r, e_prev, run, _ = carry
        # Responsibilities: r(i,k) = s(i,k) - max_{k' != k} [a(i,k') + s(i,k')].
        tmp = jnp.where(pair, a + s, -jnp.inf)
        first = _first_argmax(tmp, axis=1)
        y = jnp.max(tmp, axis=1)
        y2 = jnp.max(jnp.where(cols == first[:, None], -jnp.inf, tmp), axis=1)
        y2 = jnp.where(jnp.isfinite(y2), y2, y)  # one real point: no runner-up
        r_new = jnp.where(cols == first[:, None], s - y2[:, None], s - y[:, None])
        r = jnp.where(pair, r * damping + r_new * (1 - damping), 0)

        # Availabilities: a(i,k) = min(0, r(k,k) + sum_{i' not in {i,k}} max(0, r(i',k))),
        # a(k,k) = sum_{i' != k} max(0, r(i',k)); computed as scikit-learn does.
        rp = jnp.where(eye, r, jnp.maximum(r, 0))
        neg_a = rp - jnp.sum(jnp.where(pair, rp, 0), axis=0)[None, :]
        neg_a = jnp.where(eye, neg_a, jnp.maximum(neg_a, 0))
        a = jnp.where(pair, a * damping - neg_a * (1 - damping), 0)

        evidence = jnp.diagonal(a) + jnp.diagonal(r)
        e = (evidence > 0) & jnp.diagonal(pair)
        run = jnp.where(jnp.all(e == e_prev), run + 1, 1)
        done = (it >= convergence_iter) & (run >= convergence_iter) & jnp.any(e)
        return it + 1, a, r, e, run, done

    def cond(carry):
        it, *_, done = carry
        return (it < max_iter) & ~done

    zeros = jnp.zeros_like(s)
    init = (jnp.int32(0), zeros, zeros, jnp.zeros(n_max, bool), jnp.int32(0), jnp.bool_(False))
    it, a, r, e, _, done = jax.lax.while_loop(cond, body, init)
    return jnp.diagonal(a) + jnp.diagonal(r), e, it, done


def _assign(s, exemplar, mask):
    """Assignment, exemplar refinement, reassignment and label numbering (scikit-learn's).

    Clusters live in "slots" named by their first exemplar's index, so iterating slots
    in ascending order is scikit-learn's cluster order k (exemplars came out sorted).
    """
    n_max = s.shape[-1]
    idx = jnp.arange(n_max)
    # Each point to its most similar exemplar (first on ties), exemplars to themselves.
    slot = _first_argmax(jnp.where(exemplar[None, :], s, -jnp.inf), axis=1)
    slot = jnp.where(exemplar, idx, slot)
    member = (slot[:, None] == idx[None, :]) & mask[:, None]  # [point, slot]

    # Refine: the member with the largest within-cluster column sum (first on ties).
    col_sums = jnp.sum(jnp.where(member.T[:, :, None], s[None, :, :], 0), axis=1)  # [slot, j]
    refined = _first_argmax(jnp.where(member.T, col_sums, -jnp.inf), axis=1)  # [slot]

    # Reassign to the refined exemplars, slots in ascending order on ties.
    slot = _first_argmax(jnp.where(exemplar[None, :], s[:, refined], -jnp.inf), axis=1)
    slot = slot.at[jnp.where(exemplar, refined, n_max)].set(idx, mode="drop")  # to themselves
    centre = refined[slot]

    # Number clusters by ascending exemplar index.
    centres = jnp.where(exemplar, refined, n_max)  # out of range for unused slots
    is_centre = jnp.zeros(n_max, bool).at[centres].set(True, mode="drop")
    rank = jnp.cumsum(is_centre) - 1
    labels = rank[centre]
    exemplars = jnp.full(n_max, -1).at[jnp.where(is_centre, rank, n_max)].set(idx, mode="drop")
    return labels, exemplars, is_centre.sum()


def _degenerate(raw, pref, mask, eye):
    """scikit-learn's special case: one point, or all similarities and preferences equal.

    Its answer: every point its own cluster if ``preference[0] > S[0, n - 1]`` (first
    and last real points), else one cluster with exemplar 0. Returns the flag and
    (labels, exemplars, num_clusters).
    """
    n_max = raw.shape[-1]
    idx = jnp.arange(n_max)
    num_real = mask.sum()
    off = mask[:, None] & mask[None, :] & ~eye
    big = jnp.finfo(raw.dtype).max
    equal_sim = jnp.max(jnp.where(off, raw, -big)) <= jnp.min(jnp.where(off, raw, big))
    equal_pref = jnp.max(jnp.where(mask, pref, -big)) <= jnp.min(jnp.where(mask, pref, big))
    flag = (num_real == 1) | ((num_real > 1) & equal_sim & equal_pref)

    first = _first_argmax(mask)
    last = n_max - 1 - _first_argmax(mask[::-1])
    many = pref[first] > raw[first, last]
    rank = jnp.cumsum(mask) - 1
    labels = jnp.where(many, rank, 0)
    exemplars = jnp.where(
        many,
        jnp.full(n_max, -1).at[jnp.where(mask, rank, n_max)].set(idx, mode="drop"),
        jnp.where(idx == 0, first, -1),
    )
    return flag, (labels, exemplars, jnp.where(many, num_real, 1))


def _first_argmax(x: jax.Array, axis: int | None = None) -> jax.Array:
    """``jnp.argmax`` (first index of the maximum; no NaN here) from max, compare and min.

    ``jnp.argmax`` builds its reduction's initial value in the trace's default precision,
    which breaks when the trainer traces this under a nested ``jax.enable_x64`` block.
    """
    if axis is None:
        x, axis = x.ravel(), 0
    n = x.shape[axis]
    shape = [1] * x.ndim
    shape[axis] = n
    iota = jnp.arange(n).reshape(shape)
    top = jnp.max(x, axis=axis, keepdims=True)
    return jnp.min(jnp.where(x == top, iota, n), axis=axis)
