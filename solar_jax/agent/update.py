"""One TD3 iteration (algorithm.md §5): a critic step every iteration; on every
``policy_delay``-th an actor step (trunk and, by default, the transform's gate) and
Polyak updates of both targets; on every ``synergy_delay``-th the synergy optimiser steps
the synergy module (traversal embeddings and their Linear) too.

``update`` takes one morphology's batch (the reference's sequential mode); ``fused_update``
a stack ``[M, B, ...]`` of several morphologies' batches, each morphology's loss
computed with its own structure and the mean minimised in one step.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import optax

from solar_jax.agent.losses import Losses, make_losses
from solar_jax.agent.state import (
    AgentState,
    Hyper,
    init_agent,
    join_actor,
    make_optimizers,
    split_actor,
)
from solar_jax.config import TD3Config
from solar_jax.networks import Networks, Structure
from solar_jax.replay import Batch


class TD3(NamedTuple):
    init: callable
    """``(key) -> AgentState``."""
    update: callable
    """``(state, batch, structure, iteration, key, hyper) -> (state, metrics)``."""
    fused_update: callable
    """As ``update`` with ``batch`` and ``structure`` stacked over morphologies."""
    losses: Losses


def fused_losses(losses: Losses) -> Losses:
    """The losses averaged over a leading morphology axis of batch and structure."""

    def critic(critic, target_actor, target_critic, batch, s, key, hyper):
        keys = jax.random.split(key, batch.reward.shape[0])
        per_morph = jax.vmap(losses.critic, in_axes=(None, None, None, 0, 0, 0, None))
        loss, q = per_morph(critic, target_actor, target_critic, batch, s, keys, hyper)
        return loss.mean(), q.mean()

    def actor(actor, critic, batch, s):
        return jax.vmap(losses.actor, in_axes=(None, None, 0, 0))(actor, critic, batch, s).mean()

    return losses._replace(critic=critic, actor=actor)


def make_td3(networks: Networks, td3: TD3Config) -> TD3:
    losses = make_losses(networks, td3.action_penalty)
    actor_tx, critic_tx, synergy_tx = make_optimizers(td3)

    def init(key: jax.Array) -> AgentState:
        return init_agent(*networks.init(key), td3)

    def make_update(loss: Losses):
        def update(
            state: AgentState,
            batch: Batch,
            structure: Structure,
            iteration: jax.Array,
            key: jax.Array,
            hyper: Hyper,
        ) -> tuple[AgentState, dict]:
            _, synergy = split_actor(state.actor, td3)
            target_actor = join_actor(state.target_actor, synergy)
            (critic_loss, q), grads = jax.value_and_grad(loss.critic, has_aux=True)(
                state.critic, target_actor, state.target_critic, batch, structure, key, hyper
            )
            step, critic_opt = critic_tx.update(grads, state.critic_opt, state.critic)
            state = state.replace(
                critic=optax.apply_updates(state.critic, step), critic_opt=critic_opt
            )

            def actor_step(state: AgentState) -> tuple[AgentState, jax.Array]:
                actor_loss, grads = jax.value_and_grad(loss.actor)(
                    state.actor, state.critic, batch, structure
                )
                policy, synergy = split_actor(state.actor, td3)
                policy_grads, synergy_grads = split_actor(grads, td3)
                step, actor_opt = actor_tx.update(policy_grads, state.actor_opt, policy)
                policy = optax.apply_updates(policy, step)

                def synergy_step(carry):
                    params, opt = carry
                    step, opt = synergy_tx.update(synergy_grads, opt, params)
                    return optax.apply_updates(params, step), opt

                synergy, synergy_opt = jax.lax.cond(
                    iteration % td3.synergy_delay == 0,
                    synergy_step,
                    lambda carry: carry,
                    (synergy, state.synergy_opt),
                )

                def polyak(online, target):
                    return hyper.tau * online + (1.0 - hyper.tau) * target

                state = state.replace(
                    actor=join_actor(policy, synergy),
                    target_actor=jax.tree.map(polyak, policy, state.target_actor),
                    target_critic=jax.tree.map(polyak, state.critic, state.target_critic),
                    actor_opt=actor_opt,
                    synergy_opt=synergy_opt,
                )
                return state, actor_loss

            actor_iteration = iteration % td3.policy_delay == 0
            state, actor_loss = jax.lax.cond(
                actor_iteration, actor_step, lambda s: (s, jnp.float32(0.0)), state
            )
            metrics = dict(
                critic_loss=critic_loss, actor_loss=actor_loss, q=q, actor_step=actor_iteration
            )
            return state, metrics

        return update

    return TD3(
        init=init,
        update=make_update(losses),
        fused_update=make_update(fused_losses(losses)),
        losses=losses,
    )
