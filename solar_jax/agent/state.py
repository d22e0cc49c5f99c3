"""The learner's state: parameters, targets and three optimisers (SPEC section 5)."""

from typing import Any

import jax
import jax.numpy as jnp
import optax
from flax import struct

from solar_jax.config import TD3Config
from solar_jax.networks import TRANSFORM

Params = Any


@struct.dataclass
class Hyper:
    """TD3's scalar hyper-parameters as traced float32 arrays (vmappable in sweeps).

    Learning rates live in the optimiser states (``optax.inject_hyperparams``).
    """

    discount: jax.Array
    tau: jax.Array
    policy_noise: jax.Array
    noise_clip: jax.Array
    exploration_noise: jax.Array

    @classmethod
    def from_config(cls, td3: TD3Config) -> "Hyper":
        return cls(
            **{
                name: jnp.float32(getattr(td3, name))
                for name in ("discount", "tau", "policy_noise", "noise_clip", "exploration_noise")
            }
        )


@struct.dataclass
class AgentState:
    actor: Params
    """Online actor: the trunk and, for SOLAR, the action transformation (``TRANSFORM``)."""
    critic: Params
    """Twin critics, leading axis 2."""
    target_actor: Params
    """Target trunk only: the transformation has no target copy (SPEC section 5); the
    target policy uses the online one."""
    target_critic: Params
    actor_opt: optax.OptState
    critic_opt: optax.OptState
    synergy_opt: optax.OptState


def split_actor(actor: Params) -> tuple[Params, Params]:
    """(trunk, transformation) parameter trees; the transformation is {} without one."""
    trunk = {k: v for k, v in actor.items() if k != TRANSFORM}
    return trunk, actor.get(TRANSFORM, {})


def join_actor(trunk: Params, transform: Params) -> Params:
    return {**trunk, TRANSFORM: transform} if transform else dict(trunk)


def make_optimizers(td3: TD3Config) -> tuple[optax.GradientTransformation, ...]:
    """(actor, critic, synergy): Adam, each clipping its own gradients' global norm."""

    def adam(lr: float) -> optax.GradientTransformation:
        return optax.chain(
            optax.clip_by_global_norm(td3.grad_clip),
            optax.inject_hyperparams(optax.adam)(learning_rate=lr),
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
    trunk, transform = split_actor(actor)
    return AgentState(
        actor=actor,
        critic=critic,
        target_actor=_copy(trunk),
        target_critic=_copy(critic),
        actor_opt=actor_opt.init(trunk),
        critic_opt=critic_opt.init(critic),
        synergy_opt=synergy_opt.init(transform),
    )


def _copy(tree: Params) -> Params:
    """A copy with its own buffers (targets must not alias donated online parameters)."""
    return jax.tree.map(jnp.array, tree)
