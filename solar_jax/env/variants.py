"""A world's robot variants as data: one compiled step for all of them.

Variants keep the kinematic tree (``morphology.variants``), so a world of variants is
the nominal world's ``mjx.Model`` with other numbers in some float fields. A
``VariantPool`` holds those fields for ``P`` variants, ``[P, ...]``; a state carries
each robot's variant index ``[R]`` and ``model_of`` gathers its model from the pool
inside the traced step, so one program steps any mix of variants, each robot of a
world its own (robots own disjoint blocks of bodies, joints, dofs, geoms and motors).

Which fields: every float field that differs between a variant's compiled world and
the nominal one, of those MJX's physics reads (``CARRIED``); a difference anywhere
else is an error, not a silently nominal value (``IGNORED``: fields MJX does not read).
"""

import dataclasses

import jax.numpy as jnp
import mujoco
import numpy as np

from solar_jax.env.observation import ObservationLayout
from solar_jax.env.world import World

# Field prefix -> the model axis its first dimension runs over.
_AXES = {"body_": "body", "jnt_": "jnt", "dof_": "dof", "geom_": "geom", "actuator_": "actuator"}
CARRIED = (
    "body_pos", "body_quat", "body_ipos", "body_iquat", "body_mass", "body_subtreemass",
    "body_inertia", "body_invweight0", "jnt_pos", "jnt_range", "dof_armature", "dof_damping",
    "dof_invweight0", "geom_size", "geom_pos", "geom_quat", "geom_aabb", "geom_rbound",
    "actuator_gear", "actuator_acc0",
)  # fmt: skip
# A union's robots (``env.union``) differ in more: whatever a robot's own model sets per
# element, qpos0 and the floor included. Every one is a traced field of mjx.Model.
UNION_CARRIED = CARRIED + (
    "qpos0", "qpos_spring", "body_gravcomp", "jnt_axis", "jnt_stiffness", "jnt_margin",
    "jnt_solref", "jnt_solimp", "jnt_actfrcrange", "dof_frictionloss", "dof_solref",
    "dof_solimp", "geom_margin", "geom_gap", "geom_friction", "geom_solref", "geom_solimp",
    "geom_solmix", "actuator_ctrlrange", "actuator_forcerange", "actuator_gainprm",
    "actuator_biasprm", "actuator_dynprm", "actuator_lengthrange",
)  # fmt: skip
# Compiled quantities MJX's step never reads: cameras and lights (for drawing), MuJoCo
# C's bounding-volume tree and bodies' largest geom margin (its broad phase), its inertia
# diagonal and dof lengths at qpos0, and its shortcut flags (a frame that coincides with
# its body's, a body or dof that is simple): a longer limb's inertial frame leaves its
# body origin.
IGNORED = ("cam_", "light_", "bvh_", "dof_M0", "dof_length", "body_sameframe", "geom_sameframe")
IGNORED += ("site_sameframe", "body_simple", "dof_simplenum", "body_margin")  # prefixes


@dataclasses.dataclass(frozen=True, eq=False)
class VariantPool:
    """``P`` variants of one world: the fields that vary and each entry's robot.

    NumPy, host side; ``model_of`` and ``ranges_of`` read them inside traced code."""

    size: int  # P
    fields: dict[str, np.ndarray]  # mjx.Model field -> [P, n, ...] float32
    owners: dict[str, np.ndarray]  # field -> [n] int32 robot owning each entry
    roots: np.ndarray  # body ids of the robots' torsos (the world body's children)
    # The observation's joint ranges (``ranges_of``); None: a union's robots' tables
    # carry them (``env.union``).
    range_lo: np.ndarray | None = None  # [P, R, N] degrees, as ObservationLayout's
    range_width: np.ndarray | None = None  # [P, R, N]
    range_features: np.ndarray | None = None  # [P, R, N, 2]


def _owners(world: World) -> dict[str, np.ndarray]:
    """Robot of each body, joint, dof, geom and motor of ``world`` (-1: the world's)."""
    model = world.model
    body = np.full(model.nbody, -1, np.int32)
    for r in range(world.num_robots):
        body[world.body_ids[r, world.agent_mask[r]]] = r
    return {
        "body": body,
        "jnt": body[model.jnt_bodyid],
        "dof": world.dof_robot.astype(np.int32),
        "geom": body[model.geom_bodyid],
        "actuator": world.ctrl_robot.astype(np.int32),
    }


