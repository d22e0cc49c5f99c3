"""A plain NumPy implementation of algorithm.md §2, computed with MuJoCo C (test oracle).

Written independently of solar_jax.env: velocities from ``mj_objectVelocity``, the
exponential map from scipy's rotation vector, joint ranges from the compiled model.
"""

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation


def reference_observation(morph, qpos, qvel, fix_limb_types=False) -> np.ndarray:
    """``[N, 19]`` float64 observation of one robot at (qpos, qvel)."""
    model = morph.model
    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:] = qpos, qvel
    mujoco.mj_forward(model, data)
    types = morph.limb_types if fix_limb_types else morph.reference_limb_types
    rows = []
    for i in range(morph.num_agents):
        body = i + 1
        pos = data.xpos[body].copy()
        pos[0] -= data.xpos[1, 0]
        # (angular, linear) at the body frame's origin, world frame: XBODY, not BODY
        # (BODY is the centre of mass); the reference used a Jacobian at xpos.
        velocity = np.zeros(6)
        mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_XBODY, body, velocity, 0)
        w, x, y, z = data.xquat[body]
        expmap = Rotation.from_quat([x, y, z, w]).as_rotvec()  # angle in [0, pi]
        onehot = np.zeros(4)
        if types[i] >= 0:
            onehot[types[i]] = 1.0
        if i == 0:
            angle, ranges = 0.0, np.zeros(2)
        else:
            joint = model.body_jntadr[body]
            lo, hi = np.rad2deg(model.jnt_range[joint])
            angle = (np.rad2deg(data.qpos[model.jnt_qposadr[joint]]) - lo) / (hi - lo)
            ranges = (180.0 + np.array([lo, hi])) / 360.0
        rows.append(
            np.concatenate(
                [pos, np.clip(velocity[3:], -10, 10), velocity[:3], expmap, onehot, [angle], ranges]
            )
        )
    return np.stack(rows)


def reference_step(morph, qpos, qvel, action, model=None):
    """One env step in MuJoCo C: (qpos', qvel', reward, terminated) per algorithm.md §2."""
    model = model or morph.model
    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:] = qpos, qvel
    data.ctrl[morph.actuators[1:]] = np.clip(action, -1, 1)
    x_before = data.qpos[0]
    for _ in range(morph.task.frame_skip):
        mujoco.mj_step(model, data)
    task = morph.task
    dt = model.opt.timestep * task.frame_skip
    a = np.clip(action, -1, 1)
    reward = (data.qpos[0] - x_before) / dt + task.alive_bonus - task.ctrl_cost * np.sum(a**2)
    z, pitch = data.qpos[1], data.qpos[2]
    healthy = np.isfinite(data.qpos).all() and np.isfinite(data.qvel).all()
    if task.z_range is not None:
        healthy &= task.z_range[0] < z < task.z_range[1]
    if task.max_abs_pitch is not None:
        healthy &= abs(pitch) < task.max_abs_pitch
    if task.max_abs_state is not None:
        state = np.concatenate([data.qpos[2:], data.qvel])
        healthy &= bool((np.abs(state) < task.max_abs_state).all())
    return data.qpos.copy(), data.qvel.copy(), reward, task.terminates and not healthy
