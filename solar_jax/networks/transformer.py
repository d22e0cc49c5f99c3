"""Transformer pieces shared by SOLAR and Amorpheus (SPEC section 4).

Post-LayerNorm encoder layers as PyTorch's ``nn.TransformerEncoderLayer`` builds them
(ReLU feed-forward, LayerNorm eps 1e-5), with an optional additive attention bias and a
boolean mask of allowed (query, key) pairs. Dropout is 0 in SOLAR, so there is none. No
positional encoding: agents are a set, told apart only by their observations.
"""

import math

import flax.linen as nn
import jax
import jax.numpy as jnp

LAYER_NORM_EPS = 1e-5  # PyTorch's default, which the reference uses


class AgentEncoder(nn.Module):
    """Per-agent Linear(F -> width) times sqrt(width) (SPEC section 4): ``[..., F] -> [..., W]``."""

    width: int

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        return nn.Dense(self.width, name="dense")(x) * math.sqrt(self.width)


def key_mask_pairs(key_mask: jax.Array) -> jax.Array:
    """``[T] -> [T, T]`` bool (query, key): every query may attend to every valid key."""
    return jnp.broadcast_to(key_mask[None, :], key_mask.shape * 2)


class EncoderLayer(nn.Module):
    """Post-LN layer: x = LN(x + MHA(x)); x = LN(x + FF(x)). ``[B, T, W] -> [B, T, W]``."""

    width: int
    heads: int
    feedforward: int

    @nn.compact
    def __call__(
        self, x: jax.Array, allowed: jax.Array, bias: jax.Array | None = None
    ) -> jax.Array:
        """``allowed`` ``[T, T]`` bool (query, key); ``bias`` ``[T, T]`` added to the logits.

        A query with no allowed key (a padded token) attends uniformly: finite, and
        never read by a valid token because padded keys are never allowed.
        """
        head_dim = self.width // self.heads

        def heads(name: str) -> jax.Array:  # [B, T, W] -> [B, T, H, W / H]
            y = nn.Dense(self.width, name=name)(x)
            return y.reshape(*y.shape[:-1], self.heads, head_dim)

        q, k, v = heads("query"), heads("key"), heads("value")
        logits = jnp.einsum("bqhd,bkhd->bhqk", q, k) / math.sqrt(head_dim)
        if bias is not None:
            logits = logits + bias
        # The dtype's minimum, not -inf: a fully masked row then softmaxes to uniform, not NaN.
        logits = jnp.where(allowed, logits, jnp.finfo(logits.dtype).min)
        weights = jax.nn.softmax(logits, axis=-1)
        attended = jnp.einsum("bhqk,bkhd->bqhd", weights, v).reshape(x.shape)
        x = nn.LayerNorm(epsilon=LAYER_NORM_EPS, name="norm_attention")(
            x + nn.Dense(self.width, name="out")(attended)
        )
        y = nn.Dense(self.width, name="ff_out")(
            nn.relu(nn.Dense(self.feedforward, name="ff_in")(x))
        )
        return nn.LayerNorm(epsilon=LAYER_NORM_EPS, name="norm_ff")(x + y)


def final_norm() -> nn.LayerNorm:
    """The LayerNorm after the last layer (PyTorch ``TransformerEncoder(norm=...)``)."""
    return nn.LayerNorm(epsilon=LAYER_NORM_EPS, name="final_norm")
