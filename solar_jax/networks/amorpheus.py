"""The Amorpheus baseline (algorithm.md §4): SOLAR's transformer over agents, no synergy.

No bias or mask beyond padding, no pooling; one action and one Q per agent. The
``amorpheus_mask`` ablation adds SOLAR's intra-synergy attention (soft bias by default,
the hard mask with ``config.hard_mask``) to the first layer only. Shapes as in
``solar.py``. Permutation-equivariant over agents (no positional encoding), apart from
agent 0 being the torso (whose action is zeroed without ``torso_action``).
"""

import flax.linen as nn
import jax
import jax.numpy as jnp

from solar_jax.config import NetworkConfig
from solar_jax.networks.common import DIAGNOSTICS, mask_actions, mask_inputs
from solar_jax.networks.solar import intra_synergy_attention
from solar_jax.networks.transformer import AgentEncoder, EncoderLayer, final_norm, key_mask_pairs
from solar_jax.synergy import Synergy


class AgentTransformer(nn.Module):
    """``x`` ``[B, N, F]`` -> one output per agent ``[B, N]``: encoder, layers, final LN,
    then Linear(W + F -> 1) on each agent's token concatenated with its raw input."""

    config: NetworkConfig
    synergy_bias: bool = False
    """Give the first layer SOLAR's intra-synergy attention (the amorpheus_mask ablation)."""

    @nn.compact
    def __call__(self, x: jax.Array, agent_mask: jax.Array, synergy: Synergy | None) -> jax.Array:
        c = self.config
        x = mask_inputs(x, agent_mask)
        h = AgentEncoder(c.width, name="encoder")(x)
        for i in range(c.num_layers):
            allowed, bias = key_mask_pairs(agent_mask), None
            if i == 0 and self.synergy_bias:
                allowed, bias = intra_synergy_attention(c, agent_mask, synergy)
            h = EncoderLayer(c.width, c.heads, c.feedforward, name=f"layer_{i}")(h, allowed, bias)
        h = final_norm()(h)
        return nn.Dense(1, name="decoder")(jnp.concatenate([h, x], axis=-1))[..., 0]


class AmorpheusActor(nn.Module):
    """``obs`` ``[B, N, 19]`` -> actions ``[B, N]`` (tanh; padding, and the torso without
    ``torso_action``, 0)."""

    config: NetworkConfig
    synergy_bias: bool = False

    @nn.compact
    def __call__(
        self,
        obs: jax.Array,
        agent_mask: jax.Array,
        synergy: Synergy | None = None,
        traversal: jax.Array | None = None,
    ) -> jax.Array:
        del traversal  # the interface's; Amorpheus has no action transformation
        out = AgentTransformer(self.config, self.synergy_bias, name="trunk")(
            obs, agent_mask, synergy
        )
        self.sow(DIAGNOSTICS, "pre_tanh", out)
        return mask_actions(jnp.tanh(out), agent_mask, self.config.torso_action)


class AmorpheusCritic(nn.Module):
    """(``obs``, ``action``) -> per-agent Q ``[B, N]``, 0 for padded agents (the torso's
    Q is kept). Padded actions (and the torso's, without ``torso_action``) are zeroed first."""

    config: NetworkConfig
    synergy_bias: bool = False

    @nn.compact
    def __call__(
        self,
        obs: jax.Array,
        action: jax.Array,
        agent_mask: jax.Array,
        synergy: Synergy | None = None,
    ) -> jax.Array:
        action = mask_actions(action, agent_mask, self.config.torso_action)
        x = jnp.concatenate([obs, action[..., None]], axis=-1)
        q = AgentTransformer(self.config, self.synergy_bias, name="trunk")(x, agent_mask, synergy)
        return jnp.where(agent_mask, q, 0.0)
