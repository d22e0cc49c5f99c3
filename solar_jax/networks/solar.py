"""SOLAR's synergy-aware actor and critic (SPEC section 4).

Shapes: B batch, N = N_max agents (torso first, padded), K = K_max = N_max synergies
(padded), F input features (19 observation, critic 20 with the action), W width, S the
transform's heads, d its dimension. One morphology per call (its agent mask, synergy
structure and traversal are unbatched); vmap over morphologies at the edge.
"""

import flax.linen as nn
import jax
import jax.numpy as jnp

from solar_jax.networks.common import MLP, mask_actions, mask_inputs, masked_mean
from solar_jax.networks.config import NetworkConfig
from solar_jax.networks.transformer import AgentEncoder, EncoderLayer, final_norm, key_mask_pairs
from solar_jax.synergy import Synergy

TRANSFORM = "transform"  # top-level key of the action transformation's parameters


def intra_synergy_attention(
    config: NetworkConfig, agent_mask: jax.Array, synergy: Synergy
) -> tuple[jax.Array, jax.Array | None]:
    """Layer 0's (allowed ``[N, N]`` bool, bias ``[N, N]`` or None) for a synergy structure.

    Soft (default, the code's): additive log(Ŵ Ŵᵀ), nothing blocked but padded keys.
    Hard (``config.hard_mask``, the paper's text): attention across synergies blocked.
    """
    allowed = key_mask_pairs(agent_mask)
    if config.hard_mask:
        return allowed & (synergy.hard_mask | ~agent_mask[:, None]), None
    return allowed, synergy.attention_bias


class SynergyTransformer(nn.Module):
    """Encoder, intra-synergy layer, pooling, inter-synergy layers, final LN, decoder.

    ``x`` ``[B, N, F]`` -> (one output per synergy ``[B, K]``, zero for invalid synergies;
    the per-agent encoder output ``[B, N, W]``, which the action transform's gate reads).
    """

    config: NetworkConfig

    @nn.compact
    def __call__(
        self, x: jax.Array, agent_mask: jax.Array, synergy: Synergy
    ) -> tuple[jax.Array, jax.Array]:
        c = self.config
        x = mask_inputs(x, agent_mask)
        encoded = AgentEncoder(c.width, name="encoder")(x)
        allowed, bias = intra_synergy_attention(c, agent_mask, synergy)
        h = EncoderLayer(c.width, c.heads, c.feedforward, name="layer_0")(encoded, allowed, bias)
        # Pooling: token k = mean of layer-0 outputs over synergy k's members (the torso
        # synergy: all real agents); the decoder's raw features are pooled the same way.
        pool = synergy.pool_weights  # [N, K]
        tokens = jnp.einsum("nk,bnw->bkw", pool, h)
        raw = jnp.einsum("nk,bnf->bkf", pool, x)
        valid = synergy.synergy_mask  # [K]
        for i in range(1, c.num_layers):
            tokens = EncoderLayer(c.width, c.heads, c.feedforward, name=f"layer_{i}")(
                tokens, key_mask_pairs(valid)
            )
        tokens = final_norm()(tokens)
        out = nn.Dense(1, name="decoder")(jnp.concatenate([tokens, raw], axis=-1))[..., 0]
        return jnp.where(valid, out, 0.0), encoded


