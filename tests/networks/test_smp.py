"""Our SMP equals the reference's (the Amorpheus code base's SMP, both passes, torchfold
on), parameter for parameter: walker_7_main and humanoid_2d_9_full padded to N_max with
garbage in the padding, through one network; and 8 TD3 iterations of the reference's
``train_single``. The fixture is ``make_smp_fixture.py``'s. Then what batching must not
change: a limb's outputs whatever N_max, the rounds and the other morphologies.
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
from solar_jax.networks import (
    Structure,
    example_inputs,
    limb_trees,
    make_networks,
    make_tree,
    pad_traversal,
)
from solar_jax.networks.smp import up_route
from solar_jax.replay import Batch
from tests import unoptimised

FIXTURE = Path(__file__).with_name("smp_reference.npz")
N_MAX = 11  # two more than the humanoid: every robot has padding
ROBOTS = ("walker_7_main", "humanoid_2d_9_full")


@pytest.fixture(scope="module")
def ref():
    return dict(np.load(FIXTURE))


def _config(ref) -> NetworkConfig:
    message, width, *hidden = (int(x) for x in ref["sizes"])
    return NetworkConfig.tiny(mlp_hidden=tuple(hidden), message_dim=message, message_width=width)


def _networks(ref, n_max: int = N_MAX):
    return make_networks("smp", _config(ref), n_max, max_children=int(ref["max_children"]))


def _dense(ref, key):
    return {"kernel": jnp.asarray(ref[f"{key}.weight"].T), "bias": jnp.asarray(ref[f"{key}.bias"])}


def _mlp(ref, key):
    return {f"dense_{i}": _dense(ref, f"{key}.l{i + 1}") for i in range(3)}


def _params(ref, tag: str, actor: str = "actor", critic: str = "critic"):
    """The fixture's torch modules as our (actor, critic) trees."""
    up = {name: _dense(ref, f"{tag}/{actor}/up/{name}") for name in ("fc1", "fc2", "fc3")}
    actor_params = {
        "up": up,
        "msg_base": _mlp(ref, f"{tag}/{actor}/down/msg_base"),
        "action_base": _mlp(ref, f"{tag}/{actor}/down/action_base"),
    }
    up = {name: _dense(ref, f"{tag}/{critic}/up/{name}") for name in ("fc1", "fc2", "fc3")}
    critic_params = {
        "up": up,
        "msg_base": _mlp(ref, f"{tag}/{critic}/down/msg_base"),
        "q1": _mlp(ref, f"{tag}/{critic}/down/baseQ1"),
        "q2": _mlp(ref, f"{tag}/{critic}/down/baseQ2"),
    }
    return actor_params, critic_params


def _padded(ref, name: str, n_max: int = N_MAX, seed: int = 1, widths=None):
    """(obs [B, n_max, 19], action [B, n_max], mask, tree): the fixture's limbs first,
    garbage (large values, NaN) in the padding; ``widths``: the tree's senders'."""
    parents = ref[f"{name}/parents"]
    n, batch = len(parents), len(ref[f"{name}/obs"])
    rng = np.random.default_rng(seed)
    obs = rng.normal(size=(batch, n_max, 19)).astype(np.float32) * 1e3
    action = rng.uniform(-1, 1, size=(batch, n_max)).astype(np.float32)
    obs[:, n:, 0], action[:, n:] = np.nan, np.nan
    obs[:, :n] = ref[f"{name}/obs"].reshape(batch, n, 19)
    action[:, :n] = ref[f"{name}/action_in"]
    tree = make_tree(parents, n_max, int(ref["max_children"]), False, widths)
    return jnp.asarray(obs), jnp.asarray(action), jnp.asarray(np.arange(n_max) < n), tree


