"""Checkpoints alone: a state comes back as device arrays with the same bits, and a
checkpoint of another format is one clear error (runs resume through them:
tests/test_runner.py)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from solar_jax.training import checkpoint
from solar_jax.training.checkpoint import Checkpointer, CheckpointError


def _state():
    key = jax.random.PRNGKey(3)
    return {
        "params": jax.random.normal(key, (4, 3)),
        "count": jnp.int32(7),
        "flags": jnp.array([True, False]),
        "key": key,
    }


def test_a_state_comes_back_on_the_device_with_the_same_bits(tmp_path):
    state = _state()
    checkpointer = Checkpointer(tmp_path)
    checkpointer.save(5, state, {"seed": 1}, replay_slots=1024)
    restored, meta = checkpointer.restore(lambda meta: state)
    checkpointer.close()
    assert meta["step"] == 5 and meta["config"] == {"seed": 1} and meta["replay_slots"] == 1024
    assert jax.tree.structure(restored) == jax.tree.structure(state)
    for got, saved in zip(jax.tree.leaves(restored), jax.tree.leaves(state), strict=True):
        assert isinstance(got, jax.Array) and got.dtype == saved.dtype
        np.testing.assert_array_equal(got, saved)


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
