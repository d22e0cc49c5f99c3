"""SOLAR's actor and critic (algorithm.md §4): padding and relabelling invariance, the
action transformation against a NumPy oracle, the d = 1 warning, the parameter groups."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from solar_jax.config import NetworkConfig
from solar_jax.networks import GATE, TRANSFORM, make_networks
from solar_jax.networks.common import MLP, mask_actions
from solar_jax.networks.solar import (
    Gate,
    SolarActor,
    SynergyModule,
    intra_synergy_attention,
    transform_actions,
)
from solar_jax.synergy import Synergy
from tests import unoptimised
from tests.networks.inputs import N_MAX, ROBOTS, networks, robot, synergy

BATCH = 4


def _fewer_rows(params, n_max: int):
    """The actor's parameters for a smaller n_max: the first rows of each traversal table."""
    params = jax.tree.map(lambda x: x, params)  # a copy to edit
    for order in ("pre", "in", "post"):
        table = params[TRANSFORM][f"{order}_order"]["embedding"]
        params[TRANSFORM][f"{order}_order"] = {"embedding": table[:n_max]}
    return params


@pytest.mark.parametrize("variant", [{}, {"hard_mask": True, "paper_transform": True}])
def test_padding_agents_and_synergies_change_nothing(variant):
    # walker_7 (7 agents, 3 synergies) padded to 7 (clean) and to 9 (garbage padding).
    nets, (actor, critic) = networks("solar", **variant)
    obs, action, mask, syn, trav = robot("walker_7_main", 7, BATCH)
    big = robot("walker_7_main", N_MAX, BATCH, garbage=True)
    small_nets = make_networks("solar", nets.config, n_max=7)
    # Jitted: eagerly, this test took 15-18 s on 2 cores (default variant), jitted 11 s.
    a_small = unoptimised.jit(small_nets.act)(_fewer_rows(actor, 7), obs, mask, syn, trav)
    a_big = unoptimised.jit(nets.act)(actor, big[0], big[2], big[3], big[4])
    np.testing.assert_allclose(a_big[:, :7], a_small, atol=1e-5)
    np.testing.assert_array_equal(a_big[:, 7:], 0.0)
    if variant:
        return  # the critic's trunk is the actor's: checked with the default variant
    q_small = unoptimised.jit(small_nets.q)(critic, obs, action, mask, syn)
    q_big = unoptimised.jit(nets.q)(critic, *big[:4])
    assert q_big.shape == (2, BATCH)
    np.testing.assert_allclose(q_big, q_small, atol=1e-5)


def test_fewer_synergy_slots_change_nothing_up_to_rounding():
    # humanoid_2d_9_full: K = 5 of 9 slots, cut to 5 and to 6 (one padded synergy left).
    # The update runs the smallest slot bucket holding K (``Trainer._in_slot_bucket``).
    nets, (actor, critic) = networks("solar")
    obs, action, mask, syn, trav = robot("humanoid_2d_9_full", N_MAX, BATCH, garbage=True)

    @unoptimised.jit
    def outputs(actor, critic, syn):
        act = nets.act(actor, obs, mask, syn, trav)
        q = nets.q(critic, obs, action, mask, syn)

        def actor_objective(actor, critic):  # the actor's loss's path through both
            return jnp.sum(nets.q1(critic, obs, nets.act(actor, obs, mask, syn, trav), mask, syn))

        return act, q, jax.grad(actor_objective, argnums=(0, 1))(actor, critic)

    full = outputs(actor, critic, syn)
    for slots in (5, 6):
        cut = outputs(actor, critic, syn.with_slots(slots))
        jax.tree.map(lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6), cut, full)


def test_relabelling_clusters_changes_nothing():
    nets, (actor, critic) = networks("solar")
    obs, action, mask, syn, trav = robot("humanoid_2d_9_full", N_MAX, BATCH)
    _, labels, exemplars = ROBOTS["humanoid_2d_9_full"]
    perm = np.array([3, 0, 4, 1, 2])  # synergy k becomes perm[k]
    new_exemplars = np.empty(5, int)
    new_exemplars[perm] = exemplars
    relabelled = synergy(perm[labels], new_exemplars, N_MAX)
    assert int(relabelled.torso_synergy) == 2
    act, q = unoptimised.jit(nets.act), unoptimised.jit(nets.q)  # one compile for both labellings
    np.testing.assert_allclose(
        act(actor, obs, mask, relabelled, trav), act(actor, obs, mask, syn, trav), atol=1e-5
    )
    np.testing.assert_allclose(
        q(critic, obs, action, mask, relabelled), q(critic, obs, action, mask, syn), atol=1e-5
    )


