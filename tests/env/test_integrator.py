"""RK4's stages in one loop (``solar_jax.env.integrator``) against ``mjx.step``'s."""

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


def test_rolled_rk4_steps_as_mjx_up_to_float_rounding():
    model = _rk4_hopper()
    mx = mjx.put_model(model)
    rng = np.random.default_rng(0)
    landing = mujoco.MjData(model)  # dropped (in MuJoCo C) until its foot touches the floor,
    while landing.ncon == 0 and landing.time < 2.0:  # so that the constraint solver runs
        mujoco.mj_step(model, landing)  # from the first stage
    assert landing.ncon > 0
    start = mjx.make_data(mx).replace(
        qpos=jnp.asarray(landing.qpos + rng.uniform(-0.05, 0.05, model.nq), jnp.float32),
        qvel=jnp.asarray(landing.qvel + rng.uniform(-0.5, 0.5, model.nv), jnp.float32),
    )
    controls = jnp.asarray(rng.uniform(-1, 1, (STEPS, model.nu)), jnp.float32)

    def rollout(step):
        def body(data, ctrl):
            data = step(mx, data.replace(ctrl=ctrl))
            return data, (data.qpos, data.qvel, data.qacc_warmstart, data.time)

        return jit_physics(lambda data: jax.lax.scan(body, data, controls)[1])(start)

    ours, mjx_s = rollout(rk4_step), rollout(mjx.step)
    for name, a, b in zip(("qpos", "qvel", "qacc_warmstart", "time"), ours, mjx_s, strict=True):
        assert np.isfinite(a).all(), name
        np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-4, err_msg=name)
    # Not the same numbers by accident of a no-op: the state moved.
    assert np.abs(np.asarray(ours[1][-1]) - np.asarray(start.qvel)).max() > 1e-3
