"""Robot variants in the batch: each environment's model is its variant's, as MuJoCo C
compiles the variant's MJCF, in one program for all of them.

The pool's fields are checked on the host for a hopper, a walker and a humanoid, and in
a world of two robots whose variants mix (the default suite); the physics against
MuJoCo C for 50 steps on the tests' Euler hopper, hopper_3, walker_7_main and
humanoid_2d_9_full, and the draws per episode, in the slow suite (each compiles its own
step).
"""

import dataclasses
import functools

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from solar_jax.config import EnvConfig
from solar_jax.env.batch import MultiEnv
from solar_jax.env.variants import make_pool, model_of
from solar_jax.env.world import build_world
from solar_jax.morphology import load
from solar_jax.morphology.variants import PROPERTIES, make_variants
from tests.env.oracle import reference_observation, reference_step
from tests.env.test_single import ONE_STEP_ATOL, OPEN_LOOP_ATOL
from tests.tiny import ROBOT as TINY_ROBOT
from tests.unoptimised import jit_physics

# Fields MuJoCo C derives or reads that the physics uses, compared per robot.
PER_BODY = ("body_mass", "body_inertia", "body_ipos", "body_iquat", "body_pos", "body_invweight0")
PER_OTHER = {
    "geom": ("geom_size", "geom_pos", "geom_rbound", "geom_aabb"),
    "jnt": ("jnt_range",),
    "dof": ("dof_armature", "dof_damping", "dof_invweight0"),
    "actuator": ("actuator_gear",),
}


def _c_model(morph) -> mujoco.MjModel:
    """MuJoCo C's model of a variant's MJCF text."""
    return mujoco.MjModel.from_xml_string(morph.xml)


def _robot_blocks(world, r: int) -> dict[str, np.ndarray]:
    """World indices of robot ``r``'s bodies, geoms, joints, dofs and motors, in the
    order of the robot's own model (its world body and floor left out)."""
    model = world.model
    bodies = world.body_ids[r, world.agent_mask[r]]
    geoms = np.flatnonzero(np.isin(model.geom_bodyid, bodies))
    joints = np.flatnonzero(np.isin(model.jnt_bodyid, bodies))
    return {
        "body": bodies,
        "geom": geoms,
        "jnt": joints,
        "dof": np.flatnonzero(world.dof_robot == r),
        "actuator": np.flatnonzero(world.ctrl_robot == r),
    }


def _own_blocks(model: mujoco.MjModel) -> dict[str, np.ndarray]:
    return {
        "body": np.arange(1, model.nbody),
        "geom": np.flatnonzero(model.geom_bodyid > 0),
        "jnt": np.arange(model.njnt),
        "dof": np.arange(model.nv),
        "actuator": np.arange(model.nu),
    }


def _check_robot(gathered: dict, world, r: int, c_model: mujoco.MjModel):
    """Robot ``r``'s fields of a gathered world model equal its C model's (float32)."""
    ours, theirs = _robot_blocks(world, r), _own_blocks(c_model)
    fields = {"body": PER_BODY, **PER_OTHER}
    for axis, names in fields.items():
        for name in names:
            got = np.asarray(gathered[name])[ours[axis]]
            want = getattr(c_model, name)[theirs[axis]].astype(np.float32)
            np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-7, err_msg=name)


def _gathered(env, w: int, variant) -> dict[str, np.ndarray]:
    """World ``w``'s model fields with its robots as ``variant`` ([R])."""
    mx = _NominalFields(env.worlds[w].model)
    return model_of(mx, env.pools[w], jnp.asarray(variant, jnp.int32)).fields


@dataclasses.dataclass
class _NominalFields:
    """A stand-in for the world's ``mjx.Model`` (model_of reads and replaces fields)."""

    model: mujoco.MjModel
    fields: dict = dataclasses.field(default_factory=dict)

    def replace(self, **replaced):
        names = {*PER_BODY, *(n for names in PER_OTHER.values() for n in names)}
        fields = {n: np.asarray(getattr(self.model, n), np.float32) for n in names}
        fields.update({n: np.asarray(v) for n, v in replaced.items()})
        return _NominalFields(self.model, fields)


