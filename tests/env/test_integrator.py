"""RK4's stages in one loop (``solar_jax.env.integrator``) against MuJoCo C's RK4 step."""

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from solar_jax.env.integrator import mjx, rk4_step, rolls_rk4, world_step
from tests.tiny import ROBOT as TINY_ROBOT
from tests.unoptimised import jit_physics

STEPS = 8  # physics steps from a landing: the foot in contact from the first


def _rk4_hopper() -> mujoco.MjModel:
    """The tests' Euler hopper (3 hinges on a planar root) switched to RK4."""
    model = mujoco.MjModel.from_xml_path(str(TINY_ROBOT))
    model.opt.integrator = mujoco.mjtIntegrator.mjINT_RK4
    return model


def test_which_models_the_rolled_loop_steps():
    model = _rk4_hopper()
    assert rolls_rk4(model) and world_step(model) is rk4_step
    euler = mujoco.MjModel.from_xml_path(str(TINY_ROBOT))
    assert not rolls_rk4(euler) and world_step(euler) is mjx.step
    free = mujoco.MjModel.from_xml_string(
        "<mujoco><option integrator='RK4'/><worldbody><body><freejoint/>"
        "<geom size='0.1'/></body></worldbody></mujoco>"
    )
    assert not rolls_rk4(free) and world_step(free) is mjx.step  # quaternions: MJX's own


def test_rolled_rk4_steps_as_mujoco_c_up_to_float_rounding():
    # The oracle is MuJoCo C's RK4 (float64), not ``mjx.step`` (its four unrolled stages
    # took 2.7x our step's compile time): 8 steps agree to 2e-6 in qvel, and a 0.2%
    # change of one RK4 weight moves them by 6e-4.
    model = _rk4_hopper()
    mx = mjx.put_model(model)
    rng = np.random.default_rng(0)
    c = mujoco.MjData(model)  # dropped until its foot touches the floor, so that the
    while c.ncon == 0 and c.time < 2.0:  # constraint solver runs from the first stage
        mujoco.mj_step(model, c)
    assert c.ncon > 0
    qpos = (c.qpos + rng.uniform(-0.05, 0.05, model.nq)).astype(np.float32)
    qvel = (c.qvel + rng.uniform(-0.5, 0.5, model.nv)).astype(np.float32)
    controls = rng.uniform(-1, 1, (STEPS, model.nu)).astype(np.float32)
    start = mjx.make_data(mx).replace(qpos=jnp.asarray(qpos), qvel=jnp.asarray(qvel))

    def body(data, ctrl):
        data = rk4_step(mx, data.replace(ctrl=ctrl))
        return data, (data.qpos, data.qvel, data.qacc_warmstart, data.time)

    ours = jit_physics(lambda data: jax.lax.scan(body, data, jnp.asarray(controls))[1])(start)
    c.qpos[:], c.qvel[:], c.time = qpos, qvel, 0.0
    expected = []
    for ctrl in controls:
        c.ctrl[:] = ctrl
        mujoco.mj_step(model, c)
        expected.append((c.qpos.copy(), c.qvel.copy(), c.qacc_warmstart.copy(), c.time))
    expected = [np.array(field) for field in zip(*expected, strict=True)]
    for name, a, b in zip(("qpos", "qvel", "qacc_warmstart", "time"), ours, expected, strict=True):
        assert np.isfinite(a).all(), name
        scale = max(1.0, np.abs(b).max())  # accelerations reach ~300: float32's rounding
        np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-4 * scale, err_msg=name)
    # Not the same numbers by accident of a no-op: the state moved.
    assert np.abs(np.asarray(ours[1][-1]) - qvel).max() > 1e-3
