"""Our TD3 learner on one robot, driven step by step from outside the trainer: the
networks, update and ΔQ re-clustering of ``solar_jax``, jitted, with the reference's
interface to batches (flat observations ``[B, N * 19]``). ``lockstep.py`` feeds it the
authors' batches; ``reference.py`` runs it in the authors' training loop.
"""

import jax
import jax.numpy as jnp
import numpy as np

from solar_jax.agent.state import Hyper, init_agent
from solar_jax.agent.update import make_td3
from solar_jax.config import NetworkConfig, TD3Config
from solar_jax.networks import Structure, make_networks
from solar_jax.networks.common import pad_traversal
from solar_jax.replay import Batch
from solar_jax.synergy.discovery import SuiteAffinity
from solar_jax.synergy.preference import delta_q_preference
from tests.networks.reference_params import (
    amorpheus_actor,
    critics,
    policy_group,
    solar_actor,
)

REFERENCE_WIDTHS = dict(gate_hidden=256, embedding_dim=64)
"""The reference's gate and embedding widths, fixed in its code."""
SATURATED = 0.99


class Ours:
    """SOLAR or Amorpheus on ``morph`` (N_max = N) from ``params``: ``(actor, critic)``
    trees, or None for our own initialisation from ``key``."""

    def __init__(
        self,
        method: str,
        config: NetworkConfig,
        lr: float,
        morph,
        params: tuple | None = None,
        key: jax.Array | None = None,
    ):
        n = len(morph.parents)
        self.n, self.method = n, method
        self.nets = make_networks(method, config, n_max=n)
        self.td3_config = TD3Config(lr=lr)
        self.td3 = make_td3(self.nets, self.td3_config)
        self.hyper = Hyper.from_config(self.td3_config)
        if params is None:
            self.state = jax.jit(self.td3.init)(key)
        else:
            self.state = jax.jit(init_agent, static_argnums=2)(*params, self.td3_config)
        self.affinity = SuiteAffinity([morph.parents], n)
        self.mask = jnp.ones(n, bool)
        self.traversal = pad_traversal(morph.traversal, n)
        self.synergy = None
        if self.nets.uses_synergy:
            self.synergy = first(self.affinity.cluster(None))  # the median, as the reference
        self._update = jax.jit(self.td3.update)
        self._recluster = jax.jit(self._preference_clustering)
        self._probe = jax.jit(self._probe_stats)
        self._act = jax.jit(self.nets.act)

    def structure(self, synergy=None) -> Structure:
        synergy = self.synergy if synergy is None else synergy
        return Structure(agent_mask=self.mask, synergy=synergy, traversal=self.traversal)

    def _preference_clustering(self, critic, synergy, obs, action):
        s = self.structure(synergy)

        def q1(o, a):
            return self.td3.losses.q1(critic, o, a, s)

        preference = delta_q_preference(q1, obs, action, self.mask)
        return first(self.affinity.cluster(preference[None]))

    def recluster(self, obs: np.ndarray, action: np.ndarray):
        """SOLAR: affinity propagation from ΔQ on ``obs [P, N * 19]``, ``action [P, N]``
        under the online first critic (algorithm.md §3); others: nothing."""
        if self.nets.uses_synergy:
            obs = jnp.asarray(obs, jnp.float32).reshape(len(obs), self.n, 19)
            action = jnp.asarray(action, jnp.float32)
            self.synergy = self._recluster(self.state.critic, self.synergy, obs, action)

    def update(self, x, y, u, r, d, iteration: int, key: jax.Array) -> jax.Array:
        """One TD3 iteration on the reference's batch layout: ``x``/``y`` ``[B, N * 19]``,
        ``u [B, N]``, ``r``/``d`` ``[B(, 1)]`` (d: 1 where terminated). The critic loss
        (a device scalar: reading it would wait for the step)."""
        b = len(x)
        batch = Batch(
            obs=jnp.asarray(x, jnp.float32).reshape(b, self.n, 19),
            action=jnp.asarray(u, jnp.float32),
            reward=jnp.asarray(np.ravel(r), jnp.float32),
            next_obs=jnp.asarray(y, jnp.float32).reshape(b, self.n, 19),
            terminated=jnp.asarray(np.ravel(d) > 0.5),
        )
        self.state, metrics = self._update(
            self.state, batch, self.structure(), jnp.int32(iteration), key, self.hyper
        )
        return metrics["critic_loss"]

    def act(self, obs: np.ndarray) -> np.ndarray:
        """Deterministic actions ``[N]`` (the torso's included) for one ``obs [N * 19]``."""
        obs = jnp.asarray(obs, jnp.float32).reshape(1, self.n, 19)
        actor = self.state.actor
        return np.asarray(self._act(actor, obs, self.mask, self.synergy, self.traversal))[0]

    def _probe_stats(self, state, synergy, obs, action):
        s = self.structure(synergy)
        _, inside = self.nets.act_diagnostics(state.actor, obs, self.mask, synergy, s.traversal)
        return self.td3.losses.q1(state.critic, obs, action, s).mean(), inside["pre_tanh"]

    def stats(self, obs: np.ndarray, action: np.ndarray) -> dict:
        """Q1, the actions before the tanh and the clustering on ``obs [P, N * 19]``."""
        obs = jnp.asarray(obs, jnp.float32).reshape(len(obs), self.n, 19)
        q, pre_tanh = self._probe(self.state, self.synergy, obs, jnp.asarray(action))
        labels = None if self.synergy is None else np.asarray(self.synergy.labels).tolist()
        return {"q": float(q), **action_stats(np.asarray(pre_tanh)), "labels": labels}

    def groups(self) -> dict[str, np.ndarray]:
        s = self.state
        return split_groups(s.actor, s.critic, s.target_actor, s.target_critic)


