"""Transformer pieces shared by SOLAR and Amorpheus (algorithm.md §4).

Post-LayerNorm encoder layers as PyTorch's ``nn.TransformerEncoderLayer`` builds them
(ReLU feed-forward, LayerNorm eps 1e-5), with an optional additive attention bias and a
boolean mask of allowed (query, key) pairs. Dropout is 0 in SOLAR, so there is none. No
positional encoding: agents are a set, told apart only by their observations.
"""

import math

import flax.linen as nn
import jax
import jax.numpy as jnp

from solar_jax.networks.common import DenseParams

LAYER_NORM_EPS = 1e-5  # PyTorch's default, which the reference uses
_QKV = ("query", "key", "value")


class AgentEncoder(nn.Module):
    """Per-agent Linear(F -> width) times sqrt(width) (algorithm.md §4):
    ``[..., F] -> [..., W]``."""

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

        # One [W, 3W] product for the query, key and value projections (kept as three
        # parameter sets, the in-projection's thirds): one larger GEMM runs faster on CPU
        # than three (benchmarks/README.md, learner).
        params = [DenseParams(self.width, name=n)(x.shape[-1]) for n in _QKV]
        kernels, offsets = zip(*params, strict=True)
        qkv = x @ jnp.concatenate(kernels, axis=-1) + jnp.concatenate(offsets, axis=-1)
        qkv = qkv.reshape(*x.shape[:-1], 3, self.heads, head_dim)
        q, k, v = qkv[..., 0, :, :], qkv[..., 1, :, :], qkv[..., 2, :, :]  # [B, T, H, W / H]
        # Products and sums over broadcast axes rather than einsum: with so few tokens
        # (T <= N_max) the batched [T, T] dots ran at a few GFLOP/s on XLA:CPU, the fused
        # loops several times faster (benchmarks/README.md, learner).
        pairs = q[..., :, None, :, :] * k[..., None, :, :, :]  # [B, Q, K, H, W / H]
        logits = jnp.sum(pairs, axis=-1) / math.sqrt(head_dim)  # [B, Q, K, H]
        if bias is not None:
            logits = logits + bias[..., None]
        # The dtype's minimum, not -inf: a fully masked row then softmaxes to uniform, not NaN.
        logits = jnp.where(allowed[..., None], logits, jnp.finfo(logits.dtype).min)
        weights = jax.nn.softmax(logits, axis=-2)  # over keys
        attended = jnp.sum(weights[..., None] * v[..., None, :, :, :], axis=-3)  # [B, Q, H, W/H]
        attended = attended.reshape(x.shape)
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