@pytest.mark.parametrize("name", ROBOTS)
def test_actor_and_critic_equal_the_reference(ref, name):
    nets = _networks(ref)
    actor, critic = _params(ref, "init")
    obs, action, mask, tree = _padded(ref, name)
    n = len(ref[f"{name}/parents"])
    acted = unoptimised.jit(lambda o, m, t: nets.act(actor, o, m, tree=t))(obs, mask, tree)
    q = unoptimised.jit(lambda o, a, m, t: nets.q(critic, o, a, m, tree=t))(obs, action, mask, tree)
    first = unoptimised.jit(lambda o, a, m, t: nets.q1(critic, o, a, m, tree=t))(
        obs, action, mask, tree
    )
    np.testing.assert_allclose(acted[:, :n], ref[f"{name}/action"], atol=1e-5)
    np.testing.assert_allclose(q[:, :, :n], ref[f"{name}/q"], atol=1e-5)
    np.testing.assert_allclose(first[:, :n], ref[f"{name}/q1"], atol=1e-5)
    assert not np.any(acted[:, n:]) and not np.any(q[:, :, n:])  # the padding: zeros


def test_the_tree_follows_birth_order_depths_and_the_flipped_walker_s_first_limb():
    parents = (-1, 0, 1, 0, 3, 3)  # torso with two children; limb 3 with two
    tree = make_tree(parents, 7, 3)
    up = up_route(tree, jnp.arange(7) < 6, 3)
    assert up.shape == (7, 3, 7)
    assert {tuple(map(int, i)) for i in np.argwhere(np.asarray(up))} == {
        (0, 0, 1),  # limb 1: the torso's first child
        (0, 1, 3),  # limb 3: its second
        (1, 0, 2),
        (3, 0, 4),
        (3, 1, 5),
    }
    np.testing.assert_array_equal(tree.down_slot, [-1, 0, 0, 1, 0, 1, -1])
    assert [s.tolist() for s in tree.senders] == [[0], [1, 3]]  # by depth, leaves not
    flipped = make_tree(parents, 7, 3, flipped=True)
    # The reference reverses the slot of limb 1 only (top_down_transmission).
    np.testing.assert_array_equal(flipped.down_slot, [-1, 2, 0, 1, 0, 1, -1])
    np.testing.assert_array_equal(flipped.sibling, tree.sibling)  # bottom-up: birth order
    padded = make_tree(parents, 7, 3, widths=(2, 3, 1)).senders
    assert [s.tolist() for s in padded] == [[0, -1], [1, 3, -1], [-1]]


def test_the_suite_s_trees_share_one_shape():
    walker, humanoid = load("walker_7_main"), load("humanoid_2d_9_full")
    trees, children = limb_trees([walker.parents, humanoid.parents], ["a", "b"], 9)
    assert children == 4 and trees.parents.shape == (2, 9)
    # Per depth, the widest: the torso; the humanoid's 4 hips; the walker's 2 knees.
    assert [s.shape for s in trees.senders] == [(2, 1), (2, 4), (2, 2)]
    with pytest.raises(ValueError, match="do not fit"):
        make_tree(walker.parents, 9, 4, widths=(1, 4))


def test_a_limb_with_too_many_children_is_one_error():
    with pytest.raises(ValueError, match="a limb has 3 children, more than 2"):
        make_tree((-1, 0, 0, 0), 4, 2)