def to_ours(ref: dict, tag: str, method: str, config: NetworkConfig, n: int, online: bool):
    """The reference's parameters as our trees, in their own precision: (actor, critic)
    if ``online``, else (actor, critic, target actor group, target critic)."""
    with jax.enable_x64(True):  # keep a float64 reference float64
        if method == "solar":
            actor = solar_actor(ref, tag, config, n)
        else:
            actor = amorpheus_actor(ref, tag, config)
        critic = critics(ref, tag, config)
        if online:
            return actor, critic
        if method == "solar":
            target = policy_group(solar_actor(ref, tag, config, n, actor="target_actor"))
        else:
            target = amorpheus_actor(ref, tag, config, actor="target_actor")
        trees = actor, critic, target, critics(ref, tag, config, critic="target_critic")
        return jax.tree.map(np.asarray, trees)


def split_groups(actor, critic, target_actor, target_critic) -> dict[str, np.ndarray]:
    """Each parameter group flattened to one float64 vector."""

    def flat(tree) -> np.ndarray:
        leaves = jax.tree.leaves(jax.device_get(tree))
        return np.concatenate([np.asarray(x, np.float64).ravel() for x in leaves])

    groups = {
        "trunk": actor["trunk"],
        "gate": actor.get("gate"),
        "transform": actor.get("transform"),
        "critic": critic,
        "target_actor": target_actor,
        "target_critic": target_critic,
    }
    return {k: flat(v) for k, v in groups.items() if v is not None}


def action_stats(pre_tanh: np.ndarray) -> dict:
    """RMS of the actuated agents' pre-tanh actions (the torso, agent 0, has no motor)
    and the share of |tanh| > 0.99 among them."""
    u = np.asarray(pre_tanh, np.float64)[:, 1:]
    return {
        "pre_tanh_rms": float(np.sqrt(np.mean(u**2))),
        "saturation": float(np.mean(np.abs(np.tanh(u)) > SATURATED)),
    }


def first(tree):
    """The first entry of a leading axis."""
    return jax.tree.map(lambda x: x[0], tree)
