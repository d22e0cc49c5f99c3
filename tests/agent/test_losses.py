"""TD3's losses on a hand-built batch, against NumPy (algorithm.md §5).

The networks are replaced by linear stand-ins whose outputs are easy to write down,
so every term of the target (noise clip, action clip, twin minimum, terminal mask,
discount) and of the loss can be computed by hand.
"""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from solar_jax.agent import Hyper, make_losses
from solar_jax.agent.update import fused_losses
from solar_jax.config import TD3Config
from solar_jax.networks import Structure
from solar_jax.replay import Batch

N = 4  # agents: torso, two actuated, one padded
MASK = np.array([True, True, True, False])
ACTUATED = np.array([False, True, True, False])


@dataclasses.dataclass(frozen=True)
class LinearNetworks:
    """act = tanh(obs @ w) per agent (0 on padding, and on the torso without
    ``torso_action``); twin Q_j = obs·u_j + action·v_j summed over real agents (per agent
    when ``per_agent_q``)."""

    per_agent_q: bool
    torso_action: bool = True

    def acting_mask(self, agent_mask):
        return agent_mask & (self.torso_action | (jnp.arange(N) != 0))

    def act(self, params, obs, agent_mask, synergy, traversal, tree=None):
        return jnp.where(self.acting_mask(agent_mask), jnp.tanh(obs @ params["w"]), 0.0)

    def act_diagnostics(self, params, obs, agent_mask, synergy, traversal, tree=None):
        pre_tanh = jnp.where(self.acting_mask(agent_mask), obs @ params["w"], 0.0)
        return self.act(params, obs, agent_mask, synergy, traversal), {"pre_tanh": pre_tanh}

    def q(self, params, obs, action, agent_mask, synergy, tree=None):
        per_agent = obs @ params["u"].T + action[..., None] * params["v"]  # [B, N, 2]
        per_agent = jnp.where(agent_mask[:, None], per_agent, 0.0)
        per_agent = jnp.moveaxis(per_agent, -1, 0)  # [2, B, N]
        return per_agent if self.per_agent_q else per_agent.sum(-1)

    def q1(self, params, obs, action, agent_mask, synergy, tree=None):
        return self.q(params, obs, action, agent_mask, synergy)[0]


def _params(rng):
    actor = {"w": rng.normal(size=3).astype(np.float32)}
    critic = {
        "u": rng.normal(size=(2, 3)).astype(np.float32),
        "v": rng.normal(size=2).astype(np.float32),
    }
    return actor, critic


def _batch(rng, b=5):
    return Batch(
        obs=rng.normal(size=(b, N, 3)).astype(np.float32),
        action=rng.uniform(-1, 1, size=(b, N)).astype(np.float32) * ACTUATED,
        reward=rng.normal(size=b).astype(np.float32),
        next_obs=rng.normal(size=(b, N, 3)).astype(np.float32),
        terminated=np.array([False, True, False, False, True]),
    )


def _numpy_q(critic, obs, action):
    """[2, B, N] per agent."""
    per_agent = obs @ critic["u"].T + action[..., None] * critic["v"]
    return np.moveaxis(np.where(MASK[:, None], per_agent, 0.0), -1, 0)


@pytest.mark.parametrize("torso_action", [True, False], ids=["torso", "no_torso"])
@pytest.mark.parametrize("per_agent_q", [False, True], ids=["per_sample", "per_agent"])
def test_critic_loss_matches_hand_computation(per_agent_q, torso_action):
    rng = np.random.default_rng(0)
    actor, critic = _params(rng)
    target_actor, target_critic = _params(rng)
    batch = _batch(rng)
    hyper = Hyper.from_config(TD3Config(policy_noise=0.7, noise_clip=0.3))
    structure = Structure(agent_mask=jnp.asarray(MASK), synergy=None, traversal=None)
    losses = make_losses(LinearNetworks(per_agent_q, torso_action))
    key = jax.random.PRNGKey(3)
    loss, q_mean = losses.critic(critic, target_actor, target_critic, batch, structure, key, hyper)

    # By hand: the same normal draw, clipped to ±0.3; actions clipped to [-1, 1].
    noise = 0.7 * np.asarray(jax.random.normal(key, (5, N)))
    noise = np.clip(noise, -0.3, 0.3)
    next_a = np.tanh(batch.next_obs @ target_actor["w"]) + noise
    # Target noise reaches every agent the actor acts for: the torso too by default.
    next_a = np.where(MASK if torso_action else ACTUATED, np.clip(next_a, -1, 1), 0.0)
    next_q = _numpy_q(target_critic, batch.next_obs, next_a)
    current = _numpy_q(critic, batch.obs, batch.action)
    not_done = 1.0 - batch.terminated
    if per_agent_q:
        target = batch.reward[:, None] + 0.99 * not_done[:, None] * next_q.min(0)
        sq = (current - target[None]) ** 2  # [2, B, N]
        expected = sum(sq[j][:, MASK].mean() for j in range(2))
        expected_q = current[0][:, MASK].mean()
    else:
        next_q, current = next_q.sum(-1), current.sum(-1)
        target = batch.reward + 0.99 * not_done * next_q.min(0)
        expected = sum(((current[j] - target) ** 2).mean() for j in range(2))
        expected_q = current[0].mean()
    np.testing.assert_allclose(loss, expected, rtol=1e-5)
    np.testing.assert_allclose(q_mean, expected_q, rtol=1e-5, atol=1e-6)
    # The noise was clipped somewhere, or the test would not test the clip.
    assert np.any(np.abs(0.7 * np.asarray(jax.random.normal(key, (5, N)))) > 0.3)


