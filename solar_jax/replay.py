"""On-device replay: one ring buffer per morphology, stacked and padded (algorithm.md §5).

    obs, next_obs  [M, C, N_max, 19]    action  [M, C, N_max]    reward, terminated  [M, C]
    position, size [M]

Writes are masked: a round stores only the transitions of environments still in their
round's episode and whose physics stayed finite, so morphologies fill at different
rates. That is why this is a small masked scatter rather than flashbax, whose buffers
add fixed-size batches unconditionally and keep one fill level; ``next_obs`` is stored
explicitly because at an auto-reset it is the true final observation, not the next
stored one.
"""

import jax
import jax.numpy as jnp
from flax import struct


@struct.dataclass
class Replay:
    obs: jax.Array  # [M, C, N, F]
    action: jax.Array  # [M, C, N]
    reward: jax.Array  # [M, C]
    next_obs: jax.Array  # [M, C, N, F]
    terminated: jax.Array  # [M, C] bool: the task ended (truncations are stored as False)
    position: jax.Array  # [M] int32: next slot to write
    size: jax.Array  # [M] int32: filled slots (<= C)

    @property
    def capacity(self) -> int:
        return self.reward.shape[-1]  # also with leading (lane) axes


@struct.dataclass
class Batch:
    """Transitions of one morphology ``[B, ...]`` (or several, ``[M, B, ...]``)."""

    obs: jax.Array
    action: jax.Array
    reward: jax.Array
    next_obs: jax.Array
    terminated: jax.Array


def init_replay(num_morphs: int, capacity: int, n_max: int, obs_size: int) -> Replay:
    if capacity < 1:
        raise ValueError(f"replay capacity must be >= 1, got {capacity}")
    m, c = num_morphs, capacity
    return Replay(
        obs=jnp.zeros((m, c, n_max, obs_size), jnp.float32),
        action=jnp.zeros((m, c, n_max), jnp.float32),
        reward=jnp.zeros((m, c), jnp.float32),
        next_obs=jnp.zeros((m, c, n_max, obs_size), jnp.float32),
        terminated=jnp.zeros((m, c), bool),
        position=jnp.zeros(m, jnp.int32),
        size=jnp.zeros(m, jnp.int32),
    )


def grow(replay: Replay, capacity: int) -> Replay:
    """``replay`` in buffers of ``capacity`` slots (zero-padded at the end). Only for a
    ring that has not wrapped (position == size): its transitions keep their slots, so
    every later write and sample is what a buffer of ``capacity`` from the start gives."""
    extra = capacity - replay.capacity
    if extra < 0:
        raise ValueError(f"cannot shrink a replay of {replay.capacity} to {capacity}")
    axis = replay.reward.ndim - 1  # the slot axis, after any leading (lane) axes

    def pad(x):
        return jnp.pad(x, [(0, extra if i == axis else 0) for i in range(x.ndim)])

    return replay.replace(
        obs=pad(replay.obs),
        action=pad(replay.action),
        reward=pad(replay.reward),
        next_obs=pad(replay.next_obs),
        terminated=pad(replay.terminated),
    )


def add(replay: Replay, batch: Batch, mask: jax.Array) -> Replay:
    """Writes the rows of ``batch`` (``[M, B, ...]``) where ``mask [M, B]`` holds.

    Each morphology's kept rows go to consecutive slots from its position, wrapping
    around (ring overwrite of the oldest); masked rows are dropped by the scatter.
    """
    c = replay.capacity
    count = jnp.cumsum(mask, axis=1, dtype=jnp.int32)  # [M, B]
    slot = (replay.position[:, None] + count - 1) % c
    slot = jnp.where(mask, slot, c)  # out of range: dropped
    morph = jnp.broadcast_to(jnp.arange(mask.shape[0])[:, None], mask.shape)

    def write(store, rows):
        return store.at[morph, slot].set(rows.astype(store.dtype), mode="drop")

    added = count[:, -1]
    return Replay(
        obs=write(replay.obs, batch.obs),
        action=write(replay.action, batch.action),
        reward=write(replay.reward, batch.reward),
        next_obs=write(replay.next_obs, batch.next_obs),
        terminated=write(replay.terminated, batch.terminated),
        position=(replay.position + added) % c,
        size=jnp.minimum(replay.size + added, c),
    )


def _rows(staged: Replay) -> Batch:
    """A ring's slots as a batch of rows ``[M, C, ...]`` (in slot order)."""
    return Batch(staged.obs, staged.action, staged.reward, staged.next_obs, staged.terminated)


def append(replay: Replay, staged: Replay) -> Replay:
    """``replay`` after the transitions written into ``staged`` (a ring that has not
    wrapped: its first ``size`` slots per morphology, in the order they were added), as
    if they had been added to ``replay`` directly and in that order.

    This lets a round collect into a buffer of its own fixed size, so the program that
    steps the physics does not depend on (and is not recompiled for) the ring's size.
    When a morphology staged more rows than ``replay`` holds, the direct writes would
    have overwritten its first ones: only the last ``capacity`` are written, at the
    slots those writes left them in.
    """
    c = replay.capacity
    count = staged.size[:, None]  # [M, 1]
    index = jnp.arange(staged.capacity)[None, :]  # [1, S]
    overwritten = jnp.maximum(staged.size - c, 0)  # [M]
    keep = (index < count) & (index >= overwritten[:, None])
    shifted = replay.replace(position=(replay.position + overwritten) % c)
    return add(shifted, _rows(staged), keep)


def sample(replay: Replay, key: jax.Array, morph: jax.Array, batch_size: int) -> Batch:
    """``batch_size`` transitions of morphology ``morph`` (a traced index), uniformly
    with replacement from its filled slots (as the reference's ``randint``)."""
    index = jax.random.randint(key, (batch_size,), 0, jnp.maximum(replay.size[morph], 1))
    return Batch(
        obs=replay.obs[morph, index],
        action=replay.action[morph, index],
        reward=replay.reward[morph, index],
        next_obs=replay.next_obs[morph, index],
        terminated=replay.terminated[morph, index],
    )


def sample_each(replay: Replay, key: jax.Array, morphs: jax.Array, batch_size: int) -> Batch:
    """One batch per listed morphology, stacked ``[len(morphs), batch_size, ...]``."""
    keys = jax.random.split(key, morphs.shape[0])
    return jax.vmap(sample, in_axes=(None, 0, 0, None))(replay, keys, morphs, batch_size)