def test_outputs_do_not_depend_on_padding_rounds_or_the_other_morphologies(ref):
    actor, critic = _params(ref, "init")
    walker, humanoid = ROBOTS

    def outputs(n_max: int, widths=(1, 4, 2), names=ROBOTS, seed: int = 1):
        """Each robot's real limbs' (actions, Q), the robots stacked as morphologies."""
        nets = _networks(ref, n_max)
        inputs = [_padded(ref, name, n_max, seed, widths) for name in names]
        obs, action, mask, tree = jax.tree.map(lambda *x: jnp.stack(x), *inputs)

        @unoptimised.jit
        @jax.vmap
        def act_and_q(obs, action, mask, tree):  # one program per layout
            return nets.act(actor, obs, mask, tree=tree), nets.q(
                critic, obs, action, mask, tree=tree
            )

        acted, q = act_and_q(obs, action, mask, tree)
        sizes = [len(ref[f"{name}/parents"]) for name in names]
        return {
            name: (np.asarray(acted[i, :, :n]), np.asarray(q[i, :, :, :n]))
            for i, (name, n) in enumerate(zip(names, sizes, strict=True))
        }

    base = outputs(N_MAX)
    for other in (
        outputs(16, seed=2),  # more padding, other garbage in it
        outputs(9, widths=(3, 5, 4, 2)),  # no padding for the humanoid; more senders
        outputs(N_MAX, names=(humanoid, walker)),  # order
        outputs(N_MAX, widths=None, names=(walker,)),  # alone, its own senders
    ):
        for name, (acted, q) in other.items():
            np.testing.assert_allclose(acted, base[name][0], atol=1e-6, err_msg=name)
            np.testing.assert_allclose(q, base[name][1], atol=1e-6, err_msg=name)


def test_eight_td3_iterations_equal_the_reference(ref):
    # The reference's train_single from the same parameters on the same 8 batches, no
    # target-policy noise, no gradient clip (SMP's scripts): 8 critic steps on per-limb
    # TD targets, 4 actor steps with Polyak updates of both targets.
    lr, discount, tau, delay = ref["train/settings"]
    td3_config = TD3Config(
        lr=float(lr),
        discount=float(discount),
        tau=float(tau),
        policy_delay=int(delay),
        policy_noise=0.0,
        grad_clip=0.0,
    )
    nets = _networks(ref)
    parents = ref[f"{ROBOTS[0]}/parents"]
    n = len(parents)
    mask = jnp.asarray(np.arange(N_MAX) < n)
    _, action, _, tree = _padded(ref, ROBOTS[0])
    traversal = pad_traversal(load(ROBOTS[0]).traversal, N_MAX)
    synergy = example_inputs(N_MAX)[3]  # SMP reads none
    structure = Structure(agent_mask=mask, synergy=synergy, traversal=traversal, tree=tree)
    td3 = make_td3(nets, td3_config)
    state = unoptimised.jit(init_agent, static_argnums=2)(*_params(ref, "init"), td3_config)
    hyper = Hyper.from_config(td3_config)
    update = unoptimised.jit(td3.update)

    def padded(x, features: bool):
        x = x.reshape(len(x), n, 19) if features else x
        widths = [(0, 0), (0, N_MAX - n)] + ([(0, 0)] if features else [])
        return jnp.asarray(np.pad(x, widths))

    for i in range(8):
        batch = Batch(
            obs=padded(ref[f"train/{i}/obs"], True),
            action=padded(ref[f"train/{i}/action"], False),
            reward=jnp.asarray(ref[f"train/{i}/reward"][:, 0]),
            next_obs=padded(ref[f"train/{i}/next_obs"], True),
            terminated=jnp.asarray(ref[f"train/{i}/done"][:, 0] > 0.5),
        )
        state, _ = update(state, batch, structure, jnp.int32(i), jax.random.key(i), hyper)

    actor, critic = _params(ref, "trained")
    target_actor, target_critic = _params(ref, "trained", "target_actor", "target_critic")
    start_actor, start_critic = _params(ref, "init")
    for ours, expected, before in (
        (state.actor, actor, start_actor),
        (state.target_actor, target_actor, start_actor),
        (state.critic, critic, start_critic),
        (state.target_critic, target_critic, start_critic),
    ):
        for path, value in jax.tree_util.tree_leaves_with_path(expected):
            name = jax.tree_util.keystr(path)
            got, start = _at(ours, path), _at(before, path)
            moved = np.abs(np.asarray(value) - np.asarray(start)).max()
            assert moved > 1e-5, f"{name} did not move in the reference"
            np.testing.assert_allclose(got, value, atol=1e-6, rtol=1e-4, err_msg=name)


def _at(tree, path):
    for key in path:
        tree = tree[key.key]
    return np.asarray(tree)
