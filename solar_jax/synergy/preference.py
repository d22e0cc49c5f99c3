"""ΔQ preference for affinity propagation (algorithm.md §3, paper Sec. 3.2).

ΔQ_i = mean over a batch of Q(s, a) - Q(s, a with a_i = 0): how much agent i's action
moves the value. Preference = 1.2 · softmax_i(ΔQ_i) over the real agents, torso included.
"""

from collections.abc import Callable

import jax
import jax.numpy as jnp

PREFERENCE_SCALE = 1.2
"""The reference's factor on the softmax (algorithm.md §3)."""

QFunction = Callable[[jax.Array, jax.Array], jax.Array]
"""``q(obs [B, N_max, F], act [B, N_max]) -> [B]``, e.g. the online first critic."""


def delta_q(q: QFunction, obs: jax.Array, act: jax.Array, agent_mask: jax.Array) -> jax.Array:
    """ΔQ per agent, ``[N_max]``; 0 for padded agents.

    One forward pass over a batch of (N_max + 1)·B: the batch as it is, then once per agent
    with that agent's action zeroed (a batch axis rather than a vmap over agents keeps the
    operands' rank low, which XLA:CPU's fusion needs under the sweeps' extra vmaps).
    """
    act = jnp.asarray(act)
    b, n_max = act.shape
    ablated = jnp.where(jnp.eye(n_max, dtype=bool)[:, None, :], 0.0, act[None])  # [N, B, N]
    actions = jnp.concatenate([act[None], ablated]).reshape((n_max + 1) * b, n_max)
    states = jnp.broadcast_to(obs[None], (n_max + 1, *obs.shape)).reshape(-1, *obs.shape[1:])
    values = q(states, actions).reshape(n_max + 1, b)
    dq = jnp.mean(values[0][None, :] - values[1:], axis=-1)
    return jnp.where(agent_mask, dq, 0.0)


def preference_from_delta_q(
    dq: jax.Array, agent_mask: jax.Array, scale: float = PREFERENCE_SCALE
) -> jax.Array:
    """``scale · softmax(ΔQ)`` over the real agents, ``[N_max]``; 0 for padded agents."""
    logits = jnp.where(agent_mask, dq, -jnp.inf)
    return jnp.where(agent_mask, scale * jax.nn.softmax(logits), 0.0)


def delta_q_preference(
    q: QFunction,
    obs: jax.Array,
    act: jax.Array,
    agent_mask: jax.Array,
    scale: float = PREFERENCE_SCALE,
) -> jax.Array:
    """Preference ``[N_max]`` for affinity propagation from a critic and a batch."""
    return preference_from_delta_q(delta_q(q, obs, act, agent_mask), agent_mask, scale)
