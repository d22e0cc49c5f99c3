"""The 19-value per-agent observation of algorithm.md §2, in JAX.

Per agent, torso first, agents in pre-order:
  [0:3]   body-origin position, x relative to the torso's x
  [3:6]   body-origin linear velocity, world frame, clipped to +-10
  [6:9]   angular velocity, world frame
  [9:12]  orientation as an exponential map
  [12:16] limb-type one-hot (all zeros for 2-D humanoids by default: algorithm.md §2)
  [16]    joint angle normalised to its range, (deg(q) - lo) / (hi - lo)
  [17:19] joint range, ((180 + lo) / 360, (180 + hi) / 360)
The torso's angle and range are 0; padded agents are all zeros.

Kinematics are taken at the current state. The reference (mujoco-py) read them after
``mj_step``, when MuJoCo's body poses still belong to the start of the last physics
substep (0.002 s earlier); only the joint angle used the current qpos.
"""

import jax.numpy as jnp
import numpy as np
from flax import struct

from solar_jax.env.world import OBS_SIZE, World

_EPS = float(np.finfo(np.float32).eps)


def quat_to_expmap(quat: jnp.ndarray) -> jnp.ndarray:
    """``[..., 4]`` (w, x, y, z) -> ``[..., 3]`` rotation vector with angle in [0, pi].

    As the reference: theta = 2 atan2(|v|, w); a rotation beyond pi is folded back
    with the axis flipped; the axis is v / (|v| + eps), so identity maps to 0.
    """
    v, w = quat[..., 1:], quat[..., :1]
    sin_half = jnp.linalg.norm(v, axis=-1, keepdims=True)
    axis = v / (sin_half + _EPS)
    theta = jnp.mod(2.0 * jnp.arctan2(sin_half, w) + 2.0 * jnp.pi, 2.0 * jnp.pi)
    folded = theta > jnp.pi
    return jnp.where(folded, -axis, axis) * jnp.where(folded, 2.0 * jnp.pi - theta, theta)


@struct.dataclass
class ObservationLayout:
    """Per-agent features of one world, ``[R, n_max, ...]``: NumPy, or a union's robot's
    gathered inside the step (``env.union``)."""

    body_ids: np.ndarray  # [R, N]
    torso_ids: np.ndarray  # [R]
    mask: np.ndarray  # [R, N] bool
    qpos_adr: np.ndarray  # [R, N]
    range_lo: np.ndarray  # [R, N] degrees (torso 0)
    range_width: np.ndarray  # [R, N] degrees (torso 1, to avoid 0/0)
    limb_onehot: np.ndarray  # [R, N, 4]
    range_features: np.ndarray  # [R, N, 2]

    @classmethod
    def of(cls, world: World, fix_limb_types: bool) -> "ObservationLayout":
        num, n = world.body_ids.shape
        lo = np.zeros((num, n))
        width = np.ones((num, n))
        onehot = np.zeros((num, n, 4), np.float32)
        features = np.zeros((num, n, 2), np.float32)
        for r, m in enumerate(world.morphs):
            k = m.num_agents
            lo[r, 1:k] = m.joint_range[1:, 0]
            width[r, 1:k] = m.joint_range[1:, 1] - m.joint_range[1:, 0]
            features[r, 1:k] = (180.0 + m.joint_range[1:]) / 360.0
            types = m.limb_types if fix_limb_types else m.reference_limb_types
            for i, t in enumerate(types):
                if t >= 0:
                    onehot[r, i, t] = 1.0
        return cls(
            body_ids=world.body_ids,
            torso_ids=world.body_ids[:, 0],
            mask=world.agent_mask,
            qpos_adr=world.qpos_adr,
            range_lo=lo.astype(np.float32),
            range_width=width.astype(np.float32),
            limb_onehot=onehot,
            range_features=features,
        )


def observe(
    layout: ObservationLayout,
    qpos: jnp.ndarray,
    xpos: jnp.ndarray,
    xquat: jnp.ndarray,
    cvel: jnp.ndarray,
    subtree_com: jnp.ndarray,
    ranges: tuple[jnp.ndarray, ...] | None = None,
) -> jnp.ndarray:
    """Observations ``[R, n_max, 19]`` from one world's kinematics at the current state.

    ``cvel`` is MuJoCo's com-based spatial velocity (angular, linear) at the subtree
    centre of mass of each body's root; every robot's root is its torso. ``ranges``: the
    joint ranges' ``(range_lo, range_width, range_features)`` in place of the layout's,
    for robot variants (``env.variants.ranges_of``).
    """
    ids = layout.body_ids
    pos = xpos[ids]  # [R, N, 3]
    pos = pos.at[..., 0].add(-xpos[layout.torso_ids, 0][:, None])
    ang, lin_com = cvel[ids, :3], cvel[ids, 3:]
    # Shift the linear velocity from the robot's centre of mass to each body origin.
    offset = xpos[ids] - subtree_com[layout.torso_ids][:, None, :]
    lin = jnp.clip(lin_com + jnp.cross(ang, offset), -10.0, 10.0)
    range_lo, range_width, range_features = ranges or (
        layout.range_lo,
        layout.range_width,
        layout.range_features,
    )
    angle = (jnp.rad2deg(qpos[layout.qpos_adr]) - range_lo) / range_width
    angle = jnp.where(jnp.arange(ids.shape[1]) == 0, 0.0, angle)
    obs = jnp.concatenate(
        [
            pos,
            lin,
            ang,
            quat_to_expmap(xquat[ids]),
            jnp.asarray(layout.limb_onehot),
            angle[..., None],
            jnp.asarray(range_features),
        ],
        axis=-1,
    )
    assert obs.shape[-1] == OBS_SIZE
    return jnp.where(layout.mask[..., None], obs, 0.0)