def _numpy_transform(params, cfg, y, encoded, syn: Synergy, traversal):
    """algorithm.md §4's action transformation, written out in float64 NumPy."""
    p = jax.tree.map(lambda x: np.asarray(x, np.float64), params)
    n, s, d = traversal.shape[0], cfg.transform_heads, cfg.transform_dim
    emb = np.concatenate(
        [
            p[f"{o}_order"]["embedding"][traversal[:, i]]
            for i, o in enumerate(("pre", "in", "post"))
        ],
        axis=1,
    )
    structure = emb @ p["structure"]["kernel"] + p["structure"]["bias"]  # [N, S d]
    heads = structure.reshape(n, s, d)
    mask = np.asarray(syn.agent_mask)
    labels, k = np.asarray(syn.labels), int(syn.num_synergies)
    torso, exemplars = int(syn.torso_synergy), np.asarray(syn.exemplars)
    w = np.zeros((n, k))  # membership, torso column all ones
    for i in np.flatnonzero(mask):
        w[i, labels[i]] = w[i, torso] = 1.0
    y = np.asarray(y, np.float64)[:, :k]
    actions = np.zeros((y.shape[0], n))
    gate = None
    if not cfg.paper_transform:
        g_in = np.concatenate(
            [np.asarray(encoded, np.float64), np.broadcast_to(structure, (y.shape[0], n, s * d))],
            -1,
        )
        g = p["gate"]
        hidden = np.maximum(g_in @ g["dense_0"]["kernel"] + g["dense_0"]["bias"], 0.0)
        gate = hidden @ g["dense_1"]["kernel"] + g["dense_1"]["bias"]  # [B, N, S]
    for b in range(y.shape[0]):
        for i in range(n):
            total = 0.0
            for h in range(s):
                k1, e = heads[:, h, 0], heads[:, h, 1:]
                a_mat = e @ e.T / d - np.diag(k1)
                if cfg.paper_transform:  # columns averaged over each cluster's members
                    t = [a_mat[i] @ w[:, c] / w[:, c].sum() for c in range(k)]
                    total += np.dot(t, y[b])
                else:
                    t0 = [a_mat[exemplars[c], i] * w[i, c] for c in range(k)]
                    total += gate[b, i, h] * np.dot(t0, y[b])
            actions[b, i] = np.tanh(total / s)
    if not cfg.torso_action:
        actions[:, 0] = 0.0
    return np.where(mask, actions, 0.0)


@pytest.mark.parametrize("paper", [False, True])
def test_action_transform_matches_numpy_for_a_three_agent_robot(paper):
    # hopper_3 (3 agents) padded to 4; synergy 0 = {1, 2} with exemplar 2, torso alone.
    cfg = NetworkConfig.tiny(paper_transform=paper)
    _, action, mask, syn, trav = robot("hopper_3", 4, 2, garbage=True)
    rng = np.random.default_rng(1)
    y = jnp.asarray(rng.normal(size=(2, 4)) + 100.0 * (np.arange(4) >= 2), jnp.float32)
    encoded = jnp.asarray(rng.normal(size=(2, 4, cfg.width)), jnp.float32)

    @unoptimised.jit  # one program (eagerly: 76 small ones)
    def actor_pieces(trav, syn, y, encoded, mask):
        """The actor's pieces as SolarActor wires them: synergy module, gate, transform."""
        module = SynergyModule(cfg)
        params = module.init(jax.random.key(3), trav)["params"]
        relation, structure = module.apply({"params": params}, trav)
        gate = None
        if not paper:
            gate_mlp = Gate(cfg.gate_hidden, cfg.transform_heads)
            params = params | {"gate": gate_mlp.init(jax.random.key(4), encoded, structure)}
            params["gate"] = params["gate"]["params"]
            gate = gate_mlp.apply({"params": params["gate"]}, encoded, structure)
        pre_tanh = transform_actions(cfg, relation, syn, y, gate)
        return params, mask_actions(jnp.tanh(pre_tanh), mask, cfg.torso_action)

    params, got = actor_pieces(trav, syn, y, encoded, mask)
    trav_np = np.where(np.asarray(mask)[:, None], np.asarray(trav), 0)  # padded rows unused
    want = _numpy_transform(params, cfg, y, encoded, syn, trav_np)
    assert np.abs(want[:, 1:3]).min() > 1e-3  # a non-trivial comparison
    np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-6)


