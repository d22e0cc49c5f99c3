"""Padded inputs for the network tests: algorithm.md §3's synergy fixtures, garbage padding."""

import functools

import jax
import jax.numpy as jnp
import numpy as np

from solar_jax.config import NetworkConfig
from solar_jax.morphology.graph import traversal_indices
from solar_jax.networks import make_networks, make_tree, pad_traversal
from solar_jax.synergy import Synergy
from tests import unoptimised

OBS = 19
N_MAX = 9
MAX_CHILDREN = 4  # the humanoid's torso: SMP's message slots
# Methods whose networks are another's (the ablation lives in synergy discovery).
_SAME_NETWORKS = {"solar_no_pref": "solar"}

# name: (parents, labels, exemplars) after the torso rule (algorithm.md §3 fixtures).
ROBOTS = {
    "walker_7_main": ((-1, 0, 1, 2, 0, 4, 5), [2, 0, 0, 0, 1, 1, 1], [1, 5, 0]),
    "humanoid_2d_9_full": (
        (-1, 0, 1, 0, 3, 0, 5, 0, 7),
        [4, 0, 0, 1, 1, 2, 2, 3, 3],
        [2, 3, 6, 7, 0],
    ),
    "hopper_3": ((-1, 0, 1), [1, 0, 0], [2, 0]),
}


def synergy(labels, exemplars, n_max: int, garbage: np.random.Generator | None = None) -> Synergy:
    """A padded ``Synergy``; the torso synergy is the torso's label. With ``garbage``, the
    padded labels and exemplars hold random indices instead of -1."""
    n, k = len(labels), len(exemplars)
    pad_labels = np.full(n_max, -1)
    pad_exemplars = np.full(n_max, -1)
    if garbage is not None:
        pad_labels = garbage.integers(0, n_max, n_max)
        pad_exemplars = garbage.integers(0, n_max, n_max)
    pad_labels[:n], pad_exemplars[:k] = labels, exemplars
    return Synergy(
        labels=jnp.asarray(pad_labels, jnp.int32),
        exemplars=jnp.asarray(pad_exemplars, jnp.int32),
        num_synergies=jnp.int32(k),
        torso_synergy=jnp.int32(labels[0]),
        agent_mask=jnp.arange(n_max) < n,
    )


def robot(name: str, n_max: int, batch: int, seed: int = 0, garbage: bool = False) -> tuple:
    """(obs [B, n_max, 19], action [B, n_max], agent_mask, synergy, traversal) for a fixture.

    The real agents' values depend on ``seed`` only; with ``garbage`` every padded slot
    (observations, actions, labels, exemplars, traversal rows) holds large random values.
    """
    parents, labels, exemplars = ROBOTS[name]
    n = len(parents)
    rng = np.random.default_rng(seed)
    obs = np.zeros((batch, n_max, OBS), np.float32)
    action = np.zeros((batch, n_max), np.float32)
    obs[:, :n] = rng.normal(size=(batch, n, OBS))
    action[:, :n] = rng.uniform(-1, 1, (batch, n))
    traversal = np.array(pad_traversal(traversal_indices(parents), n_max))
    junk = np.random.default_rng(seed + 1000) if garbage else None
    if garbage:
        obs[:, n:] = 1e3 * junk.normal(size=(batch, n_max - n, OBS))
        action[:, n:] = 1e3 * junk.normal(size=(batch, n_max - n))
        traversal[n:] = junk.integers(0, n_max, (n_max - n, 3))
    return (
        jnp.asarray(obs),
        jnp.asarray(action),
        jnp.arange(n_max) < n,
        synergy(labels, exemplars, n_max, junk),
        jnp.asarray(traversal),
    )


def tree(name: str, n_max: int):
    """A fixture robot's limb ``Tree`` (SMP's input; the other methods ignore it), its
    senders padded to the fixtures' widest per depth: the walker's 3 depths, the
    humanoid's 4 hips."""
    return make_tree(ROBOTS[name][0], n_max, MAX_CHILDREN, widths=(1, 4, 2))


@functools.cache
def networks(method: str, n_max: int = N_MAX, **overrides) -> tuple:
    """(Networks, (actor params, twin critic params)) at tiny sizes, built once per session.

    Shared between test modules and between methods with the same networks: compiling is
    most of the tests' time (every test uses batch 4 so eager ops compile once)."""
    config = NetworkConfig.tiny(**overrides)
    nets = make_networks(method, config, n_max=n_max, max_children=MAX_CHILDREN)
    if method in _SAME_NETWORKS:
        return nets, networks(_SAME_NETWORKS[method], n_max, **overrides)[1]
    return nets, unoptimised.jit(nets.init)(jax.random.key(0))  # eager: 25 s for SOLAR's
