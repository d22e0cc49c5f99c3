"""Our SOLAR and Amorpheus networks equal the authors' PyTorch networks, parameter for
parameter, on walker_7_main padded to N_max = 9 (garbage in the padding).

The fixture (``make_reference_fixture.py``) holds the reference's parameters at the tiny
sizes, its clustering after the torso rule (one cluster keeps the torso as exemplar
after the torso moved out), random inputs, and its outputs: actions (the torso's
included), each critic's Q, and ΔQ per agent; ``reference_params`` maps its
parameters onto ours.
"""

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from solar_jax.agent.state import Hyper, init_agent
from solar_jax.agent.update import make_td3
from solar_jax.config import NetworkConfig, TD3Config
from solar_jax.morphology import load
from solar_jax.networks import Structure, make_networks
from solar_jax.networks.common import pad_traversal
from solar_jax.replay import Batch
from solar_jax.synergy import Synergy
from solar_jax.synergy.discovery import SuiteAffinity
from solar_jax.synergy.preference import delta_q, delta_q_preference
from tests import unoptimised
from tests.networks.reference_params import amorpheus_actor, critics, policy_group, solar_actor

FIXTURE = Path(__file__).with_name("reference_forward.npz")
N_MAX = 9
CONFIG = NetworkConfig.tiny(gate_hidden=256, embedding_dim=64)  # the reference's fixed widths


@pytest.fixture(scope="module")
def ref():
    return dict(np.load(FIXTURE))


def _solar_actor(ref, actor: str = "actor"):
    return solar_actor(ref, "solar", CONFIG, N_MAX, actor)


def _critics(ref, m, critic: str = "critic"):
    return critics(ref, m, CONFIG, critic)


def _inputs(ref):
    """Padded inputs: real agents first, garbage in the padding."""
    n = len(ref["parents"])
    rng = np.random.default_rng(1)
    obs = rng.normal(size=(len(ref["obs"]), N_MAX, 19)).astype(np.float32) * 100
    action = rng.uniform(-1, 1, size=(len(ref["obs"]), N_MAX)).astype(np.float32)
    obs[:, :n], action[:, :n] = ref["obs"], ref["action"]
    mask = np.arange(N_MAX) < n
    return jnp.asarray(obs), jnp.asarray(action), jnp.asarray(mask), n


def _synergy(labels, exemplars, mask):
    """Our Synergy from the reference's labels and exemplars (after its torso rule)."""
    k = len(exemplars)
    return Synergy(
        labels=jnp.asarray(np.pad(labels, (0, N_MAX - len(labels)), constant_values=-1), jnp.int32),
        exemplars=jnp.asarray(np.pad(exemplars, (0, N_MAX - k), constant_values=-1), jnp.int32),
        num_synergies=jnp.int32(k),
        torso_synergy=jnp.int32(labels[0]),
        agent_mask=mask,
    )


def test_the_fixture_clustering_has_the_torso_rule_edge_case(ref):
    # The torso moved to its own last synergy; the cluster it left keeps it as exemplar.
    labels, exemplars = ref["solar/labels"], ref["solar/exemplars"]
    assert labels[0] == len(exemplars) - 1 and exemplars[-1] == 0
    assert (exemplars[:-1] == 0).any()


