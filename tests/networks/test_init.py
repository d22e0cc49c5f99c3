"""The reference's initialisation (algorithm.md §4), checked by the statistics of a draw
at the paper's sizes (large tensors, so the bounds and moments are tight)."""

import functools
import math

import jax
import numpy as np
import pytest

from solar_jax.config import NetworkConfig
from solar_jax.networks import GATE, TRANSFORM, make_networks
from tests import unoptimised


@functools.cache
def _params(method: str, init: str = "reference"):
    nets = make_networks(method, NetworkConfig(init=init), n_max=9)
    return jax.tree.map(np.asarray, unoptimised.jit(nets.init)(jax.random.key(0)))


def _uniform_within(x: np.ndarray, bound: float):
    """Drawn from U(±bound): inside it, reaching close to it, with the uniform's std."""
    assert np.abs(x).max() <= bound
    assert np.abs(x).max() > 0.9 * bound
    np.testing.assert_allclose(x.std(), bound / math.sqrt(3), rtol=0.15)


def test_solar_actor_follows_the_reference_rules():
    actor, _ = _params("solar")
    trunk = actor["trunk"]
    _uniform_within(trunk["encoder"]["dense"]["kernel"], 0.1)
    _uniform_within(trunk["encoder"]["dense"]["bias"], 1 / math.sqrt(19))  # PyTorch default
    _uniform_within(trunk["decoder"]["kernel"], 0.1)
    np.testing.assert_array_equal(trunk["decoder"]["bias"], 0.0)
    layer = trunk["layer_0"]
    for name in ("query", "key", "value"):  # xavier over the in-projection [3W, W]
        _uniform_within(layer[name]["kernel"], math.sqrt(6 / (128 + 3 * 128)))
        np.testing.assert_array_equal(layer[name]["bias"], 0.0)
    _uniform_within(layer["out"]["kernel"], 1 / math.sqrt(128))
    np.testing.assert_array_equal(layer["out"]["bias"], 0.0)
    _uniform_within(layer["ff_in"]["kernel"], 1 / math.sqrt(128))
    _uniform_within(layer["ff_out"]["bias"], 1 / math.sqrt(256))
    np.testing.assert_array_equal(layer["norm_ff"]["scale"], 1.0)
    for order in ("pre", "in", "post"):  # N(0, 1): std 1, not Flax's 1/sqrt(64)
        table = actor[TRANSFORM][f"{order}_order"]["embedding"]
        np.testing.assert_allclose(table.std(), 1.0, rtol=0.1)
    _uniform_within(actor[TRANSFORM]["structure"]["kernel"], 1 / math.sqrt(3 * 64))
    _uniform_within(actor[GATE]["dense_0"]["kernel"], 1 / math.sqrt(128 + 4 * 64))
    _uniform_within(actor[GATE]["dense_1"]["kernel"], 1 / math.sqrt(256))


@pytest.mark.parametrize("method", ["solar", "amorpheus"])
def test_layers_start_identical_and_twin_critics_do_not(method):
    actor, critic = _params(method)
    for tree in (actor["trunk"], critic["trunk"]):
        for i in (1, 2):
            jax.tree.map(np.testing.assert_array_equal, tree[f"layer_{i}"], tree["layer_0"])
    for leaf in jax.tree.leaves(critic):  # [2, ...]: one draw per critic
        if leaf.size > 2 and leaf.std() > 0:
            assert not np.array_equal(leaf[0], leaf[1])
    _uniform_within(critic["trunk"]["encoder"]["dense"]["kernel"], 0.1)  # 20 inputs


def test_monolithic_uses_pytorch_linear_defaults():
    actor, critic = _params("monolithic")
    _uniform_within(actor["mlp"]["dense_0"]["kernel"], 1 / math.sqrt(9 * 19))
    _uniform_within(critic["mlp"]["dense_1"]["bias"], 1 / math.sqrt(400))


def test_flax_switch_keeps_flax_initialisers():
    actor, _ = _params("solar", "flax")
    table = actor[TRANSFORM]["pre_order"]["embedding"]
    np.testing.assert_allclose(table.std(), 1 / math.sqrt(64), rtol=0.15)  # Flax's Embed
    assert not np.array_equal(
        actor["trunk"]["layer_1"]["ff_in"]["kernel"], actor["trunk"]["layer_0"]["ff_in"]["kernel"]
    )
