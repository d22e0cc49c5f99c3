"""One interface for every method, chosen by name (algorithm.md §4; STYLE habit 4).

>>> nets = make_networks("solar", NetworkConfig.tiny(), n_max=9)
>>> actor_params, critic_params = nets.init(jax.random.key(0))
>>> nets.act(actor_params, obs, agent_mask, synergy, traversal, tree)  # [B, N]
>>> nets.q(critic_params, obs, action, agent_mask, synergy, tree)  # [2, B] or [2, B, N]

Inputs, all padded to N_max and unbatched over morphologies (vmap over them): ``obs``
``[B, N, 19]``, ``action`` ``[B, N]``, ``agent_mask`` ``[N]`` bool (agent 0 the torso),
``synergy`` a ``Synergy`` whose ``agent_mask`` equals ``agent_mask``, ``traversal``
``[N, 3]`` int32 (``pad_traversal``), ``tree`` a ``Tree`` (``make_tree``). Methods that
ignore the synergy, traversal or tree accept None for them.
"""

import dataclasses
from typing import Any

import flax.linen as nn
import jax
import jax.numpy as jnp
from flax import struct

from solar_jax.config import NetworkConfig
from solar_jax.env.world import OBS_SIZE  # 19 per agent (algorithm.md §2)
from solar_jax.networks.amorpheus import AmorpheusActor, AmorpheusCritic
from solar_jax.networks.common import DIAGNOSTICS, acting_mask
from solar_jax.networks.init import reference_init
from solar_jax.networks.monolithic import MonolithicActor, MonolithicCritic
from solar_jax.networks.smp import SmpActor, SmpCritic, Tree
from solar_jax.networks.solar import SolarActor, SolarCritic
from solar_jax.synergy import Synergy

Params = Any  # a Flax parameter tree (nested dicts of arrays)

NUM_CRITICS = 2  # TD3's twin critics, one leading parameter axis


@dataclasses.dataclass(frozen=True)
class _Method:
    actor: type[nn.Module]
    critic: type[nn.Module]
    per_agent_q: bool
    uses_synergy: bool
    delta_q_preference: bool
    options: dict = dataclasses.field(default_factory=dict)  # extra module attributes
    uses_tree: bool = False  # the modules read the limb tree (their last argument)
    twin_critic: bool = False  # the critic module gives both Q itself (twin=True/False)


_METHODS = {
    "solar": _Method(SolarActor, SolarCritic, False, True, True),
    # The ablation lives in synergy discovery (the median preference always).
    "solar_no_pref": _Method(SolarActor, SolarCritic, False, True, False),
    "amorpheus": _Method(AmorpheusActor, AmorpheusCritic, True, False, False),
    "amorpheus_mask": _Method(
        AmorpheusActor, AmorpheusCritic, True, True, True, {"synergy_bias": True}
    ),
    "smp": _Method(SmpActor, SmpCritic, True, False, False, uses_tree=True, twin_critic=True),
    "monolithic": _Method(MonolithicActor, MonolithicCritic, False, False, False),
}
METHODS = tuple(_METHODS)


@struct.dataclass
class Structure:
    """What the networks read about one morphology (``[M, ...]`` when stacked)."""

    agent_mask: jax.Array  # [N] bool
    synergy: Synergy  # the current clustering
    traversal: jax.Array  # [N, 3] int32
    tree: Tree | None = None  # the limb tree (SMP's messages; None for the other methods)


