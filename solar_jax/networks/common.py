"""Masks, pooling and small blocks shared by every network (algorithm.md §1 and §4)."""

import flax.linen as nn
import jax
import jax.numpy as jnp

TORSO = 0  # agent 0 is the torso (algorithm.md §1): its action is ignored by the physics
DIAGNOSTICS = "diagnostics"  # the actors' sown intermediates (pre-tanh action, gate)


def actuated_mask(agent_mask: jax.Array) -> jax.Array:
    """``[N]`` bool: real agents with a motor (not the torso, not padding)."""
    return agent_mask & (jnp.arange(agent_mask.shape[-1]) != TORSO)


def acting_mask(agent_mask: jax.Array, torso_action: bool) -> jax.Array:
    """``[N]`` bool: the agents whose action the networks produce and read. The reference
    acts for the torso too (algorithm.md §2); without ``torso_action`` only actuators."""
    return agent_mask if torso_action else actuated_mask(agent_mask)


def mask_inputs(x: jax.Array, agent_mask: jax.Array) -> jax.Array:
    """Zeroes padded agents' features ``[B, N, F]`` so no padding value (even NaN) leaks."""
    return jnp.where(agent_mask[:, None], x, 0.0)


def mask_actions(action: jax.Array, agent_mask: jax.Array, torso_action: bool) -> jax.Array:
    """Zeroes padded agents' actions ``[B, N]``, and the torso's unless ``torso_action``."""
    return jnp.where(acting_mask(agent_mask, torso_action), action, 0.0)


def masked_mean(x: jax.Array, mask: jax.Array, axis: int = -1) -> jax.Array:
    """Mean of ``x`` over ``axis`` where ``mask`` (broadcast) holds; 0 if none does."""
    mask = jnp.broadcast_to(mask, x.shape)
    total = jnp.sum(jnp.where(mask, x, 0.0), axis=axis)
    return total / jnp.maximum(jnp.sum(mask, axis=axis), 1)


class DenseParams(nn.Module):
    """The parameters of ``nn.Dense(features)`` for inputs of ``fan_in`` features: the same
    names, initialisers and draws, returned as (kernel ``[fan_in, features]``, bias) for
    products the caller assembles itself (fused or split)."""

    features: int

    @nn.compact
    def __call__(self, fan_in: int) -> tuple[jax.Array, jax.Array]:
        kernel = self.param("kernel", nn.initializers.lecun_normal(), (fan_in, self.features))
        return kernel, self.param("bias", nn.initializers.zeros_init(), (self.features,))


class MLP(nn.Module):
    """Dense layers with ReLU between them; the last layer is linear."""

    sizes: tuple[int, ...]

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        for i, size in enumerate(self.sizes):
            x = nn.Dense(size, name=f"dense_{i}")(x)
            if i < len(self.sizes) - 1:
                x = nn.relu(x)
        return x


def pad_traversal(traversal, n_max: int) -> jax.Array:
    """A morphology's traversal ``[N, 3]`` (pre, in, post) zero-padded to ``[n_max, 3]`` int32."""
    traversal = jnp.asarray(traversal, jnp.int32)
    if traversal.shape[0] > n_max:
        raise ValueError(f"traversal has {traversal.shape[0]} agents, more than n_max = {n_max}")
    return jnp.zeros((n_max, 3), jnp.int32).at[: traversal.shape[0]].set(traversal)
