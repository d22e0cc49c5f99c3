"""Observations equal the NumPy/MuJoCo-C oracle of algorithm.md §2 on the same states."""

import functools

import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from solar_jax.config import EnvConfig
from solar_jax.env.observation import quat_to_expmap
from solar_jax.env.physics import make_world_fns
from solar_jax.env.world import build_world
from solar_jax.morphology import load
from tests.env.oracle import reference_observation
from tests.unoptimised import jit_physics

# float32 kinematics against float64 MuJoCo C (measured max error: see test body).
ATOL = 2e-5
FAMILIES = (("walker_7_main", "hopper_5", "humanoid_2d_9_full"), ("cheetah_7_full",))


def test_quat_to_expmap_matches_rotation_vectors():
    quats = Rotation.random(500, random_state=0).as_quat()  # (x, y, z, w), w of both signs
    quats[::2] *= -1  # the same rotations with the opposite sign
    wxyz = np.concatenate([quats[:, 3:], quats[:, :3]], axis=1)
    ours = np.asarray(quat_to_expmap(jnp.asarray(wxyz, jnp.float32)))
    np.testing.assert_allclose(ours, Rotation.from_quat(quats).as_rotvec(), atol=1e-5)
    assert np.linalg.norm(ours, axis=1).max() <= np.pi + 1e-6
    np.testing.assert_array_equal(quat_to_expmap(jnp.array([1.0, 0, 0, 0])), 0.0)


def _states(morph, rng, count):
    """Reachable states (C simulation under random actions) and extreme ones."""
    model = morph.model
    data = mujoco.MjData(model)
    data.qpos[:] = model.qpos0 + rng.uniform(-0.1, 0.1, model.nq)
    states = []
    for k in range(count):
        for _ in range(4 * (k + 1)):
            data.ctrl[:] = rng.uniform(-1, 1, model.nu)
            mujoco.mj_step(model, data)
        states.append((data.qpos.copy(), data.qvel.copy()))
    qpos = model.qpos0.copy()
    qpos[2] = 3.0  # torso pitched beyond pi/2: limbs cross the +-pi fold of the exp map
    qpos[3:] = rng.uniform(model.jnt_range[3:, 0], model.jnt_range[3:, 1])
    states.append((qpos, rng.normal(0, 20, model.nv)))  # velocities beyond the +-10 clip
    return states


@functools.cache
def _observer(names, fix):
    morphs = tuple(load(n) for n in names)
    world = build_world(morphs, max(m.num_agents for m in morphs))
    return (
        morphs,
        world,
        jit_physics(make_world_fns(world, EnvConfig(fix_humanoid_limb_types=fix)).observe_state),
    )


@pytest.mark.parametrize("names", FAMILIES, ids=lambda n: "+".join(n))
@pytest.mark.parametrize("fix", [False, True], ids=["reference_limb_types", "fixed_limb_types"])
def test_observation_equals_numpy_reference(names, fix):
    morphs, world, observe_state = _observer(names, fix)
    rng = np.random.default_rng(0)
    per_robot = [_states(m, rng, 4) for m in morphs]
    worst = 0.0
    for k in range(len(per_robot[0])):
        qpos = np.concatenate([s[k][0] for s in per_robot])
        qvel = np.concatenate([s[k][1] for s in per_robot])
        obs = np.asarray(
            observe_state(jnp.asarray(qpos, jnp.float32), jnp.asarray(qvel, jnp.float32))
        )
        for r, (m, states) in enumerate(zip(morphs, per_robot, strict=True)):
            expected = reference_observation(m, *states[k], fix_limb_types=fix)
            n = m.num_agents
            worst = max(worst, float(np.abs(obs[r, :n] - expected).max()))
            np.testing.assert_allclose(obs[r, :n], expected, atol=ATOL, rtol=1e-5)
            np.testing.assert_array_equal(obs[r, n:], 0.0)  # padding stays zero
    assert worst > 0.0  # float32 against float64: a zero would mean a vacuous comparison


def test_humanoid_limb_types_are_zero_in_reference_mode():
    morphs, world, observe_state = _observer(FAMILIES[0], False)
    obs = np.asarray(observe_state(jnp.asarray(world.model.qpos0), jnp.zeros(world.model.nv)))
    humanoid = [m.name for m in morphs].index("humanoid_2d_9_full")
    np.testing.assert_array_equal(obs[humanoid, :, 12:16], 0.0)
    walker = [m.name for m in morphs].index("walker_7_main")
    np.testing.assert_array_equal(obs[walker, :7, 12:16].argmax(-1), [0, 1, 2, 3, 1, 2, 3])


def test_world_keeps_a_user_robots_options(tmp_path):
    from solar_jax.env.world import build_world, physics_key
    from tests.morphology.test_morphology import HINGE, MINIMAL, MOTOR, ROOT

    xml = MINIMAL.format(root=ROOT, leg_joints=HINGE, motors=MOTOR).replace(
        "<mujoco>", '<mujoco><option cone="elliptic" impratio="3" timestep="0.004"/>'
    )
    (tmp_path / "robot.xml").write_text(xml)
    morph = load(tmp_path / "robot.xml")
    world = build_world((morph,), 2)
    for name in ("cone", "impratio", "timestep", "integrator", "jacobian", "tolerance"):
        np.testing.assert_array_equal(
            getattr(world.model.opt, name), getattr(morph.model.opt, name)
        )
    np.testing.assert_array_equal(world.model.jnt_range, morph.model.jnt_range)  # degrees kept
    assert physics_key(morph) != physics_key(load("walker_2_main"))
    assert physics_key(load("walker_2_main")) == physics_key(load("hopper_3"))
