"""Graph facts of a morphology's body tree, computed once on the host (NumPy).

Agents are bodies in pre-order, torso first, so a tree is fully described by its
parent list: ``parents[0] == -1`` and ``parents[i] < i`` for every other agent.
"""

from collections.abc import Sequence

import numpy as np


def validate_parents(parents: Sequence[int]) -> tuple[int, ...]:
    """Checks that ``parents`` is a pre-order parent list; returns it as a tuple of ints."""
    parents = tuple(int(p) for p in parents)
    if not parents:
        raise ValueError("a morphology needs at least one body (the torso)")
    if parents[0] != -1:
        raise ValueError(f"parents[0] must be -1 (the torso is the root), got {parents[0]}")
    for i, p in enumerate(parents[1:], start=1):
        if not 0 <= p < i:
            raise ValueError(f"parents[{i}] = {p}: pre-order requires 0 <= parent < {i}")
    # Pre-order also requires each subtree to be contiguous: a body's parent must be on
    # the path from the previous body to the root.
    for i in range(1, len(parents)):
        ancestor = i - 1
        while ancestor != -1 and ancestor != parents[i]:
            ancestor = parents[ancestor]
        if ancestor == -1:
            raise ValueError(f"parents {parents} are not in pre-order (body {i})")
    return parents


def children(parents: Sequence[int]) -> tuple[tuple[int, ...], ...]:
    """Children of each agent, in pre-order (= the order they appear in the file)."""
    kids: list[list[int]] = [[] for _ in parents]
    for i, p in enumerate(parents):
        if p >= 0:
            kids[p].append(i)
    return tuple(tuple(k) for k in kids)


def depths(parents: Sequence[int]) -> np.ndarray:
    """Hop count from the torso, ``[N]`` int."""
    depth = np.zeros(len(parents), dtype=np.int32)
    for i, p in enumerate(parents):
        if p >= 0:
            depth[i] = depth[p] + 1
    return depth


def hop_distances(parents: Sequence[int]) -> np.ndarray:
    """All-pairs hop distances on the (undirected) parent tree, ``[N, N]`` int32.

    Floyd-Warshall, as the SOLAR reference computes it (algorithm.md §3).
    """
    n = len(parents)
    inf = n + 1  # larger than any path in a tree of n nodes
    dist = np.full((n, n), inf, dtype=np.int64)
    np.fill_diagonal(dist, 0)
    for i, p in enumerate(parents):
        if p >= 0:
            dist[i, p] = dist[p, i] = 1
    for k in range(n):
        dist = np.minimum(dist, dist[:, k : k + 1] + dist[k : k + 1, :])
    if (dist >= inf).any():
        raise ValueError(f"parents {tuple(parents)} do not form one connected tree")
    return dist.astype(np.int32)


def traversal_indices(parents: Sequence[int]) -> np.ndarray:
    """Pre-, in- and post-order positions in the left-child right-sibling binary tree.

    The first child of a body is its left child, each later sibling is the right
    child of the sibling before it (algorithm.md §4). Returns ``[N, 3]`` int32 with
    columns (pre, in, post); row ``i`` is agent ``i``.
    """
    n = len(parents)
    kids = children(parents)
    left = [k[0] if k else -1 for k in kids]
    right = [-1] * n
    for k in kids:
        for a, b in zip(k[:-1], k[1:], strict=True):
            right[a] = b

    order: dict[str, list[int]] = {"pre": [], "in": [], "post": []}

    def visit(node: int) -> None:
        # Iterative depth would need an explicit stack; trees here have <= ~20 nodes.
        if node < 0:
            return
        order["pre"].append(node)
        visit(left[node])
        order["in"].append(node)
        visit(right[node])
        order["post"].append(node)

    visit(0)
    out = np.zeros((n, 3), dtype=np.int32)
    for col, name in enumerate(("pre", "in", "post")):
        out[order[name], col] = np.arange(n, dtype=np.int32)
    return out
