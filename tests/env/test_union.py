"""A union world's pool and tables: entry ``k * P + p`` is robot ``k``'s variant ``p`` as
MuJoCo C compiles it, on the robot's elements of the union; each robot's observation
layout, motors and reset noise sit on its own elements; redrawn variants stay the
robot's own. The physics against MuJoCo C: tests/morphology/test_union.py (C),
tests/env/test_batch.py (the batch of all 38 robots) and tests/training/test_collect.py
(a union collects what a model per robot collects)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from solar_jax.config import EnvConfig
from solar_jax.env.batch import MultiEnv
from solar_jax.env.variants import model_of
from solar_jax.morphology import load
from solar_jax.morphology.variants import PROPERTIES, make_variants
from tests.env.test_variants import PER_BODY, PER_OTHER, _c_model, _NominalFields
from tests.unoptimised import jit_physics

P = 3  # variants per robot


def _env(redraw=False):
    robots = [load(name) for name in ("hopper_3", "hopper_5", "hopper_4")]
    variants = [[r] + [v.morph for v in make_variants(r, PROPERTIES, P - 1, 4)] for r in robots]
    return MultiEnv(robots, 2, variants=variants, redraw=redraw), variants


def test_each_entry_is_its_robot_s_variant_on_its_own_elements():
    env, variants = _env()
    assert env.groups == [[1, 0, 2]]  # hopper_5 hosts
    union = env.unions[0]
    assert union.per_robot == P and union.pool.size == 3 * P
    for k, robot in enumerate(env.groups[0]):
        emb = union.union.embeddings[k]
        for p, variant in enumerate(variants[robot]):
            entry = k * P + p
            gathered = model_of(
                _NominalFields(union.world.model), union.pool, jnp.array([entry])
            ).fields
            c_model = _c_model(variant)
            axes = {"body": emb.body, "geom": emb.geom, "jnt": emb.jnt, "dof": emb.dof}
            axes["actuator"] = emb.actuator
            for axis, names in {"body": PER_BODY, **PER_OTHER}.items():
                for name in names:
                    got = np.asarray(gathered.get(name, getattr(union.world.model, name)))
                    want = getattr(c_model, name).astype(np.float32)
                    np.testing.assert_allclose(got[axes[axis]], want, rtol=1e-6, err_msg=name)
            np.testing.assert_allclose(gathered["qpos0"][emb.qpos], c_model.qpos0, rtol=1e-6)
            # The union's other elements are dummies: massless, motors without gear.
            dummies = np.setdiff1d(np.arange(union.world.model.nbody), emb.body)
            assert (np.asarray(gathered["body_mass"])[dummies] == 0).all()
            others = np.setdiff1d(np.arange(union.world.model.nu), emb.actuator)
            assert (np.asarray(gathered["actuator_gear"])[others] == 0).all()
            # Its tables: observation, motors and reset noise on its own elements.
            tables = jax.tree.map(lambda x, e=entry: x[e], union.tables)
            morph = variant
            n = morph.num_agents
            np.testing.assert_array_equal(tables.layout.body_ids[0, :n], emb.body[1 : n + 1])
            np.testing.assert_array_equal(tables.layout.qpos_adr[0, :n], emb.qpos[morph.qpos_adr])
            agents = np.flatnonzero(morph.actuators >= 0)
            np.testing.assert_array_equal(
                tables.ctrl_agent[emb.actuator[morph.actuators[agents]]], agents
            )
            assert tables.ctrl_on.sum() == morph.num_actuators
            noisy = np.flatnonzero(tables.task["qpos_noise"])
            assert set(noisy) <= set(emb.qpos) and len(noisy) > 0
            np.testing.assert_array_equal(tables.draw_qpos[emb.qpos], np.arange(len(emb.qpos)))


def test_redrawn_variants_stay_the_robot_s_own():
    env, _ = _env(redraw=True)
    reset = jit_physics(env.reset)
    seen = set()
    for seed in range(4):
        variant = np.asarray(reset(jax.random.key(seed)).worlds[0].variant)  # [B, G]
        np.testing.assert_array_equal(variant // P, np.broadcast_to(np.arange(3), variant.shape))
        seen |= set((variant % P).ravel().tolist())
    assert seen == set(range(P))
    nominal = np.asarray(jit_physics(env.reset)(jax.random.key(0), True).worlds[0].variant)
    np.testing.assert_array_equal(nominal % P, 0)


@pytest.mark.slow  # hopper++ about 100 s, humanoid++ about 160 s: both layouts' steps
@pytest.mark.parametrize("suite", ["hopper++", "humanoid++"])
def test_a_union_steps_a_suite_as_a_model_per_robot_does(suite):
    # The same keys, the same starts (each robot's reset noise over its own joints) and
    # the same actions: the same episodes up to float32 rounding, which contacts amplify.
    envs = [MultiEnv(suite, 2, EnvConfig(layout=layout)) for layout in ("union", "per_robot")]
    assert [len(env.worlds) for env in envs] == [1, len(envs[1].morphs)]
    steps = [jit_physics(env.step) for env in envs]
    states = [jit_physics(env.reset)(jax.random.key(0)) for env in envs]
    np.testing.assert_allclose(states[0].obs, states[1].obs, atol=1e-6)
    shape = (envs[0].num_morphs, 2, envs[0].n_max)
    for t in range(20):
        actions = jax.random.uniform(jax.random.key(100 + t), shape, minval=-1, maxval=1)
        (states[0], union), (states[1], own) = [
            step(state, actions) for step, state in zip(steps, states, strict=True)
        ]
        np.testing.assert_allclose(union.next_obs, own.next_obs, atol=1e-3, err_msg=str(t))
        np.testing.assert_allclose(union.reward, own.reward, atol=1e-2, err_msg=str(t))
        for name in ("terminated", "truncated", "valid"):
            np.testing.assert_array_equal(getattr(union, name), getattr(own, name))
