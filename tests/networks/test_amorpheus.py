"""The Amorpheus baseline (algorithm.md §4): permutation equivariance, padding, the
amorpheus_mask ablation."""

import jax
import numpy as np

from tests import unoptimised
from tests.networks.inputs import N_MAX, networks, robot

BATCH = 4


def test_permutation_equivariant_over_agents():
    # walker_7 in 9 slots; move agents 1..6 and the two padding slots around (the torso,
    # agent 0 by convention, stays first).
    nets, (actor, critic) = networks("amorpheus")
    obs, action, mask, _, _ = robot("walker_7_main", N_MAX, BATCH, garbage=True)
    perm = np.array([0, 5, 2, 8, 1, 3, 7, 4, 6])  # old slot i -> new slot perm[i]
    inv = np.argsort(perm)
    p_obs, p_action, p_mask = obs[:, inv], action[:, inv], mask[inv]
    np.testing.assert_array_equal(p_mask[perm], mask)
    act, q = unoptimised.jit(nets.act), unoptimised.jit(nets.q)  # one compile each for both orders
    a, p_a = act(actor, obs, mask), act(actor, p_obs, p_mask)
    np.testing.assert_allclose(p_a[:, perm], a, atol=1e-5)
    q, p_q = q(critic, obs, action, mask), q(critic, p_obs, p_action, p_mask)
    assert q.shape == (2, BATCH, N_MAX)
    np.testing.assert_allclose(p_q[:, :, perm], q, atol=1e-5)


def test_padding_agents_change_nothing():
    nets, (actor, critic) = networks("amorpheus")
    small = robot("walker_7_main", 7, BATCH)
    big = robot("walker_7_main", N_MAX, BATCH, garbage=True)
    act, q = unoptimised.jit(nets.act), unoptimised.jit(nets.q)  # eagerly: 12 s of op compiles
    np.testing.assert_allclose(
        act(actor, big[0], big[2])[:, :7], act(actor, small[0], small[2]), atol=1e-5
    )
    q_big = q(critic, *big[:3])
    np.testing.assert_allclose(q_big[..., :7], q(critic, *small[:3]), atol=1e-5)
    np.testing.assert_array_equal(q_big[..., 7:], 0.0)


def test_amorpheus_mask_adds_the_synergy_bias_to_the_first_layer():
    plain, (actor, critic) = networks("amorpheus")
    masked, (m_actor, _) = networks("amorpheus_mask")
    assert jax.tree.structure(actor) == jax.tree.structure(m_actor)  # same parameters
    obs, action, mask, syn, trav = robot("humanoid_2d_9_full", N_MAX, BATCH)
    act, act_masked = unoptimised.jit(plain.act), unoptimised.jit(masked.act)  # eagerly: 55
    a, m_a = act(actor, obs, mask), act_masked(actor, obs, mask, syn, trav)
    assert np.abs(a - m_a).max() > 1e-4
    # With every agent in the torso synergy only, the bias is 0: the two coincide.
    flat = syn.replace(labels=np.where(mask, 0, -1), torso_synergy=np.int32(0))
    np.testing.assert_allclose(act_masked(actor, obs, mask, flat, trav), a, atol=1e-5)