@dataclasses.dataclass(frozen=True)
class Networks:
    """A method's actor and twin critic as pure functions of their parameters."""

    method: str
    config: NetworkConfig
    n_max: int
    obs_size: int
    actor: nn.Module
    """``(obs, agent_mask, synergy, traversal[, tree]) -> actions [B, N]`` in [-1, 1], 0
    for the torso and padded agents."""
    critic: nn.Module
    """``(obs, action, agent_mask, synergy[, tree]) -> Q``: ``[2, B]``, or ``[2, B, N]``
    per agent (0 for padded agents) where ``per_agent_q``. The torso's and padded actions
    are ignored."""
    first_critic: nn.Module
    """The first critic alone, for ``q1``: one of the twins (``critic`` without its leading
    axis), or, where the twins share a network (SMP), its first head."""
    per_agent_q: bool
    """Amorpheus: one Q and one TD target per agent; otherwise one Q per sample."""
    uses_synergy: bool
    """The networks read the synergy structure, so the trainer must discover it."""
    delta_q_preference: bool
    """Synergy discovery uses ΔQ preferences after the first clustering (False: the median
    always). Informational: discovery is the trainer's; with per-agent Q (amorpheus_mask)
    it would average the first critic's Q over real agents."""
    uses_tree: bool = False
    """The modules read the limb tree (SMP): ``tree`` is passed to them."""
    twin_critic: bool = False
    """The critic's parameters have no leading twin axis: one module gives both Q (SMP)."""

    def _tree(self, tree: Tree | None) -> tuple:
        return (tree,) if self.uses_tree else ()

    def init(self, key: jax.Array) -> tuple[Params, Params]:
        """(actor params, twin critic params, leading axis 2) from one key, drawn by the
        reference's rules unless ``config.init == "flax"`` (``networks/init.py``)."""
        actor_key, critic_key = jax.random.split(key)
        obs, action, agent_mask, synergy, traversal, tree = example_inputs(
            self.n_max, self.obs_size
        )
        tree = self._tree(tree)
        actor = self.actor.init(actor_key, obs, agent_mask, synergy, traversal, *tree)["params"]
        critic = self.critic.init(critic_key, obs, action, agent_mask, synergy, *tree)["params"]
        if self.config.init == "reference":
            # Flax's draws fix the tree's structure; the reference's replace every value.
            actor = reference_init(actor, jax.random.fold_in(actor_key, 1))
            critic = reference_init(critic, jax.random.fold_in(critic_key, 1))
        return actor, critic

    def act(
        self,
        params: Params,
        obs: jax.Array,
        agent_mask: jax.Array,
        synergy: Synergy | None = None,
        traversal: jax.Array | None = None,
        tree: Tree | None = None,
    ) -> jax.Array:
        tree = self._tree(tree)
        return self.actor.apply({"params": params}, obs, agent_mask, synergy, traversal, *tree)

    def acting_mask(self, agent_mask: jax.Array) -> jax.Array:
        """``[..., N]`` bool: the agents the actor acts for (the torso too by default)."""
        return acting_mask(agent_mask, self.config.torso_action)

    def act_diagnostics(
        self,
        params: Params,
        obs: jax.Array,
        agent_mask: jax.Array,
        synergy: Synergy | None = None,
        traversal: jax.Array | None = None,
        tree: Tree | None = None,
    ) -> tuple[jax.Array, dict]:
        """As ``act``, with the actor's intermediates: {"pre_tanh": ``[B, N]``} and, for
        SOLAR's gated transform, "gate_values": ``[B, N, S]``."""
        inputs = (obs, agent_mask, synergy, traversal, *self._tree(tree))
        action, state = self.actor.apply({"params": params}, *inputs, mutable=[DIAGNOSTICS])
        return action, {name: value[0] for name, value in state[DIAGNOSTICS].items()}

    def q(
        self,
        params: Params,
        obs: jax.Array,
        action: jax.Array,
        agent_mask: jax.Array,
        synergy: Synergy | None = None,
        tree: Tree | None = None,
    ) -> jax.Array:
        tree = self._tree(tree)
        return self.critic.apply({"params": params}, obs, action, agent_mask, synergy, *tree)

    def q1(
        self,
        params: Params,
        obs: jax.Array,
        action: jax.Array,
        agent_mask: jax.Array,
        synergy: Synergy | None = None,
        tree: Tree | None = None,
    ) -> jax.Array:
        """``q(...)[0]``, the first critic alone (the reference's ``Q1``, which the actor's
        loss and ΔQ read): ``[B]`` or ``[B, N]``. The twins run as one batched program, so
        slicing ``q`` would pay for the second critic, forward and backward."""
        first = params if self.twin_critic else jax.tree.map(lambda x: x[0], params)
        inputs = (obs, action, agent_mask, synergy, *self._tree(tree))
        return self.first_critic.apply({"params": first}, *inputs)


def _twin(critic: type[nn.Module]) -> type[nn.Module]:
    """Independent critics as one module: parameters and outputs get a leading axis 2."""
    return nn.vmap(
        critic,
        variable_axes={"params": 0},
        split_rngs={"params": True},
        in_axes=None,
        out_axes=0,
        axis_size=NUM_CRITICS,
    )


def make_networks(
    method: str,
    config: NetworkConfig | None = None,
    n_max: int = 9,
    obs_size: int = OBS_SIZE,
    max_children: int = 2,
) -> Networks:
    """The networks of ``method`` (one of ``METHODS``) for morphologies padded to ``n_max``.
    SMP only: ``max_children``, the most children of any limb in the suite (its message
    widths; ``limb_trees``)."""
    if method not in _METHODS:
        raise ValueError(f"unknown method {method!r}; valid: {', '.join(METHODS)}")
    config = config or NetworkConfig()
    spec = _METHODS[method]
    options = dict(spec.options)
    if spec.uses_tree:
        options |= dict(max_children=max_children)
    if spec.twin_critic:
        critic, first = spec.critic(config, **options), spec.critic(config, twin=False, **options)
    else:
        critic, first = _twin(spec.critic)(config, **options), spec.critic(config, **options)
    return Networks(
        method=method,
        config=config,
        n_max=n_max,
        obs_size=obs_size,
        actor=spec.actor(config, **options),
        critic=critic,
        first_critic=first,
        per_agent_q=spec.per_agent_q,
        uses_synergy=spec.uses_synergy,
        delta_q_preference=spec.delta_q_preference,
        uses_tree=spec.uses_tree,
        twin_critic=spec.twin_critic,
    )


def example_inputs(n_max: int, obs_size: int = OBS_SIZE, batch: int = 1) -> tuple:
    """Zero inputs for ``init``: (obs, action, agent_mask, synergy, traversal, tree), all
    agents real, one synergy and no limb a child, the torso a sender of SMP's top-down
    messages so that every module is built (parameter shapes depend on n_max, obs_size and
    the networks' own sizes only)."""
    no_parent = jnp.full(n_max, -1, jnp.int32)
    k = jnp.arange(n_max)
    synergy = Synergy(
        labels=jnp.zeros(n_max, jnp.int32),
        exemplars=jnp.where(k == 0, 0, -1).astype(jnp.int32),
        num_synergies=jnp.int32(1),
        torso_synergy=jnp.int32(0),
        agent_mask=jnp.ones(n_max, bool),
    )
    return (
        jnp.zeros((batch, n_max, obs_size)),
        jnp.zeros((batch, n_max)),
        jnp.ones(n_max, bool),
        synergy,
        jnp.zeros((n_max, 3), jnp.int32),
        Tree(no_parent, no_parent, no_parent, senders=(jnp.zeros(1, jnp.int32),)),
    )