@pytest.mark.parametrize("name", ["hopper_3", "walker_7_main", "humanoid_2d_9_full"])
def test_each_variant_in_the_pool_is_the_model_mujoco_c_compiles(name):
    morph = load(name)
    variants = make_variants(morph, PROPERTIES, 3, seed=5)
    env = MultiEnv([morph], 3, variants=[[v.morph for v in variants]])
    assert env.num_variants == 3 and env.pools[0].size == 3
    for p, variant in enumerate(variants):
        _check_robot(_gathered(env, 0, [p]), env.worlds[0], 0, _c_model(variant.morph))


def test_robots_of_one_world_take_their_own_variants():
    """Two walkers merged into one world, each as another variant."""
    morphs = (load("walker_7_main"), load("walker_4_main"))
    variants = [make_variants(m, PROPERTIES, 3, seed=6) for m in morphs]
    world = build_world(morphs, 7)
    worlds = [build_world(tuple(own[p].morph for own in variants), 7) for p in range(3)]
    pool = make_pool(world, worlds, False)
    for choice in ([0, 2], [2, 1], [1, 1]):
        mx = _NominalFields(world.model)
        gathered = model_of(mx, pool, jnp.asarray(choice, jnp.int32)).fields
        for r, p in enumerate(choice):
            _check_robot(gathered, world, r, _c_model(variants[r][p].morph))
        # The world body's total mass is the robots' together.
        total = sum(
            _c_model(variants[r][p].morph).body_subtreemass[0] for r, p in enumerate(choice)
        )
        assert gathered["body_subtreemass"][0] == pytest.approx(total, rel=1e-6)


def test_variants_that_change_the_structure_are_refused():
    hopper, walker = load("hopper_3"), load("walker_7_main")
    with pytest.raises(ValueError, match="every robot needs the same number"):
        MultiEnv([hopper, walker], 2, variants=[[hopper], [walker, walker]])
    with pytest.raises(ValueError, match="a variant of hopper_3 has other agents"):
        MultiEnv([hopper], 2, variants=[[walker]])
    nominal = build_world((hopper,), 3)
    longer = load("hopper_4")
    with pytest.raises(ValueError, match="variants change the robots' structure"):
        make_pool(nominal, [build_world((longer,), 4)], False)


def _no_end(morph):
    """``morph`` without termination: both simulators follow one trajectory."""
    return dataclasses.replace(morph, task=dataclasses.replace(morph.task, terminates=False))


@functools.cache
def _variant_env(name: str, count: int):
    morph = _no_end(load(name))
    variants = make_variants(morph, PROPERTIES, count, seed=9)
    morphs = [_no_end(v.morph) for v in variants]
    env = MultiEnv([morph], count, EnvConfig(max_episode_steps=1000), variants=[morphs])
    return env, morphs, jit_physics(env.reset), jit_physics(env.step)