def test_critic_target_has_no_gradient():
    rng = np.random.default_rng(1)
    actor, critic = _params(rng)
    batch = _batch(rng)
    hyper = Hyper.from_config(TD3Config())
    structure = Structure(agent_mask=jnp.asarray(MASK), synergy=None, traversal=None)
    losses = make_losses(LinearNetworks(False))
    grads = jax.grad(
        lambda ta, tc: losses.critic(
            critic, ta, tc, batch, structure, jax.random.PRNGKey(0), hyper
        )[0],
        argnums=(0, 1),
    )(actor, critic)
    for leaf in jax.tree.leaves(grads):
        np.testing.assert_array_equal(leaf, 0.0)


@pytest.mark.parametrize("per_agent_q", [False, True], ids=["per_sample", "per_agent"])
def test_actor_loss_is_minus_mean_first_critic(per_agent_q):
    rng = np.random.default_rng(2)
    actor, critic = _params(rng)
    batch = _batch(rng)
    structure = Structure(agent_mask=jnp.asarray(MASK), synergy=None, traversal=None)
    losses = make_losses(LinearNetworks(per_agent_q))
    a = np.where(MASK, np.tanh(batch.obs @ actor["w"]), 0.0)  # the torso acts too
    q1 = _numpy_q(critic, batch.obs, a)[0]  # [B, N]
    expected = -(q1[:, MASK].mean() if per_agent_q else q1.sum(-1).mean())
    np.testing.assert_allclose(losses.actor(actor, critic, batch, structure), expected, rtol=1e-5)
    # ΔQ's first critic: per sample, per-agent Q averaged over real agents.
    q1_fn = losses.q1(critic, batch.obs, jnp.asarray(a), structure)
    expected_q1 = q1[:, MASK].mean(-1) if per_agent_q else q1.sum(-1)
    np.testing.assert_allclose(q1_fn, expected_q1, rtol=1e-5)


@pytest.mark.parametrize("torso_action", [True, False], ids=["torso", "no_torso"])
def test_action_penalty_adds_the_mean_square_before_the_tanh(torso_action):
    """``td3.action_penalty`` λ: the actor loss gains λ · mean u² over the batch and the
    agents the actor acts for (padding, and the torso without ``torso_action``, left out)."""
    rng = np.random.default_rng(5)
    actor, critic = _params(rng)
    batch = _batch(rng)
    structure = Structure(agent_mask=jnp.asarray(MASK), synergy=None, traversal=None)
    networks = LinearNetworks(False, torso_action)
    plain = make_losses(networks).actor(actor, critic, batch, structure)
    penalised = make_losses(networks, 0.3).actor(actor, critic, batch, structure)
    acting = MASK & (torso_action | (np.arange(N) != 0))
    u = batch.obs @ actor["w"]  # [B, N]
    np.testing.assert_allclose(penalised - plain, 0.3 * np.mean(u[:, acting] ** 2), rtol=1e-5)


def test_fused_losses_average_the_morphologies():
    """The fused update's losses: each morphology's loss with its own structure and noise
    key (``jax.random.split`` of the iteration's key), averaged."""
    rng = np.random.default_rng(3)
    actor, critic = _params(rng)
    target_actor, target_critic = _params(rng)
    batches = [_batch(rng), _batch(rng)]
    masks = [MASK, np.array([True, True, False, False])]
    structures = [Structure(jnp.asarray(m), None, None) for m in masks]
    hyper = Hyper.from_config(TD3Config())
    losses = make_losses(LinearNetworks(False))
    fused = fused_losses(losses)
    stack = lambda *xs: jnp.stack(xs)  # noqa: E731
    batch, structure = jax.tree.map(stack, *batches), jax.tree.map(stack, *structures)
    key = jax.random.PRNGKey(4)
    keys = jax.random.split(key, 2)
    expected = [
        losses.critic(critic, target_actor, target_critic, b, s, k, hyper)
        for b, s, k in zip(batches, structures, keys, strict=True)
    ]
    loss, q = fused.critic(critic, target_actor, target_critic, batch, structure, key, hyper)
    np.testing.assert_allclose(loss, np.mean([e[0] for e in expected]), rtol=1e-6)
    np.testing.assert_allclose(q, np.mean([e[1] for e in expected]), rtol=1e-6)
    actor_expected = [
        losses.actor(actor, critic, b, s) for b, s in zip(batches, structures, strict=True)
    ]
    np.testing.assert_allclose(
        fused.actor(actor, critic, batch, structure), np.mean(actor_expected), rtol=1e-6
    )
