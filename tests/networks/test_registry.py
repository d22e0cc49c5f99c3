"""Every registered method builds and runs under jit and vmap over morphologies with
different synergy structures; the torso's and padded actions are ignored."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from solar_jax.networks import METHODS, make_networks
from tests import unoptimised
from tests.networks.inputs import N_MAX, networks, robot, tree

BATCH = 4


def _stacked(*robots):
    return jax.tree.map(lambda *xs: jnp.stack(xs), *robots)


def test_unknown_method_lists_the_valid_names():
    with pytest.raises(ValueError, match="solar, solar_no_pref, amorpheus, amorpheus_mask, smp"):
        make_networks("gnn")


def test_solar_no_pref_is_solar_with_median_preferences():
    # The ablation lives in synergy discovery; its networks are SOLAR's.
    ablation, solar = make_networks("solar_no_pref"), make_networks("solar")
    assert ablation.actor == solar.actor
    assert type(ablation.critic).__name__ == type(solar.critic).__name__ == "VmapSolarCritic"
    assert solar.delta_q_preference and not ablation.delta_q_preference
    assert solar.uses_synergy and not make_networks("amorpheus").uses_synergy


@pytest.mark.parametrize("method", [m for m in METHODS if m != "solar_no_pref"])
def test_jit_and_vmap_over_morphologies(method):
    nets, (actor, critic) = networks(method)
    # Two morphologies with different agent counts and synergy structures, one call.
    batch = _stacked(
        (*robot("walker_7_main", N_MAX, BATCH, garbage=True), tree("walker_7_main", N_MAX)),
        (
            *robot("humanoid_2d_9_full", N_MAX, BATCH, seed=1),
            tree("humanoid_2d_9_full", N_MAX),
        ),
    )

    @unoptimised.jit
    @jax.vmap
    def act_and_q(obs, action, mask, syn, trav, tr):  # one compilation for both
        return (
            nets.act(actor, obs, mask, syn, trav, tr),
            nets.q(critic, obs, action, mask, syn, tr),
        )

    actions, values = act_and_q(*batch)
    assert actions.shape == (2, BATCH, N_MAX) and actions.dtype == jnp.float32
    q_shape = (2, 2, BATCH, N_MAX) if nets.per_agent_q else (2, 2, BATCH)
    assert values.shape == q_shape and values.dtype == jnp.float32
    assert np.all(np.isfinite(actions)) and np.all(np.isfinite(values))
    assert np.all(np.abs(actions) <= 1.0)
    assert not np.allclose(values[:, 0], values[:, 1])  # twin critics are independent
    act, q, q1 = (unoptimised.jit(f) for f in (nets.act, nets.q, nets.q1))
    for m in range(2):  # vmapped == one morphology at a time
        obs, action, mask, syn, trav, tr = jax.tree.map(lambda x, m=m: x[m], batch)
        np.testing.assert_allclose(actions[m], act(actor, obs, mask, syn, trav, tr), atol=1e-5)
        np.testing.assert_allclose(values[m], q(critic, obs, action, mask, syn, tr), atol=1e-5)
        # q1, the first critic run alone (what the actor's loss and ΔQ read), is q's first.
        first = q1(critic, obs, action, mask, syn, tr)
        np.testing.assert_allclose(values[m][0], first, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize(
    ("method", "torso_action"),
    [(method, True) for method in METHODS] + [(m, False) for m in ("solar", "smp", "monolithic")],
)
def test_padded_actions_are_zero_and_ignored_the_torso_s_as_switched(method, torso_action):
    # algorithm.md §2: by default the actor acts for the torso and the critic reads that
    # action (the physics ignores it); network.torso_action=false zeroes it everywhere.
    nets, (actor, critic) = networks(method, torso_action=torso_action)
    act, q_of = unoptimised.jit(nets.act), unoptimised.jit(nets.q)  # eager: 200+ op compiles
    obs, action, mask, syn, trav = robot("walker_7_main", N_MAX, BATCH)
    tr = tree("walker_7_main", N_MAX)
    actions = act(actor, obs, mask, syn, trav, tr)
    np.testing.assert_array_equal(actions[:, 7:], 0.0)
    assert np.all(np.abs(actions[:, 1:7]) > 0)
    assert np.all(np.abs(actions[:, 0]) > 0) == torso_action
    assert np.all(actions[:, 0] == 0) == (not torso_action)
    q = q_of(critic, obs, action, mask, syn, tr)
    padded = action.at[:, 7:].set(-3.0)
    np.testing.assert_array_equal(q_of(critic, obs, padded, mask, syn, tr), q)
    torso = action.at[:, 0].set(0.9)
    assert np.array_equal(q_of(critic, obs, torso, mask, syn, tr), q) == (not torso_action)
    changed = action.at[:, 3].add(0.5)  # a real actuator's action does matter
    assert not np.allclose(q_of(critic, obs, changed, mask, syn, tr), q)