def test_solar_actor_critic_and_delta_q_equal_the_reference(ref):
    obs, action, mask, n = _inputs(ref)
    syn = _synergy(ref["solar/labels"], ref["solar/exemplars"], mask)
    traversal = pad_traversal(load("walker_7_main").traversal, N_MAX)
    nets = make_networks("solar", CONFIG, n_max=N_MAX)
    actor, critic = _solar_actor(ref), _critics(ref, "solar")
    # Same tree as our init, so no parameter is missing or extra.
    ours = jax.eval_shape(nets.init, jax.random.key(0))  # the tree, without drawing it
    assert jax.tree.structure(actor) == jax.tree.structure(ours[0])
    assert jax.tree.structure(critic) == jax.tree.structure(ours[1])

    # Jitted (eagerly, each of ~1,000 operations compiles apart: 15 s on 2 cores).
    actions = unoptimised.jit(nets.act)(actor, obs, mask, syn, traversal)
    np.testing.assert_allclose(actions[:, :n], ref["solar/actions"], atol=2e-5)
    np.testing.assert_array_equal(actions[:, n:], 0.0)
    q = unoptimised.jit(nets.q)(critic, obs, action, mask, syn)
    np.testing.assert_allclose(q[0], ref["solar/q1"].mean(-1), rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(q[1], ref["solar/q2"].mean(-1), rtol=1e-4, atol=1e-5)

    def q1(o, a):
        return nets.q(critic, o, a, mask, syn)[0]

    dq = unoptimised.jit(lambda o, a: delta_q(q1, o, a, mask))(obs, action)
    np.testing.assert_allclose(dq[:n], ref["solar/delta_q"].mean(0), rtol=1e-3, atol=1e-5)


def test_amorpheus_actor_and_critic_equal_the_reference(ref):
    obs, action, mask, n = _inputs(ref)
    nets = make_networks("amorpheus", CONFIG, n_max=N_MAX)
    actor = amorpheus_actor(ref, "amorpheus", CONFIG)
    critic = _critics(ref, "amorpheus")
    actions = unoptimised.jit(nets.act)(actor, obs, mask)  # eager: 100 op compiles
    np.testing.assert_allclose(actions[:, :n], ref["amorpheus/actions"], atol=2e-5)
    q = unoptimised.jit(nets.q)(critic, obs, action, mask)  # [2, B, N] per agent
    np.testing.assert_allclose(q[0][:, :n], ref["amorpheus/q1"], rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(q[1][:, :n], ref["amorpheus/q2"], rtol=1e-4, atol=1e-5)


def _padded(x: np.ndarray, n: int) -> np.ndarray:
    """``[..., n(, F)]`` real agents -> ``[..., N_MAX(, F)]``."""
    widths = [(0, 0)] * x.ndim
    widths[-1 if x.ndim == 2 else -2] = (0, N_MAX - n)
    return np.pad(x, widths)


def test_eight_td3_iterations_equal_the_reference(ref):
    # The reference's train_single from the same parameters on the same 8 batches, no
    # target-policy noise: 8 critic steps, 4 actor steps with Polyak updates of both
    # targets (the gate's included), 2 synergy-module steps; each optimiser clips its own
    # gradients. Any difference in groups, order, clipping or Adam shows here.
    n = len(ref["parents"])
    mask = jnp.asarray(np.arange(N_MAX) < n)
    labels, exemplars = ref["train/labels"], ref["train/exemplars"]
    syn = _synergy(labels, exemplars, mask)
    # train_single first re-clusters from ΔQ on its first batch: ours finds the same.
    nets = make_networks("solar", CONFIG, n_max=N_MAX)
    critic = _critics(ref, "solar")
    obs0 = jnp.asarray(_padded(ref["train/obs"][0].reshape(-1, n, 19), n))
    act0 = jnp.asarray(_padded(ref["train/action"][0], n))
    first = _synergy(ref["solar/labels"], ref["solar/exemplars"], mask)

    def q1(o, a):
        return nets.q(critic, o, a, mask, first)[0]

    preference = unoptimised.jit(lambda o, a: delta_q_preference(q1, o, a, mask))(obs0, act0)
    ours = SuiteAffinity([ref["parents"]], N_MAX).cluster(preference[None])
    np.testing.assert_array_equal(ours.labels[0, :n], labels)
    np.testing.assert_array_equal(ours.exemplars[0, : len(exemplars)], exemplars)
    traversal = pad_traversal(load("walker_7_main").traversal, N_MAX)
    structure = Structure(agent_mask=mask, synergy=syn, traversal=traversal)
    td3_config = TD3Config(policy_noise=0.0)
    td3 = make_td3(nets, td3_config)
    # Jitted: eager, each optimiser-state leaf shape compiles its own program.
    state = unoptimised.jit(init_agent, static_argnums=2)(
        _solar_actor(ref), _critics(ref, "solar"), td3_config
    )
    hyper = Hyper.from_config(td3_config)
    update = unoptimised.jit(td3.update)
    for i in range(1, len(ref["train/obs"])):  # batch 0 was the reference's ΔQ batch
        b = len(ref["train/obs"][i])
        batch = Batch(
            obs=jnp.asarray(_padded(ref["train/obs"][i].reshape(b, n, 19), n)),
            action=jnp.asarray(_padded(ref["train/action"][i], n)),
            reward=jnp.asarray(ref["train/reward"][i][:, 0]),
            next_obs=jnp.asarray(_padded(ref["train/next_obs"][i].reshape(b, n, 19), n)),
            terminated=jnp.asarray(ref["train/done"][i][:, 0] > 0.5),
        )
        state, _ = update(state, batch, structure, jnp.int32(i - 1), jax.random.key(i), hyper)

    after = _trained(ref)  # the reference's parameters after its 8 iterations
    start = _solar_actor(ref)
    target_actor = _solar_actor(after, actor="target_actor")
    for ours, expected, before in (
        (state.actor, _solar_actor(after), start),
        (state.target_actor, policy_group(target_actor), policy_group(start)),
        (state.critic, _critics(after, "solar"), _critics(ref, "solar")),
        (state.target_critic, _critics(after, "solar", "target_critic"), _critics(ref, "solar")),
    ):
        for path, value in jax.tree_util.tree_leaves_with_path(expected):
            name = jax.tree_util.keystr(path)
            got, value, start_value = (np.asarray(_at(t, path)) for t in (ours, expected, before))
            if "embedding" in name:  # our tables have N_MAX rows, the reference's N
                got, value, start_value = got[:n], value[:n], start_value[:n]
            moved = np.abs(value - start_value).max()
            if "['key']['bias']" in name:
                # Its exact gradient is 0 (a key bias shifts a query's logits equally):
                # both sides move it by float noise only.
                assert moved < 1e-5 and np.abs(got - start_value).max() < 1e-5, name
                continue
            assert moved > 1e-5, f"{name} did not move in the reference"
            np.testing.assert_allclose(got, value, atol=1e-6, rtol=1e-4, err_msg=name)


def _trained(ref) -> dict:
    """The fixture's trained parameters under the forward parameters' names."""
    return {
        f"solar/{k.removeprefix('train/')}": v for k, v in ref.items() if k.startswith("train/")
    }


def _at(tree, path):
    for key in path:
        tree = tree[key.key]
    return tree
