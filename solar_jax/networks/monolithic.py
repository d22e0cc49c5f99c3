"""The monolithic baseline (algorithm.md §4): TD3's MLPs over the zero-padded, flattened
observation of all N_max agents (and, for the critic, their actions). Shapes as in
``solar.py``; unlike the transformers, its parameters depend on N_max.
"""

import flax.linen as nn
import jax
import jax.numpy as jnp

from solar_jax.config import NetworkConfig
from solar_jax.networks.common import DIAGNOSTICS, MLP, mask_actions, mask_inputs
from solar_jax.synergy import Synergy


def _flatten(obs: jax.Array, agent_mask: jax.Array) -> jax.Array:
    """``[B, N, F] -> [B, N·F]`` with padded agents' features zeroed."""
    obs = mask_inputs(obs, agent_mask)
    return obs.reshape(*obs.shape[:-2], -1)


class MonolithicActor(nn.Module):
    """``obs`` ``[B, N, 19]`` -> actions ``[B, N]``: MLP -> N outputs, tanh, padding (and
    the torso without ``torso_action``) 0."""

    config: NetworkConfig

    @nn.compact
    def __call__(
        self,
        obs: jax.Array,
        agent_mask: jax.Array,
        synergy: Synergy | None = None,
        traversal: jax.Array | None = None,
    ) -> jax.Array:
        del synergy, traversal  # the interface's; unused
        sizes = (*self.config.mlp_hidden, obs.shape[-2])
        out = MLP(sizes, name="mlp")(_flatten(obs, agent_mask))
        self.sow(DIAGNOSTICS, "pre_tanh", out)
        return mask_actions(jnp.tanh(out), agent_mask, self.config.torso_action)


class MonolithicCritic(nn.Module):
    """(``obs``, ``action``) -> Q ``[B]``; padded actions (and the torso's, without
    ``torso_action``) are zeroed first."""

    config: NetworkConfig

    @nn.compact
    def __call__(
        self,
        obs: jax.Array,
        action: jax.Array,
        agent_mask: jax.Array,
        synergy: Synergy | None = None,
    ) -> jax.Array:
        del synergy
        action = mask_actions(action, agent_mask, self.config.torso_action)
        x = jnp.concatenate([_flatten(obs, agent_mask), action], -1)
        return MLP((*self.config.mlp_hidden, 1), name="mlp")(x)[..., 0]
