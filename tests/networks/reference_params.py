"""The authors' PyTorch parameters as our Flax trees.

``ref`` maps ``"<tag>/<module>/<state_dict key>"`` to arrays (the fixture's layout, and
``benchmarks/reference.py``'s ``reference_parameters``). Names map one to one; the only
reorderings are the synergy module's output, which the reference reads as [N, d, S]
(``key.reshape(N, E, SD)``) and ours as [N, S, d], and the gate's input, [structure,
encoded] there and [encoded, structure] here.
"""

import jax
import jax.numpy as jnp
import numpy as np

from solar_jax.config import NetworkConfig

HEADS = 4  # the reference's D_AGG: heads of the action transformation


def dense(ref, key, rows=None):
    """A torch Linear's (weight [out, in], bias) as a Flax Dense {"kernel" [in, out], "bias"}."""
    kernel = ref[f"{key}.weight"].T
    if rows is not None:
        kernel = kernel[rows]
    return {"kernel": jnp.asarray(kernel), "bias": jnp.asarray(ref[f"{key}.bias"])}


def norm(ref, key):
    return {"scale": jnp.asarray(ref[f"{key}.weight"]), "bias": jnp.asarray(ref[f"{key}.bias"])}


def trunk(ref, prefix: str, config: NetworkConfig):
    """A reference TransformerModel's encoder, layers, final norm and decoder."""
    p = {
        "encoder": {"dense": dense(ref, f"{prefix}/encoder")},
        "decoder": dense(ref, f"{prefix}/decoder"),
        "final_norm": norm(ref, f"{prefix}/transformer_encoder.norm"),
    }
    w = config.width
    for i in range(config.num_layers):
        layer = f"{prefix}/transformer_encoder.layers.{i}"
        in_w = ref[f"{layer}.self_attn.in_proj_weight"]
        in_b = ref[f"{layer}.self_attn.in_proj_bias"]
        p[f"layer_{i}"] = {
            name: {
                "kernel": jnp.asarray(in_w[j * w : (j + 1) * w].T),
                "bias": jnp.asarray(in_b[j * w : (j + 1) * w]),
            }
            for j, name in enumerate(("query", "key", "value"))
        } | {
            "out": dense(ref, f"{layer}.self_attn.out_proj"),
            "ff_in": dense(ref, f"{layer}.linear1"),
            "ff_out": dense(ref, f"{layer}.linear2"),
            "norm_attention": norm(ref, f"{layer}.norm1"),
            "norm_ff": norm(ref, f"{layer}.norm2"),
        }
    return p


def ours_from_theirs(config: NetworkConfig, s: int = HEADS) -> np.ndarray:
    """Index map ours [S, d] flat -> theirs [d, S] flat, for the synergy module's output."""
    d = config.transform_dim
    return np.array([e * s + h for h in range(s) for e in range(d)])


def solar_actor(ref, tag: str, config: NetworkConfig, n_max: int, actor: str = "actor"):
    """SOLAR's actor: trunk, synergy module (traversal embeddings padded to ``n_max``
    rows) and gate."""
    order = ours_from_theirs(config)
    structure = dense(ref, f"{tag}/synergy/action_attn.aggregate")
    structure = {k: jnp.asarray(np.asarray(v)[..., order]) for k, v in structure.items()}
    tables = {}
    for i, name in enumerate(("pre", "in", "post")):
        table = ref[f"{tag}/synergy/action_attn.embeds.{i}.weight"]  # [N, 64]: pad the rows
        table = np.pad(table, ((0, n_max - len(table)), (0, 0)))
        tables[f"{name}_order"] = {"embedding": jnp.asarray(table)}
    gate_rows = np.concatenate([HEADS * config.transform_dim + np.arange(config.width), order])
    return {
        "trunk": trunk(ref, f"{tag}/{actor}", config),
        "transform": tables | {"structure": structure},
        "gate": {
            "dense_0": dense(ref, f"{tag}/{actor}/act_weight.0", rows=gate_rows),
            "dense_1": dense(ref, f"{tag}/{actor}/act_weight.2"),
        },
    }


def amorpheus_actor(ref, tag: str, config: NetworkConfig, actor: str = "actor"):
    return {"trunk": trunk(ref, f"{tag}/{actor}", config)}


def critics(ref, tag: str, config: NetworkConfig, critic: str = "critic"):
    """The twin critics, stacked on a leading axis of 2."""
    twins = [trunk(ref, f"{tag}/{critic}{i}", config) for i in (1, 2)]
    # Stacked on the host: an eager ``jnp.stack`` compiles a program per leaf shape.
    return {"trunk": jax.tree.map(lambda a, b: jnp.asarray(np.stack([a, b])), *twins)}


def policy_group(actor):
    """The actor's parameters that have a target copy: the trunk and, for SOLAR, the gate."""
    return {k: actor[k] for k in ("trunk", "gate") if k in actor}