def _float_fields(model: mujoco.MjModel) -> dict[str, np.ndarray]:
    return {
        name: value
        for name in dir(model)
        if not name.startswith("_")
        and isinstance(value := getattr(model, name), np.ndarray)
        and np.issubdtype(value.dtype, np.floating)
    }


def _varying(
    nominal: mujoco.MjModel, models: list[mujoco.MjModel], carried: tuple[str, ...]
) -> dict[str, np.ndarray]:
    """``[P, ...]`` float32 of each float field in which ``models`` (of ``nominal``'s
    structure) differ from ``nominal``: each one of ``carried``, else an error."""
    for name in dir(nominal):
        value = getattr(nominal, name)
        if name.startswith(IGNORED):
            continue
        if isinstance(value, np.ndarray) and not np.issubdtype(value.dtype, np.floating):
            if any(not np.array_equal(getattr(m, name), value) for m in models):
                raise ValueError(f"variants change the robots' structure ({name})")
    base = _float_fields(nominal)
    fields = [_float_fields(m) for m in models]
    varying = {}
    for name, value in base.items():
        differs = any(
            f[name].shape != value.shape or not np.array_equal(f[name], value) for f in fields
        )
        if not differs or name.startswith(IGNORED):
            continue
        if name not in carried:
            raise ValueError(f"variants differ in {name}, which a variant pool does not carry")
        varying[name] = np.stack([f[name] for f in fields]).astype(np.float32)
    return varying


def model_pool(nominal: mujoco.MjModel, models: list[mujoco.MjModel]) -> VariantPool:
    """The pool of ``models``, each a whole one-robot world of ``nominal``'s structure (a
    union's robots, ``env.union``): every field of ``UNION_CARRIED`` may differ, the
    floor's too. The observation's ranges come with the robots' tables, not from here."""
    fields = _varying(nominal, models, UNION_CARRIED)
    return VariantPool(
        size=len(models),
        fields=fields,
        owners={name: np.zeros(value.shape[1], np.int32) for name, value in fields.items()},
        roots=np.array([1]),
    )


def make_pool(nominal: World, variants: list[World], fix_limb_types: bool) -> VariantPool:
    """The pool of ``variants`` (worlds of the same robots as ``nominal``, each robot a
    variant of its nominal self)."""
    varying = _varying(nominal.model, [v.model for v in variants], CARRIED)
    owners_by_axis = _owners(nominal)
    fields, owners = {}, {}
    for name, stacked in varying.items():
        owner = owners_by_axis[next(a for p, a in _AXES.items() if name.startswith(p))]
        shared = owner < 0  # the world's own entries must not vary, but for its total mass
        if name != "body_subtreemass" and (stacked[:, shared] != stacked[:1, shared]).any():
            raise ValueError(f"variants differ in {name} of the world, not of a robot")
        fields[name], owners[name] = stacked, np.maximum(owner, 0)
    layouts = [ObservationLayout.of(v, fix_limb_types) for v in variants]
    return VariantPool(
        size=len(variants),
        fields=fields,
        owners=owners,
        roots=np.flatnonzero(nominal.model.body_parentid == 0)[1:],
        range_lo=np.stack([layout.range_lo for layout in layouts]),
        range_width=np.stack([layout.range_width for layout in layouts]),
        range_features=np.stack([layout.range_features for layout in layouts]),
    )


def model_of(mx, pool: VariantPool, variant: jnp.ndarray):
    """``mx`` (the nominal world's ``mjx.Model``) with robot ``r``'s fields those of its
    variant ``variant[r]`` (``[R]`` int32, traced)."""
    replaced = {}
    for name, values in pool.fields.items():
        owner = pool.owners[name]
        replaced[name] = jnp.asarray(values)[variant[owner], np.arange(len(owner))]
    if "body_subtreemass" in replaced:  # the world body's: the robots' total
        subtree = replaced["body_subtreemass"]
        replaced["body_subtreemass"] = subtree.at[0].set(jnp.sum(subtree[pool.roots]))
    return mx.replace(**replaced)


def ranges_of(pool: VariantPool, variant: jnp.ndarray) -> tuple[jnp.ndarray, ...]:
    """The observation's joint-range arrays ``[R, N]``, ``[R, N]``, ``[R, N, 2]`` of each
    robot's variant."""
    robots = np.arange(len(pool.roots))
    return (
        jnp.asarray(pool.range_lo)[variant, robots],
        jnp.asarray(pool.range_width)[variant, robots],
        jnp.asarray(pool.range_features)[variant, robots],
    )
