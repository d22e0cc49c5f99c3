import numpy as np
import pytest

from solar_jax.morphology import graph

# algorithm.md §4 fixtures: (pre, in, post) per agent.
TRAVERSAL_FIXTURES = {
    (-1, 0, 1, 2, 0, 4, 5): [
        [0, 6, 6],
        [1, 2, 5],
        [2, 1, 1],
        [3, 0, 0],
        [4, 5, 4],
        [5, 4, 3],
        [6, 3, 2],
    ],
    (-1, 0, 1, 0, 3, 0, 5, 0, 7): [
        [0, 8, 8],
        [1, 1, 7],
        [2, 0, 0],
        [3, 3, 6],
        [4, 2, 1],
        [5, 5, 5],
        [6, 4, 2],
        [7, 7, 4],
        [8, 6, 3],
    ],
}


@pytest.mark.parametrize("parents", list(TRAVERSAL_FIXTURES))
def test_traversal_indices_match_spec_fixtures(parents):
    np.testing.assert_array_equal(graph.traversal_indices(parents), TRAVERSAL_FIXTURES[parents])


def test_traversal_of_a_chain_and_a_star():
    # A chain is all left children: pre 0..n-1, in and post reversed.
    chain = graph.traversal_indices((-1, 0, 1, 2))
    np.testing.assert_array_equal(chain[:, 0], [0, 1, 2, 3])
    np.testing.assert_array_equal(chain[:, 1], [3, 2, 1, 0])
    np.testing.assert_array_equal(chain[:, 2], [3, 2, 1, 0])
    # A star: children chained as right siblings under the torso's left child.
    star = graph.traversal_indices((-1, 0, 0, 0))
    np.testing.assert_array_equal(star[:, 1], [3, 0, 1, 2])
    np.testing.assert_array_equal(star[:, 2], [3, 2, 1, 0])


def test_hop_distances_of_humanoid_tree():
    d = graph.hop_distances((-1, 0, 1, 0, 3, 0, 5, 0, 7))
    assert d.dtype == np.int32 and d.shape == (9, 9)
    np.testing.assert_array_equal(d, d.T)
    np.testing.assert_array_equal(np.diag(d), 0)
    assert d[2, 4] == 4  # right shin -> torso -> left shin
    assert d[0].tolist() == [0, 1, 2, 1, 2, 1, 2, 1, 2]


def test_hop_distances_equal_breadth_first_search_on_random_trees():
    rng = np.random.default_rng(0)
    for _ in range(50):
        n = int(rng.integers(1, 15))
        parents = graph.validate_parents(_random_preorder_tree(rng, n))
        d = graph.hop_distances(parents)
        kids = graph.children(parents)
        neighbours = [list(kids[i]) + ([parents[i]] if parents[i] >= 0 else []) for i in range(n)]
        for source in range(n):
            seen, frontier, hops = {source: 0}, [source], 0
            while frontier:
                hops += 1
                frontier = [m for v in frontier for m in neighbours[v] if m not in seen]
                seen.update({m: hops for m in frontier})
            assert [seen[t] for t in range(n)] == d[source].tolist()


def _random_preorder_tree(rng, n):
    # Each new body attaches to a body on the path from the previous one to the root.
    parents, path = [-1], [0]
    for i in range(1, n):
        path = path[: int(rng.integers(1, len(path) + 1))]
        parents.append(path[-1])
        path.append(i)
    return parents


@pytest.mark.parametrize(
    ("parents", "message"),
    [
        ((), "at least one body"),
        ((0, 0), "must be -1"),
        ((-1, 0, 3, 1), "0 <= parent < 2"),
        ((-1, 0, 0, 1), "not in pre-order"),
    ],
)
def test_validate_parents_rejects_bad_lists(parents, message):
    with pytest.raises(ValueError, match=message):
        graph.validate_parents(parents)


def test_depths():
    np.testing.assert_array_equal(graph.depths((-1, 0, 1, 2, 0, 4, 5)), [0, 1, 2, 3, 1, 2, 3])