def _follow_mujoco_c(name: str, count: int, steps: int = 50):
    """Each environment steps as MuJoCo C steps its variant: observations at reset, one
    step from MJX's own state (ONE_STEP_ATOL), open loop from the common start."""
    env, morphs, reset, step = _variant_env(name, count)
    config = env.config
    state = reset(jax.random.key(0))
    world = state.worlds[0]
    np.testing.assert_array_equal(np.asarray(world.variant)[:, 0], np.arange(count))
    models = []
    for b, morph in enumerate(morphs):
        model = _c_model(morph)
        model.opt.iterations, model.opt.ls_iterations = (
            config.solver_iterations,
            config.ls_iterations,
        )
        models.append(model)
        qpos, qvel = np.asarray(world.data.qpos[b], np.float64), np.asarray(world.data.qvel[b])
        # The observation's joint-range features are the variant's (compiled) ranges.
        np.testing.assert_allclose(
            np.asarray(state.obs[0, b, : morph.num_agents]),
            reference_observation(morph, qpos, qvel),
            atol=1e-4,
        )
    open_loop = [
        (np.asarray(world.data.qpos[b], np.float64), np.asarray(world.data.qvel[b], np.float64))
        for b in range(count)
    ]
    rng = np.random.default_rng(1)
    one_step, drift = [], []
    for t in range(steps):
        before = state.worlds[0].data
        actions = rng.uniform(-1, 1, (1, count, env.n_max))
        state, _ = step(state, jnp.asarray(actions, jnp.float32))
        after = state.worlds[0].data
        for b, morph in enumerate(morphs):
            action = actions[0, b, 1 : morph.num_agents]
            start = (np.asarray(before.qpos[b], np.float64), np.asarray(before.qvel[b], np.float64))
            c_qpos, *_ = reference_step(morph, *start, action, models[b])
            one_step.append(np.abs(np.asarray(after.qpos[b]) - c_qpos).max())
            qpos, qvel, *_ = reference_step(morph, *open_loop[b], action, models[b])
            open_loop[b] = (qpos, qvel)
            drift.append((t, np.abs(np.asarray(after.qpos[b]) - qpos).max()))
    assert max(one_step) < ONE_STEP_ATOL, f"one step: {max(one_step):.2e}"
    assert max(d for t, d in drift if t < 10) < 1e-4
    assert max(d for _, d in drift) < OPEN_LOOP_ATOL, f"open loop: {max(d for _, d in drift):.2e}"
    # The variants differ from each other: they are not all the nominal robot.
    final = np.asarray(state.worlds[0].data.qpos)
    assert np.abs(final[0] - final[1]).max() > 1e-3


@pytest.mark.slow  # each robot compiles its own step: 25 s for the tests' Euler hopper
def test_each_environment_steps_as_mujoco_c_steps_its_variant():
    _follow_mujoco_c(str(TINY_ROBOT), 2)


@pytest.mark.slow  # each robot compiles its own step (~40-60 s on 2 cores)
@pytest.mark.parametrize("name", ["hopper_3", "walker_7_main", "humanoid_2d_9_full"])
def test_reference_robots_step_as_mujoco_c_steps_their_variants(name):
    _follow_mujoco_c(name, 3)


@pytest.mark.slow  # its own env's programs (~25 s); the trainer's test checks the draws at reset
def test_redraw_picks_a_new_variant_per_episode():
    """Domain randomisation: each robot's episode starts as a variant drawn from the pool,
    from the state's key (the same keys, the same draws)."""
    morph = load(str(TINY_ROBOT))
    variants = [v.morph for v in make_variants(morph, ("gear", "armature"), 4, seed=2)]
    env = MultiEnv([morph], 3, EnvConfig(max_episode_steps=2), variants=[variants], redraw=True)
    reset, step = jit_physics(env.reset), jit_physics(env.step)
    zeros = jnp.zeros((1, 3, env.n_max))

    def episodes(key):
        state, seen = reset(key), []
        for _ in range(8):
            seen.append(np.asarray(state.worlds[0].variant)[:, 0])
            state, _ = step(state, zeros)
        return np.stack(seen)

    seen = episodes(jax.random.key(3))
    # Evaluations start every robot as its nominal self (the pool's first variant).
    nominal = jit_physics(lambda key: env.reset(key, nominal=True))(jax.random.key(3))
    np.testing.assert_array_equal(np.asarray(nominal.worlds[0].variant), 0)
    np.testing.assert_array_equal(seen, episodes(jax.random.key(3)))
    assert ((0 <= seen) & (seen < 4)).all()
    # Within an episode (2 steps) the variant holds; across episodes it is redrawn.
    np.testing.assert_array_equal(seen[0::2], seen[1::2])
    assert len(np.unique(seen)) == 4 and (seen[0::2][1:] != seen[0::2][:-1]).any()
