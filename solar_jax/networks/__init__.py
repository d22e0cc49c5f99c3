"""Flax networks (algorithm.md §4): SOLAR's synergy-aware actor and critic, and the
Amorpheus, SMP and monolithic baselines, behind one interface chosen by method name.

>>> nets = make_networks("solar", NetworkConfig(), n_max=9)  # solar_jax.config
>>> actor_params, critic_params = nets.init(jax.random.key(0))
>>> actions = nets.act(actor_params, obs, agent_mask, synergy, traversal)  # [B, N]
>>> q = nets.q(critic_params, obs, actions, agent_mask, synergy)  # [2, B]

SOLAR's actor keeps its synergy module (traversal embeddings and their Linear) under
``actor_params["transform"]`` (``TRANSFORM``) and the transform's gate MLP under
``actor_params["gate"]`` (``GATE``): the reference optimises them in different groups
(``solar_jax.agent.state``). Initialisation is the reference's (``networks/init.py``).
"""

from solar_jax.networks.common import DIAGNOSTICS, actuated_mask, pad_traversal
from solar_jax.networks.registry import (
    METHODS,
    NUM_CRITICS,
    OBS_SIZE,
    Networks,
    Structure,
    example_inputs,
    make_networks,
)
from solar_jax.networks.smp import Tree, limb_trees, make_tree
from solar_jax.networks.solar import GATE, TRANSFORM

__all__ = [
    "DIAGNOSTICS",
    "GATE",
    "METHODS",
    "NUM_CRITICS",
    "OBS_SIZE",
    "TRANSFORM",
    "Networks",
    "Structure",
    "Tree",
    "actuated_mask",
    "example_inputs",
    "limb_trees",
    "make_networks",
    "make_tree",
    "pad_traversal",
]