def test_gate_is_an_mlp_of_the_encoded_input_and_the_structure_embedding():
    # The gate computes the structure's part of its first layer once per agent; its
    # parameters, their Flax initial values and its outputs are those of the plain MLP
    # over the concatenated input.
    rng = np.random.default_rng(0)
    encoded = jnp.asarray(rng.normal(size=(3, 5, 16)), jnp.float32)
    structure = jnp.asarray(rng.normal(size=(5, 8)), jnp.float32)
    joined = jnp.concatenate([encoded, jnp.broadcast_to(structure, (3, 5, 8))], axis=-1)
    gate, mlp = Gate(32, 4), MLP((32, 4))
    params = gate.init(jax.random.key(1), encoded, structure)
    assert jax.tree.all(jax.tree.map(np.array_equal, params, mlp.init(jax.random.key(1), joined)))
    np.testing.assert_allclose(
        gate.apply(params, encoded, structure), mlp.apply(params, joined), rtol=1e-5, atol=1e-6
    )


def test_d_equal_one_zeroes_non_exemplar_actions():
    # algorithm.md §4's warning: with d = 1, A is diagonal, so only exemplars act (the
    # torso too: it is the torso synergy's exemplar, and acts by default).
    actor = SolarActor(NetworkConfig.tiny(transform_dim=1))
    obs, _, mask, syn, trav = robot("humanoid_2d_9_full", N_MAX, BATCH)
    params = unoptimised.jit(actor.init)(jax.random.key(0), obs, mask, syn, trav)
    actions = np.asarray(unoptimised.jit(actor.apply)(params, obs, mask, syn, trav))
    exemplars = [0, 2, 3, 6, 7]
    others = [1, 4, 5, 8]
    np.testing.assert_array_equal(actions[:, others], 0.0)
    assert np.all(np.abs(actions[:, exemplars]) > 0)


def test_synergy_module_and_gate_are_their_own_parameter_groups():
    # algorithm.md §4: the synergy module (embeddings + Linear) and the gate MLP apart from
    # the trunk, so the agent can give them the reference's optimiser groups.
    _, (actor, critic) = networks("solar")
    assert set(actor) == {"trunk", TRANSFORM, GATE}
    assert set(actor[TRANSFORM]) == {"pre_order", "in_order", "post_order", "structure"}
    assert set(actor[GATE]) == {"dense_0", "dense_1"}
    assert TRANSFORM not in critic and GATE not in critic
    # Every group shapes the actions: each one's gradient is nonzero.
    nets = networks("solar")[0]
    obs, _, mask, syn, trav = robot("walker_7_main", N_MAX, 2)
    # Jitted: eagerly, its ~770 operations each compiled apart (14 s on 2 cores).
    grads = unoptimised.jit(jax.grad(lambda p: jnp.sum(nets.act(p, obs, mask, syn, trav))))(actor)
    for group in ("trunk", TRANSFORM, GATE):
        assert any(np.abs(g).max() > 0 for g in jax.tree.leaves(grads[group]))


def test_hard_mask_blocks_attention_across_synergies():
    cfg = NetworkConfig.tiny(hard_mask=True)
    _, _, mask, syn, _ = robot("walker_7_main", N_MAX, 1)
    allowed, bias = intra_synergy_attention(cfg, mask, syn)
    assert bias is None
    np.testing.assert_array_equal(allowed[:7, :7], syn.hard_mask[:7, :7])
    assert not allowed[1, 4] and allowed[1, 0] and allowed[0, 4]
    assert not np.any(allowed[:, 7:])
    soft_allowed, soft_bias = intra_synergy_attention(NetworkConfig.tiny(), mask, syn)
    assert np.all(soft_allowed[:, :7]) and not np.any(soft_allowed[:, 7:])
    np.testing.assert_allclose(soft_bias, syn.attention_bias)
