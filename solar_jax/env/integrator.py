"""One physics step of a world: MuJoCo's RK4 with its four forward passes in one loop.

``mjx.step`` on an RK4 model runs the forward dynamics once, then the three further
stages in a ``scan`` unrolled three times: four copies of the whole forward pass (the
constraint solver included) in every program that steps the world. ``rk4_step`` runs
the same four stages as one rolled loop over the Butcher tableau, one forward pass in
the program. Stage ``i`` starts from the step's initial state advanced by
``RK4_OFFSET[i] * dt`` times stage ``i - 1``'s velocity and acceleration (stage 0: the
state itself), at time ``t + RK4_OFFSET[i] * dt``; the step then advances the initial
state by the ``RK4_WEIGHT``-weighted sums of the stages' velocities and accelerations
(MuJoCo's ``mj_RungeKutta`` and ``mj_advance``), and the last stage's data is kept as
``mjx.step`` keeps it (its ``qacc`` is the next step's solver warm start).

The same arithmetic as ``mjx.step`` and MuJoCo C's RK4 step, up to float rounding (checked
against MuJoCo C: ``tests/env/test_integrator.py``), at about 40% less compile time
(docs/design.md).

Only models whose joints are hinges and slides and which have no activations qualify
(the planar robots: positions integrate as ``q + dt * v``); ``world_step`` keeps
``mjx.step`` for the others and for every other integrator.
"""

import contextlib
import io

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

with contextlib.redirect_stdout(io.StringIO()):  # without the optional warp package, mjx
    from mujoco import mjx  # prints two "Failed to import warp" lines on import

# Classic RK4 (MuJoCo's tableau for N = 4): stage i's offset from the initial state in
# units of dt times stage i - 1's derivatives (its time offset too), and the stages' weights.
RK4_OFFSET = np.array([0.0, 0.5, 0.5, 1.0], np.float32)
RK4_WEIGHT = np.array([1.0 / 6.0, 1.0 / 3.0, 1.0 / 3.0, 1.0 / 6.0], np.float32)

_PLANAR_JOINTS = {int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE)}


def rolls_rk4(model: mujoco.MjModel) -> bool:
    """Whether ``rk4_step`` steps ``model``: RK4, hinge and slide joints, no activations."""
    return (
        int(model.opt.integrator) == int(mujoco.mjtIntegrator.mjINT_RK4)
        and model.na == 0
        and {int(kind) for kind in model.jnt_type} <= _PLANAR_JOINTS
    )


def rk4_step(mx: mjx.Model, data: mjx.Data) -> mjx.Data:
    """One RK4 step of ``data`` (a model for which ``rolls_rk4`` holds)."""
    dt = mx.opt.timestep
    qpos0, qvel0, time0 = data.qpos, data.qvel, data.time

    def stage(carry, tableau):
        data, kqvel, kqacc, qvel_sum, qacc_sum = carry
        offset, weight = tableau
        data = data.replace(
            qpos=qpos0 + dt * (offset * kqvel),
            qvel=qvel0 + (offset * kqacc) * dt,
            time=time0 + offset * dt,
        )
        data = mjx.forward(mx, data)
        qvel_sum, qacc_sum = qvel_sum + weight * data.qvel, qacc_sum + weight * data.qacc
        return (data, data.qvel, data.qacc, qvel_sum, qacc_sum), None

    zeros = jnp.zeros_like(qvel0)
    carry = (data, zeros, zeros, zeros, zeros)
    (last, _, _, qvel_sum, qacc_sum), _ = jax.lax.scan(stage, carry, (RK4_OFFSET, RK4_WEIGHT))
    return last.replace(
        qpos=qpos0 + dt * qvel_sum,
        qvel=qvel0 + qacc_sum * dt,
        time=time0 + dt,
        qacc_warmstart=last.qacc,
    )


def world_step(model: mujoco.MjModel):
    """The physics step for ``model``: ``rk4_step`` where it qualifies, else ``mjx.step``."""
    return rk4_step if rolls_rk4(model) else mjx.step
