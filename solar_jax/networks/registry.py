"""One interface for every method, chosen by name (algorithm.md §4; STYLE habit 4).

>>> nets = make_networks("solar", NetworkConfig.tiny(), n_max=9)
>>> actor_params, critic_params = nets.init(jax.random.key(0))
>>> nets.act(actor_params, obs, agent_mask, synergy, traversal)  # [B, N]
>>> nets.q(critic_params, obs, action, agent_mask, synergy)  # [2, B] or [2, B, N]

Inputs, all padded to N_max and unbatched over morphologies (vmap over them): ``obs``
``[B, N, 19]``, ``action`` ``[B, N]``, ``agent_mask`` ``[N]`` bool (agent 0 the torso),
``synergy`` a ``Synergy`` whose ``agent_mask`` equals ``agent_mask``, ``traversal``
``[N, 3]`` int32 (``pad_traversal``). Methods that ignore the synergy or traversal
accept None for them.
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


_METHODS = {
    "solar": _Method(SolarActor, SolarCritic, False, True, True),
    # The ablation lives in synergy discovery (the median preference always).
    "solar_no_pref": _Method(SolarActor, SolarCritic, False, True, False),
    "amorpheus": _Method(AmorpheusActor, AmorpheusCritic, True, False, False),
    "amorpheus_mask": _Method(
        AmorpheusActor, AmorpheusCritic, True, True, True, {"synergy_bias": True}
    ),
    "monolithic": _Method(MonolithicActor, MonolithicCritic, False, False, False),
}
METHODS = tuple(_METHODS)


@struct.dataclass
class Structure:
    """What the networks read about one morphology (``[M, ...]`` when stacked)."""

    agent_mask: jax.Array  # [N] bool
    synergy: Synergy  # the current clustering
    traversal: jax.Array  # [N, 3] int32


@dataclasses.dataclass(frozen=True)
class Networks:
    """A method's actor and twin critic as pure functions of their parameters."""

    method: str
    config: NetworkConfig
    n_max: int
    obs_size: int
    actor: nn.Module
    """``(obs, agent_mask, synergy, traversal) -> actions [B, N]`` in [-1, 1], 0 for the
    torso and padded agents."""
    critic: nn.Module
    """``(obs, action, agent_mask, synergy) -> Q``: ``[2, B]``, or ``[2, B, N]`` per agent
    (0 for padded agents) where ``per_agent_q``. The torso's and padded actions are ignored."""
    first_critic: nn.Module
    """One of the twins (``critic`` without its leading axis), for ``q1``."""
    per_agent_q: bool
    """Amorpheus: one Q and one TD target per agent; otherwise one Q per sample."""
    uses_synergy: bool
    """The networks read the synergy structure, so the trainer must discover it."""
    delta_q_preference: bool
    """Synergy discovery uses ΔQ preferences after the first clustering (False: the median
    always). Informational: discovery is the trainer's; with per-agent Q (amorpheus_mask)
    it would average the first critic's Q over real agents."""

    def init(self, key: jax.Array) -> tuple[Params, Params]:
        """(actor params, twin critic params, leading axis 2) from one key, drawn by the
        reference's rules unless ``config.init == "flax"`` (``networks/init.py``)."""
        actor_key, critic_key = jax.random.split(key)
        obs, action, agent_mask, synergy, traversal = example_inputs(self.n_max, self.obs_size)
        actor = self.actor.init(actor_key, obs, agent_mask, synergy, traversal)["params"]
        critic = self.critic.init(critic_key, obs, action, agent_mask, synergy)["params"]
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
    ) -> jax.Array:
        return self.actor.apply({"params": params}, obs, agent_mask, synergy, traversal)

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
    ) -> tuple[jax.Array, dict]:
        """As ``act``, with the actor's intermediates: {"pre_tanh": ``[B, N]``} and, for
        SOLAR's gated transform, "gate_values": ``[B, N, S]``."""
        action, state = self.actor.apply(
            {"params": params}, obs, agent_mask, synergy, traversal, mutable=[DIAGNOSTICS]
        )
        return action, {name: value[0] for name, value in state[DIAGNOSTICS].items()}

    def q(
        self,
        params: Params,
        obs: jax.Array,
        action: jax.Array,
        agent_mask: jax.Array,
        synergy: Synergy | None = None,
    ) -> jax.Array:
        return self.critic.apply({"params": params}, obs, action, agent_mask, synergy)

    def q1(
        self,
        params: Params,
        obs: jax.Array,
        action: jax.Array,
        agent_mask: jax.Array,
        synergy: Synergy | None = None,
    ) -> jax.Array:
        """``q(...)[0]``, the first critic alone (the reference's ``Q1``, which the actor's
        loss and ΔQ read): ``[B]`` or ``[B, N]``. The twins run as one batched program, so
        slicing ``q`` would pay for the second critic, forward and backward."""
        first = jax.tree.map(lambda x: x[0], params)
        return self.first_critic.apply({"params": first}, obs, action, agent_mask, synergy)


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
    method: str, config: NetworkConfig | None = None, n_max: int = 9, obs_size: int = OBS_SIZE
) -> Networks:
    """The networks of ``method`` (one of ``METHODS``) for morphologies padded to ``n_max``."""
    if method not in _METHODS:
        raise ValueError(f"unknown method {method!r}; valid: {', '.join(METHODS)}")
    config = config or NetworkConfig()
    spec = _METHODS[method]
    return Networks(
        method=method,
        config=config,
        n_max=n_max,
        obs_size=obs_size,
        actor=spec.actor(config, **spec.options),
        critic=_twin(spec.critic)(config, **spec.options),
        first_critic=spec.critic(config, **spec.options),
        per_agent_q=spec.per_agent_q,
        uses_synergy=spec.uses_synergy,
        delta_q_preference=spec.delta_q_preference,
    )


def example_inputs(n_max: int, obs_size: int = OBS_SIZE, batch: int = 1) -> tuple:
    """Zero inputs for ``init``: (obs, action, agent_mask, synergy, traversal), all agents
    real and one synergy (parameter shapes depend on n_max and obs_size only)."""
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
    )
