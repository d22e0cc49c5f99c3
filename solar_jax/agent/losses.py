"""TD3's critic and actor losses for one morphology's padded batch (algorithm.md §5).

Per-sample Q (SOLAR, monolithic): ``y = r + γ (1 - terminated) min_j Q'_j(s', ã')``,
``ã' = clip(π'(s') + clip(N(0, σ²), -c, c), -1, 1)`` on the agents the actor acts for
(the torso too by default, as the reference; algorithm.md §2), loss
``Σ_j mean (Q_j(s, a) - y)²``. Per-agent Q (Amorpheus, SMP): the same per agent, the
reward shared, means over the batch and the real agents (torso included, as the
references' per-limb critics). Actor: ``-mean Q_1(s, π(s))``, plus, beyond the
reference and off by default, ``λ · mean u²`` over the batch and the agents the actor
acts for, u the action before its tanh (``td3.action_penalty``).
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp

from solar_jax.agent.state import Hyper, Params
from solar_jax.networks import Networks, Structure
from solar_jax.replay import Batch


class Losses(NamedTuple):
    critic: callable
    """``(critic, target_actor, target_critic, batch, structure, key, hyper) -> (loss, q)``;
    ``target_actor`` is the full actor tree (the target actor group + the online synergy
    module)."""
    actor: callable
    """``(actor, critic, batch, structure) -> loss``, the action penalty included."""
    q1: callable
    """``(critic, obs, action, structure) -> [B]``: the first critic, per sample (per-agent
    Q averaged over real agents); what ΔQ reads (algorithm.md §3)."""


def make_losses(networks: Networks, action_penalty: float = 0.0) -> Losses:
    """``action_penalty``: λ of the actor's pre-tanh penalty; 0 (the reference) traces
    no penalty at all."""

    def act(actor: Params, obs: jax.Array, s: Structure) -> jax.Array:
        return networks.act(actor, obs, s.agent_mask, s.synergy, s.traversal, s.tree)

    def q(critic: Params, obs, action, s: Structure) -> jax.Array:
        return networks.q(critic, obs, action, s.agent_mask, s.synergy, s.tree)  # [2, B(, N)]

    def q_first(critic: Params, obs, action, s: Structure) -> jax.Array:
        return networks.q1(critic, obs, action, s.agent_mask, s.synergy, s.tree)  # [B(, N)]

    def mean(x: jax.Array, s: Structure) -> jax.Array:
        """Mean over the batch (and, per agent, over real agents): [..., B(, N)] -> [...]."""
        if not networks.per_agent_q:
            return jnp.mean(x, axis=-1)
        weight = s.agent_mask.astype(x.dtype)
        return jnp.sum(x * weight, axis=(-2, -1)) / (x.shape[-2] * weight.sum())

    def critic_loss(critic, target_actor, target_critic, batch: Batch, s: Structure, key, hyper):
        hyper: Hyper
        next_action = act(target_actor, batch.next_obs, s)
        noise = hyper.policy_noise * jax.random.normal(key, next_action.shape)
        noise = jnp.clip(noise, -hyper.noise_clip, hyper.noise_clip)
        next_action = jnp.where(networks.acting_mask(s.agent_mask), next_action + noise, 0.0)
        next_action = jnp.clip(next_action, -1.0, 1.0)
        next_q = jnp.min(q(target_critic, batch.next_obs, next_action, s), axis=0)
        not_done = 1.0 - batch.terminated.astype(jnp.float32)
        reward, not_done = batch.reward, not_done
        if networks.per_agent_q:
            reward, not_done = reward[:, None], not_done[:, None]
        target = jax.lax.stop_gradient(reward + hyper.discount * not_done * next_q)
        current = q(critic, batch.obs, batch.action, s)
        loss = jnp.sum(mean((current - target[None]) ** 2, s))
        return loss, mean(current[0], s)

    def actor_loss(actor, critic, batch: Batch, s: Structure):
        if not action_penalty:
            action = act(actor, batch.obs, s)
            return -mean(q_first(critic, batch.obs, action, s), s)
        action, inside = networks.act_diagnostics(
            actor, batch.obs, s.agent_mask, s.synergy, s.traversal, s.tree
        )
        acting = jnp.broadcast_to(networks.acting_mask(s.agent_mask), action.shape)  # [B, N]
        square = jnp.where(acting, inside["pre_tanh"] ** 2, 0.0)
        penalty = jnp.sum(square) / jnp.maximum(jnp.sum(acting), 1)
        return -mean(q_first(critic, batch.obs, action, s), s) + action_penalty * penalty

    def q1(critic, obs, action, s: Structure) -> jax.Array:
        value = q_first(critic, obs, action, s)
        if networks.per_agent_q:
            weight = s.agent_mask.astype(value.dtype)
            value = jnp.sum(value * weight, axis=-1) / weight.sum()
        return value

    return Losses(critic=critic_loss, actor=actor_loss, q1=q1)
