"""Checkpoints alone: a state comes back as device arrays with the same bits, and a
checkpoint of another format is one clear error (runs resume through them:
tests/training/test_runner.py)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from solar_jax.agent.state import init_agent
from solar_jax.config import NetworkConfig, TD3Config
from solar_jax.networks import make_networks
from solar_jax.training import checkpoint
from solar_jax.training.checkpoint import Checkpointer, CheckpointError
from tests import unoptimised


def _state():
    key = jax.random.PRNGKey(3)
    return {
        "params": jax.random.normal(key, (4, 3)),
        "count": jnp.int32(7),
        "flags": jnp.array([True, False]),
        "key": key,
    }


def _assert_same_bits(restored, saved):
    """The same tree, each leaf a device array of the saved dtype and bits."""
    assert jax.tree.structure(restored) == jax.tree.structure(saved)
    for got, want in zip(jax.tree.leaves(restored), jax.tree.leaves(saved), strict=True):
        assert isinstance(got, jax.Array) and got.dtype == want.dtype
        np.testing.assert_array_equal(got, want)


def test_a_state_comes_back_on_the_device_with_the_same_bits(tmp_path):
    state = _state()
    checkpointer = Checkpointer(tmp_path)
    checkpointer.save(5, state, {"seed": 1}, replay_slots=1024)
    restored, meta = checkpointer.restore(lambda meta: state)
    checkpointer.close()
    assert meta["step"] == 5 and meta["config"] == {"seed": 1} and meta["replay_slots"] == 1024
    _assert_same_bits(restored, state)


@pytest.mark.parametrize("method", ["solar", "monolithic"])
def test_the_agent_of_a_method_with_or_without_synergies_comes_back(tmp_path, method):
    # Without an action transformation the synergy group is empty: its optimiser state
    # must still save (a zero-size array made orbax refuse the baselines' checkpoints).
    nets = make_networks(method, NetworkConfig.tiny(num_layers=1), n_max=4)
    td3 = TD3Config()
    agent = init_agent(*unoptimised.jit(nets.init)(jax.random.key(0)), td3)
    checkpointer = Checkpointer(tmp_path)
    checkpointer.save(1, agent, {"method": method})
    restored, _ = checkpointer.restore(agent)
    checkpointer.close()
    _assert_same_bits(restored, agent)


def test_another_format_or_no_checkpoint_is_one_clear_error(tmp_path, monkeypatch):
    empty = Checkpointer(tmp_path / "empty")
    with pytest.raises(CheckpointError, match="no checkpoint in"):
        empty.restore(_state())
    empty.close()
    checkpointer = Checkpointer(tmp_path / "old")
    monkeypatch.setattr(checkpoint, "FORMAT_VERSION", 1)
    checkpointer.save(1, _state(), {})
    monkeypatch.undo()
    with pytest.raises(CheckpointError, match="has format version 1, this solar_jax reads"):
        checkpointer.restore(_state())
    checkpointer.close()
