"""The monolithic baseline (algorithm.md §4): padded contents and the torso's action
are ignored."""

import numpy as np

from tests.networks.inputs import N_MAX, networks, robot


def test_padded_contents_change_nothing():
    nets, (actor, critic) = networks("monolithic")
    clean = robot("walker_7_main", N_MAX, 4)
    dirty = robot("walker_7_main", N_MAX, 4, garbage=True)
    np.testing.assert_array_equal(
        nets.act(actor, dirty[0], dirty[2]), nets.act(actor, clean[0], clean[2])
    )
    np.testing.assert_array_equal(nets.q(critic, *dirty[:3]), nets.q(critic, *clean[:3]))
    assert nets.q(critic, *clean[:3]).shape == (2, 4)
    mlp = actor["mlp"]
    assert mlp["dense_0"]["kernel"].shape == (N_MAX * 19, 32)
    assert mlp["dense_2"]["kernel"].shape == (32, N_MAX)
