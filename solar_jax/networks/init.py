"""The reference's initialisation (algorithm.md §4), applied to a Flax parameter tree.

Flax's default initialisers differ from PyTorch's by large factors for these networks
(embeddings 1/8 of the std, the gate about 6x larger), so the default
(``NetworkConfig.init="reference"``) re-draws every parameter by the authors' rules:

    encoder (``encoder/dense``)   weight U(±0.1), bias PyTorch's default
    decoder                       weight U(±0.1), bias 0
    attention query/key/value     xavier-uniform over the in-projection [3W, W], bias 0
    attention out                 PyTorch's default weight, bias 0
    every other Dense             PyTorch's default: weight and bias U(±1/√fan_in)
    Embed                         N(0, 1)
    LayerNorm                     scale 1, bias 0

and then copies ``layer_0`` onto every ``layer_i`` of the same network (the reference
deep-copies one layer). Leading axes (the twin critics' 2) are drawn independently, so
the critics differ from each other. Shapes: kernels ``[..., fan_in, fan_out]``.
"""

import math
import re
from typing import Any

import jax
import jax.numpy as jnp
from flax import traverse_util

Params = Any  # a Flax parameter tree

INIT_RANGE = 0.1  # the reference's encoder and decoder weights (TransformerModel.init_weights)
_ATTENTION_IN = ("query", "key", "value")
_LAYER = re.compile(r"layer_(\d+)")


def reference_init(params: Params, key: jax.Array) -> Params:
    """``params`` re-drawn by the reference's rules (module docstring), same structure."""
    flat = traverse_util.flatten_dict(params)
    modules = sorted({path[:-1] for path in flat})
    out = {}
    for index, module in enumerate(modules):
        leaves = {path[-1]: value for path, value in flat.items() if path[:-1] == module}
        drawn = _module_init(module, leaves, jax.random.fold_in(key, index))
        out |= {(*module, name): value for name, value in drawn.items()}
    return _identical_layers(traverse_util.unflatten_dict(out))


def _module_init(path: tuple, leaves: dict, key: jax.Array) -> dict:
    """One module's leaves (a Dense's kernel and bias, an Embed's table, a LayerNorm's)."""
    if "embedding" in leaves:
        return {"embedding": jax.random.normal(key, leaves["embedding"].shape)}
    if "kernel" not in leaves:  # LayerNorm: PyTorch's 1 and 0 (Flax's too)
        return {
            name: jnp.full_like(v, 1.0 if name == "scale" else 0.0) for name, v in leaves.items()
        }
    kernel = leaves["kernel"]
    fan_in, fan_out = kernel.shape[-2:]
    default = 1.0 / math.sqrt(fan_in)  # PyTorch Linear: kaiming_uniform(a=√5), bias alike
    name = path[-1]
    if path[-2:] == ("encoder", "dense"):
        weight, bias = INIT_RANGE, default
    elif name == "decoder":
        weight, bias = INIT_RANGE, 0.0
    elif name in _ATTENTION_IN:  # one third of nn.MultiheadAttention's in_proj [3W, W]
        weight, bias = math.sqrt(6.0 / (fan_in + 3 * fan_out)), 0.0
    elif name == "out":  # MultiheadAttention zeroes out_proj.bias
        weight, bias = default, 0.0
    else:
        weight, bias = default, default
    kernel_key, bias_key = jax.random.split(key)
    drawn = {"kernel": _uniform(kernel_key, kernel.shape, weight)}
    if "bias" in leaves:
        drawn["bias"] = _uniform(bias_key, leaves["bias"].shape, bias)
    return drawn


def _uniform(key: jax.Array, shape: tuple, bound: float) -> jax.Array:
    if bound == 0.0:
        return jnp.zeros(shape, jnp.float32)
    return jax.random.uniform(key, shape, jnp.float32, -bound, bound)


def _identical_layers(tree):
    """Every ``layer_i`` of one network a copy of its ``layer_0`` (``_get_clones``)."""
    if not isinstance(tree, dict):
        return tree
    tree = {k: _identical_layers(v) for k, v in tree.items()}
    if "layer_0" in tree:
        for name in tree:
            if _LAYER.fullmatch(name) and name != "layer_0":
                tree[name] = jax.tree.map(jnp.array, tree["layer_0"])
    return tree
