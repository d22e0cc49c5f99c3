"""The learner's state: parameters, targets and three optimisers (algorithm.md §5)."""

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
import optax
from flax import struct
from jax.flatten_util import ravel_pytree

from solar_jax.config import TD3Config
from solar_jax.networks import GATE, TRANSFORM

Params = Any


@struct.dataclass
class Hyper:
    """TD3's scalar hyper-parameters as traced float32 arrays (vmappable in sweeps): the
    traced fields of ``TD3Config`` (``config.TD3_TRACED``) but the learning rates, which
    live in the optimiser states (``optax.inject_hyperparams``, ``with_learning_rates``).
    """

    discount: jax.Array
    tau: jax.Array
    policy_noise: jax.Array
    noise_clip: jax.Array
    exploration_noise: jax.Array

    @classmethod
    def from_config(cls, td3: TD3Config) -> "Hyper":
        names = (field.name for field in dataclasses.fields(cls))
        return cls(**{name: jnp.float32(getattr(td3, name)) for name in names})


@struct.dataclass
class AgentState:
    actor: Params
    """Online actor: the trunk and, for SOLAR, the synergy module (``TRANSFORM``) and the
    transform's gate (``GATE``)."""
    critic: Params
    """Twin critics, leading axis 2."""
    target_actor: Params
    """Target of the actor group only (trunk and, by default, the gate): the synergy
    module has no target copy (algorithm.md §5); the target policy uses the online one."""
    target_critic: Params
    actor_opt: optax.OptState
    critic_opt: optax.OptState
    synergy_opt: optax.OptState
    """The optimiser states hold each group's moments as one flat vector (``flat``)."""


def synergy_keys(td3: TD3Config) -> tuple[str, ...]:
    """The actor's top-level keys in the synergy optimiser's group (algorithm.md §4-5): the
    synergy module, and the gate too with ``gate_group="synergy"``."""
    return (TRANSFORM, GATE) if td3.gate_group == "synergy" else (TRANSFORM,)


def split_actor(actor: Params, td3: TD3Config) -> tuple[Params, Params]:
    """(actor group, synergy group) parameter trees; the synergy group is {} for methods
    without an action transformation."""
    keys = synergy_keys(td3)
    policy = {k: v for k, v in actor.items() if k not in keys}
    return policy, {k: v for k, v in actor.items() if k in keys}


def join_actor(policy: Params, synergy: Params) -> Params:
    return {**policy, **synergy}


def flat(inner: optax.GradientTransformation) -> optax.GradientTransformation:
    """``inner`` on one vector of all the parameters (``ravel_pytree``, ``[P]``) instead of
    a tree of arrays: a few kernels per step of the optimiser, not a few per parameter
    array (the tiny test networks have 170 moment arrays, and each kernel costs compile
    time), and the states hold a vector per moment. Its
    updates come back as a tree shaped like the gradients. An empty group (the synergy
    group of methods without an action transformation) keeps ``inner`` on its empty tree:
    a ``[0]`` moment vector would be a zero-size array, which orbax refuses to save (and
    ``optax.flatten`` fails on it).
    """

    def init(params):
        if not jax.tree.leaves(params):
            return inner.init(params)
        return inner.init(ravel_pytree(params)[0])

    def update(updates, state, params=None):
        if not jax.tree.leaves(updates):
            return inner.update(updates, state, params)
        flat_updates, unravel = ravel_pytree(updates)
        flat_params = None if params is None else ravel_pytree(params)[0]
        step, state = inner.update(flat_updates, state, flat_params)
        return unravel(step), state

    return optax.GradientTransformation(init, update)


def make_optimizers(td3: TD3Config) -> tuple[optax.GradientTransformation, ...]:
    """(actor, critic, synergy): Adam, each clipping its own gradients' global norm (unless
    ``grad_clip`` is 0), on its group's parameters as one vector (``flat``)."""

    def adam(lr: float) -> optax.GradientTransformation:
        return flat(
            optax.chain(
                optax.clip_by_global_norm(td3.grad_clip) if td3.grad_clip else optax.identity(),
                optax.inject_hyperparams(optax.adam)(learning_rate=lr),
            )
        )

    return adam(td3.lr), adam(td3.lr), adam(td3.transform_lr)


def with_learning_rates(agent: AgentState, td3: TD3Config) -> AgentState:
    """``agent`` with ``td3``'s learning rates injected into its three optimiser states
    (a sweep lane's own rates, without rebuilding the optimisers)."""

    def injected(opt_state: optax.OptState, lr: float) -> optax.OptState:
        clip, adam = opt_state  # optax.chain(clip_by_global_norm, inject_hyperparams(adam))
        old = adam.hyperparams["learning_rate"]
        rates = {**adam.hyperparams, "learning_rate": jnp.asarray(lr, old.dtype)}
        return (clip, adam._replace(hyperparams=rates))

    return agent.replace(
        actor_opt=injected(agent.actor_opt, td3.lr),
        critic_opt=injected(agent.critic_opt, td3.lr),
        synergy_opt=injected(agent.synergy_opt, td3.transform_lr),
    )


def init_agent(actor: Params, critic: Params, td3: TD3Config) -> AgentState:
    actor_opt, critic_opt, synergy_opt = make_optimizers(td3)
    policy, synergy = split_actor(actor, td3)
    return AgentState(
        actor=actor,
        critic=critic,
        target_actor=_copy(policy),
        target_critic=_copy(critic),
        actor_opt=actor_opt.init(policy),
        critic_opt=critic_opt.init(critic),
        synergy_opt=synergy_opt.init(synergy),
    )


def _copy(tree: Params) -> Params:
    """A copy with its own buffers (targets must not alias donated online parameters)."""
    return jax.tree.map(jnp.array, tree)