class ActionTransform(nn.Module):
    """Synergy actions ``y`` ``[B, K]`` -> agent actions ``[B, N]`` in [-1, 1] (SPEC section 4).

    Structure embedding: three tables (N rows, indexed by pre-, in- and post-order
    positions) concatenated, then Linear(3E -> S·d), read per agent as S heads of
    [k1, e_1 .. e_{d-1}]. Per head, A_s = e_s e_sᵀ / d - diag(k1_s) ``[N, N]``.

    Code's variant (default): T0[s, n, k] = A_s[exemplar_k, n] · W[n, k]; a gate MLP on
    [encoded input, structure embedding] gives G[s, n];
    a_n = tanh(mean_s G[s, n] Σ_k T0[s, n, k] y_k).

    Paper-text variant (``paper_transform``), as read here: the same A_s plays the
    relation matrix H; T[s, n, k] = mean over the members j of synergy k of A_s[n, j]
    (the torso synergy averages over all real agents), no membership mask, no gate;
    a_n = tanh(mean_s Σ_k T[s, n, k] y_k).

    The torso's and padded agents' actions are returned as 0.
    """

    config: NetworkConfig

    @nn.compact
    def __call__(
        self,
        y: jax.Array,
        encoded: jax.Array,
        agent_mask: jax.Array,
        synergy: Synergy,
        traversal: jax.Array,
    ) -> jax.Array:
        c = self.config
        n = traversal.shape[0]
        index = jnp.clip(traversal, 0, n - 1)  # padded rows may hold anything
        embedding = jnp.concatenate(
            [
                nn.Embed(n, c.embedding_dim, name=f"{order}_order")(index[:, i])
                for i, order in enumerate(("pre", "in", "post"))
            ],
            axis=-1,
        )  # [N, 3E]
        structure = nn.Dense(c.transform_heads * c.transform_dim, name="structure")(embedding)
        per_head = structure.reshape(n, c.transform_heads, c.transform_dim)
        k1, e = per_head[..., 0], per_head[..., 1:]  # [N, S], [N, S, d-1]
        relation = jnp.einsum("isd,jsd->sij", e, e) / c.transform_dim
        relation = relation - k1.T[:, :, None] * jnp.eye(n)  # A [S, N, N]
        y = jnp.where(synergy.synergy_mask, y, 0.0)
        if c.paper_transform:
            t = jnp.einsum("snj,jk->snk", relation, synergy.pool_weights)
            action = jnp.einsum("snk,bk->bn", t, y) / c.transform_heads
        else:
            exemplars = jnp.clip(synergy.exemplars, 0, n - 1)  # invalid k: W[:, k] = 0
            t0 = jnp.swapaxes(relation[:, exemplars, :], 1, 2) * synergy.membership  # [S, N, K]
            mixed = jnp.einsum("snk,bk->bns", t0, y)
            gate_in = jnp.concatenate(
                [encoded, jnp.broadcast_to(structure, (*encoded.shape[:-1], structure.shape[-1]))],
                axis=-1,
            )
            gate = MLP((c.gate_hidden, c.transform_heads), name="gate")(gate_in)  # [B, N, S]
            action = jnp.mean(gate * mixed, axis=-1)
        return mask_actions(jnp.tanh(action), agent_mask)


class SolarActor(nn.Module):
    """``obs`` ``[B, N, 19]`` -> actions ``[B, N]``; params {"trunk", "transform"}."""

    config: NetworkConfig

    @nn.compact
    def __call__(
        self, obs: jax.Array, agent_mask: jax.Array, synergy: Synergy, traversal: jax.Array
    ) -> jax.Array:
        y, encoded = SynergyTransformer(self.config, name="trunk")(obs, agent_mask, synergy)
        return ActionTransform(self.config, name=TRANSFORM)(
            y, encoded, agent_mask, synergy, traversal
        )


class SolarCritic(nn.Module):
    """(``obs`` ``[B, N, 19]``, ``action`` ``[B, N]``) -> Q ``[B]``: the mean over valid
    synergies of one Q per synergy. The torso's and padded actions are zeroed first."""

    config: NetworkConfig

    @nn.compact
    def __call__(
        self, obs: jax.Array, action: jax.Array, agent_mask: jax.Array, synergy: Synergy
    ) -> jax.Array:
        x = jnp.concatenate([obs, mask_actions(action, agent_mask)[..., None]], axis=-1)
        q, _ = SynergyTransformer(self.config, name="trunk")(x, agent_mask, synergy)
        return masked_mean(q, synergy.synergy_mask)
