"""SOLAR's synergy-aware actor and critic (algorithm.md §4).

Shapes: B batch, N = N_max agents (torso first, padded), K = K_max = N_max synergies
(padded), F input features (19 observation, critic 20 with the action), W width, S the
transform's heads, d its dimension. One morphology per call (its agent mask, synergy
structure and traversal are unbatched); vmap over morphologies at the edge.
"""

import flax.linen as nn
import jax
import jax.numpy as jnp

from solar_jax.config import NetworkConfig
from solar_jax.networks.common import (
    DIAGNOSTICS,
    DenseParams,
    mask_actions,
    mask_inputs,
    masked_mean,
)
from solar_jax.networks.transformer import AgentEncoder, EncoderLayer, final_norm, key_mask_pairs
from solar_jax.synergy import Synergy

TRANSFORM = "transform"  # the actor's key of the synergy module (embeddings + Linear)
GATE = "gate"  # the actor's key of the action transformation's gate MLP


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


class SynergyModule(nn.Module):
    """The synergy module (algorithm.md §4; the reference's ``Synergy``): three traversal
    embedding tables (N rows, indexed by pre-, in- and post-order position) concatenated,
    then Linear(3E -> S·d), read per agent as S heads of [k1, e_1 .. e_{d-1}].

    ``traversal`` ``[N, 3]`` -> (relation A ``[S, N, N]`` with A_s = e_s e_sᵀ / d -
    diag(k1_s); the structure embedding ``[N, S·d]``, which the gate reads).
    """

    config: NetworkConfig

    @nn.compact
    def __call__(self, traversal: jax.Array) -> tuple[jax.Array, jax.Array]:
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
        return relation - k1.T[:, :, None] * jnp.eye(n), structure


class Gate(nn.Module):
    """The action transformation's gate MLP (the reference's ``act_weight``): each agent's
    encoded input and its structure embedding -> hidden -> ReLU -> S. ``encoded``
    ``[B, N, W]``, ``structure`` ``[N, S·d]`` -> G ``[B, N, S]``.

    The first layer's kernel ``[W + S·d, hidden]`` is applied in two parts: the structure
    embedding is the same for every sample, so its part is computed once per agent, not
    once per sample (at the paper's sizes 256 of the layer's 384 inputs, two thirds of
    the gate's work). The parameters are ``MLP((hidden, S))``'s, ``dense_0``, ``dense_1``."""

    hidden: int
    heads: int

    @nn.compact
    def __call__(self, encoded: jax.Array, structure: jax.Array) -> jax.Array:
        width = encoded.shape[-1]
        kernel, bias = DenseParams(self.hidden, name="dense_0")(width + structure.shape[-1])
        first = encoded @ kernel[:width] + (structure @ kernel[width:] + bias)  # [B, N, hidden]
        return nn.Dense(self.heads, name="dense_1")(nn.relu(first))


def transform_actions(
    config: NetworkConfig,
    relation: jax.Array,
    synergy: Synergy,
    y: jax.Array,
    gate: jax.Array | None,
) -> jax.Array:
    """Synergy actions ``y`` ``[B, K]`` -> agent actions before the tanh ``[B, N]``.

    Code's variant (default): T0[s, n, k] = A_s[exemplar_k, n] · W[n, k] and, with the
    gate G ``[B, N, S]``, a_n = mean_s G[s, n] Σ_k T0[s, n, k] y_k.

    Paper-text variant (``paper_transform``, ``gate`` None), as read here: the same A_s
    plays the relation matrix H; T[s, n, k] = mean over the members j of synergy k of
    A_s[n, j] (the torso synergy averages over all real agents), no membership mask;
    a_n = mean_s Σ_k T[s, n, k] y_k.
    """
    n = relation.shape[-1]
    y = jnp.where(synergy.synergy_mask, y, 0.0)
    if config.paper_transform:
        t = jnp.einsum("snj,jk->snk", relation, synergy.pool_weights)
        return jnp.einsum("snk,bk->bn", t, y) / config.transform_heads
    exemplars = jnp.clip(synergy.exemplars, 0, n - 1)  # invalid k: W[:, k] = 0
    t0 = jnp.swapaxes(relation[:, exemplars, :], 1, 2) * synergy.membership  # [S, N, K]
    mixed = jnp.einsum("snk,bk->bns", t0, y)
    return jnp.mean(gate * mixed, axis=-1)


class SolarActor(nn.Module):
    """``obs`` ``[B, N, 19]`` -> actions ``[B, N]`` in [-1, 1], 0 for padded agents (and
    for the torso without ``torso_action``).

    Parameters {"trunk", ``TRANSFORM``, ``GATE``}, apart because the reference optimises
    them apart (algorithm.md §4): the synergy module has its own Adam and no target copy;
    the gate MLP (width + S·d -> gate_hidden -> ReLU -> S, code's variant only) is an
    actor parameter. Sows the pre-tanh action and the gate as ``DIAGNOSTICS``.
    """

    config: NetworkConfig

    @nn.compact
    def __call__(
        self, obs: jax.Array, agent_mask: jax.Array, synergy: Synergy, traversal: jax.Array
    ) -> jax.Array:
        c = self.config
        y, encoded = SynergyTransformer(c, name="trunk")(obs, agent_mask, synergy)
        relation, structure = SynergyModule(c, name=TRANSFORM)(traversal)
        gate = None
        if not c.paper_transform:
            gate = Gate(c.gate_hidden, c.transform_heads, name=GATE)(encoded, structure)
            self.sow(DIAGNOSTICS, "gate_values", gate)
        action = transform_actions(c, relation, synergy, y, gate)
        self.sow(DIAGNOSTICS, "pre_tanh", action)
        return mask_actions(jnp.tanh(action), agent_mask, c.torso_action)


class SolarCritic(nn.Module):
    """(``obs`` ``[B, N, 19]``, ``action`` ``[B, N]``) -> Q ``[B]``: the mean over valid
    synergies of one Q per synergy. Padded actions (and the torso's, without
    ``torso_action``) are zeroed first."""

    config: NetworkConfig

    @nn.compact
    def __call__(
        self, obs: jax.Array, action: jax.Array, agent_mask: jax.Array, synergy: Synergy
    ) -> jax.Array:
        action = mask_actions(action, agent_mask, self.config.torso_action)
        x = jnp.concatenate([obs, action[..., None]], axis=-1)
        q, _ = SynergyTransformer(self.config, name="trunk")(x, agent_mask, synergy)
        return masked_mean(q, synergy.synergy_mask)
