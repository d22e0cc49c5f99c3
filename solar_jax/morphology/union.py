"""Unions: one MuJoCo model of which several robots are variants.

MJX traces a model's structure (its body tree; joint, geom and actuator types; which
geoms may collide) and takes its float fields as data. A union is a body tree into
which robots embed by shape: each robot's torso is the union's torso and each of its
bodies maps to a child of its parent's image, in order (ordered tree inclusion), with
joints of the same types and geoms of the same types and collision bits. So a robot's
bodies, joints, dofs, qpos and geoms are a subsequence of the union's in MuJoCo's
pre-order, and the union's other bodies hang below mapped ones as whole subtrees:
dummies. The tree is the largest robot's, grown where another needs more
(``build_union(grow=True)``); each family of robots (the same collision bits) then
keeps a bit of its own, so that geoms of two families never pair.

``robot_model(union, k)`` is the union's ``MjModel`` carrying robot ``k``'s own compiled
numbers on its mapped elements, and dummies that change nothing: mass and inertia 0 (a
massless body moves nothing), armature on their hinges (so the mass matrix stays
regular), gear 0, and a contact margin so negative that no contact with them is ever
active (MJX adds two geoms' margins; MuJoCo C's contacts with a dummy push nothing).
MuJoCo C then steps the robot's dofs as its own model does to rounding, bit for bit
for RK4 robots of an ungrown union where no dummy sits between their dofs
(tests/morphology/test_union.py). MuJoCo's compiler refuses jointed bodies below 1e-15
kg, so the zeros are written after compiling.
"""

import copy
import dataclasses

import mujoco
import numpy as np

from solar_jax.morphology.morphology import Morphology, drop_textures, options_key, physics_key

# Per-element fields whose values must agree between a robot's element and its image:
# MJX reads them as structure (the traced program), or they decide which contact pairs
# exist (contype, conaffinity, condim, priority).
_GEOM_STATIC = ("geom_type", "geom_contype", "geom_conaffinity", "geom_condim", "geom_priority")
_JOINT_STATIC = ("jnt_type", "jnt_limited", "jnt_actfrclimited")
_MOTOR_STATIC = (
    "actuator_trntype", "actuator_dyntype", "actuator_gaintype", "actuator_biastype",
    "actuator_ctrllimited", "actuator_forcelimited", "actuator_actlimited", "actuator_actadr",
    "actuator_actnum",
)  # fmt: skip

# Model fields indexed by element, by prefix, and the size they run over.
_AXES = {
    "body_": "nbody", "jnt_": "njnt", "dof_": "nv", "geom_": "ngeom", "actuator_": "nu",
    "qpos": "nq",
}  # fmt: skip
# Element flags MuJoCo C uses as shortcuts (a frame equal to its body's, a simple body
# or dof): copied from the robot for its elements, so that C takes the robot's own paths.
_SHORTCUTS = ("body_sameframe", "body_simple", "dof_simplenum", "geom_sameframe")

DUMMY_ARMATURE = 1e-6
"""A dummy hinge's armature: its whole mass matrix entry (MJX's solver stops on
improvement over trace(M), so it stays small)."""
DUMMY_MARGIN = -1e4
"""A dummy geom's contact margin: its contacts are active only beyond 1e4 m of
penetration, never."""
DUMMY_RANGE = 1e4
"""A dummy hinge's limits (radians), never reached: its limit constraint stays inactive."""


@dataclasses.dataclass(frozen=True, eq=False)
class Embedding:
    """Where a robot's elements sit in the union: ``[n]`` union indices of its ``n``
    bodies (the world body included), joints, dofs, qpos entries, geoms and motors,
    each increasing (the robot's order is kept)."""

    body: np.ndarray
    jnt: np.ndarray
    dof: np.ndarray
    qpos: np.ndarray
    geom: np.ndarray
    actuator: np.ndarray

    def of(self, axis: str) -> np.ndarray:
        return {
            "nbody": self.body,
            "njnt": self.jnt,
            "nv": self.dof,
            "nq": self.qpos,
            "ngeom": self.geom,
            "nu": self.actuator,
        }[axis]


@dataclasses.dataclass(frozen=True, eq=False)
class Union:
    """Robots as variants of one model: ``model`` is the union's tree (its numbers a
    placeholder: its first robot's), ``embeddings[k]`` robot ``k``'s place in it."""

    model: mujoco.MjModel
    robots: tuple[Morphology, ...]
    embeddings: tuple[Embedding, ...]

    @property
    def body_ratio(self) -> np.ndarray:
        """``[K]`` per robot: the union's bodies per body of the robot (1: none extra)."""
        return np.array([(self.model.nbody - 1) / (r.model.nbody - 1) for r in self.robots])


def _children(model: mujoco.MjModel) -> list[list[int]]:
    children = [[] for _ in range(model.nbody)]
    for b in range(1, model.nbody):
        children[model.body_parentid[b]].append(b)
    return children


def _signature(model: mujoco.MjModel, fields: tuple[str, ...], i: int) -> tuple:
    return tuple(np.ravel(getattr(model, f)[i]).tolist() for f in fields)


def _joints(model: mujoco.MjModel, body: int) -> list[int]:
    start = model.body_jntadr[body]
    return list(range(start, start + model.body_jntnum[body])) if start >= 0 else []


def _geoms(model: mujoco.MjModel, body: int) -> list[int]:
    start = model.body_geomadr[body]
    return list(range(start, start + model.body_geomnum[body])) if start >= 0 else []


def _motors(model: mujoco.MjModel) -> dict[int, list[int]]:
    """Joint -> the motors driving it."""
    motors: dict[int, list[int]] = {}
    for a in range(model.nu):
        if model.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT:
            motors.setdefault(int(model.actuator_trnid[a, 0]), []).append(a)
    return motors


def _subsequence(small: list, large: list) -> list[int] | None:
    """Indices into ``large`` of an order-keeping match of ``small`` (leftmost), or None."""
    out, j = [], 0
    for item in small:
        while j < len(large) and large[j] != item:
            j += 1
        if j == len(large):
            return None
        out.append(j)
        j += 1
    return out


class _Embedder:
    """Ordered tree inclusion of ``robot``'s bodies into ``union``'s, with element checks."""

    def __init__(self, robot: mujoco.MjModel, union: mujoco.MjModel):
        self.robot, self.union = robot, union
        self.r_children, self.u_children = _children(robot), _children(union)
        self.r_motors, self.u_motors = _motors(robot), _motors(union)

    def _joint_sig(self, model, motors, j: int) -> tuple:
        sig = _signature(model, _JOINT_STATIC, j)
        return sig, tuple(_signature(model, _MOTOR_STATIC, a) for a in motors.get(j, []))

    def joints_fit(self, rb: int, ub: int) -> bool:
        """Robot body ``rb``'s joints and motors are union body ``ub``'s kinds, in order."""
        r, u = self.robot, self.union
        r_joints = [self._joint_sig(r, self.r_motors, j) for j in _joints(r, rb)]
        u_joints = [self._joint_sig(u, self.u_motors, j) for j in _joints(u, ub)]
        return r_joints == u_joints

    def _fits(self, rb: int, ub: int) -> bool:
        if not self.joints_fit(rb, ub):
            return False
        r, u = self.robot, self.union
        r_geoms = [_signature(r, _GEOM_STATIC, g) for g in _geoms(r, rb)]
        u_geoms = [_signature(u, _GEOM_STATIC, g) for g in _geoms(u, ub)]
        return _subsequence(r_geoms, u_geoms) is not None

    def body_map(self, rb: int = 0, ub: int = 0, by_name: bool = True) -> dict[int, int] | None:
        """Robot body -> union body for the subtree of ``rb`` placed at ``ub``: each child,
        in order, at the first later child of ``ub`` that holds its subtree (leftmost
        matching is optimal for ordered inclusion); ``by_name``: one of the same name
        first, where there is one."""
        if not self._fits(rb, ub):
            return None
        mapping, start = {rb: ub}, 0
        slots = self.u_children[ub]
        for rc in self.r_children[rb]:
            later = range(start, len(slots))
            name = self.robot.body(rc).name
            order = [i for i in later if by_name and self.union.body(slots[i]).name == name]
            order += [i for i in later if i not in order]
            for i in order:
                sub = self.body_map(rc, slots[i], by_name)
                if sub is not None:
                    break
            else:
                return None
            mapping.update(sub)
            # Later children go after the one taken, so that the pre-order is kept.
            start = i + 1
        return mapping

    def embedding(self) -> Embedding | None:
        bodies = self.body_map() or self.body_map(by_name=False)
        if bodies is None:
            return None
        body = np.array([bodies[b] for b in range(self.robot.nbody)], np.int32)
        r, u = self.robot, self.union
        jnt, geom = [], []
        for rb, ub in enumerate(body):
            jnt += _joints(u, ub)[: len(_joints(r, rb))]
            r_geoms = [_signature(r, _GEOM_STATIC, g) for g in _geoms(r, rb)]
            u_geoms = _geoms(u, ub)
            picks = _subsequence(r_geoms, [_signature(u, _GEOM_STATIC, g) for g in u_geoms])
            geom += [u_geoms[i] for i in picks]
        jnt = np.array(jnt, np.int32)
        dof = np.concatenate([u.jnt_dofadr[j] + np.arange(_width(u, j, "dof")) for j in jnt])
        qpos = np.concatenate([u.jnt_qposadr[j] + np.arange(_width(u, j, "qpos")) for j in jnt])
        motor = np.zeros(r.nu, np.int32)
        for rj, uj in enumerate(jnt):
            for ra, ua in zip(
                self.r_motors.get(rj, []), self.u_motors.get(int(uj), []), strict=True
            ):
                motor[ra] = ua
        return Embedding(
            body=body,
            jnt=jnt,
            dof=dof.astype(np.int32),
            qpos=qpos.astype(np.int32),
            geom=np.array(geom, np.int32),
            actuator=motor,
        )


def _width(model: mujoco.MjModel, j: int, what: str) -> int:
    kind = int(model.jnt_type[j])
    if what == "dof":
        return {int(mujoco.mjtJoint.mjJNT_FREE): 6, int(mujoco.mjtJoint.mjJNT_BALL): 3}.get(kind, 1)
    return {int(mujoco.mjtJoint.mjJNT_FREE): 7, int(mujoco.mjtJoint.mjJNT_BALL): 4}.get(kind, 1)


def embed(robot: Morphology | mujoco.MjModel, union: mujoco.MjModel) -> Embedding | None:
    """Where ``robot`` sits in ``union``'s tree, or None if it does not embed."""
    model = robot.model if isinstance(robot, Morphology) else robot
    if model.nbody > union.nbody or options_key(model) != options_key(union):
        return None
    return _Embedder(model, union).embedding()


def plan_unions(robots: tuple[Morphology, ...], grow: bool = False) -> list[list[int]]:
    """Groups robot indices into unions, each a list led by its host (the largest robot:
    most bodies, then geoms; the first of equals). A group of one is a robot alone;
    members keep the suite's order.

    ``grow``: one union of all robots with the same physics options and frame skip (the
    host's tree grown until each embeds, ``build_union``). Else hosts, largest first, are
    the robots that embed in no larger host, and every other robot joins the smallest
    host (fewest dofs) it embeds in with its physics settings: a union per family."""
    order = sorted(
        range(len(robots)), key=lambda i: (-robots[i].model.nbody, -robots[i].model.ngeom, i)
    )
    if grow:
        by_physics: dict[tuple, list[int]] = {}
        for i in order:
            key = (physics_key(robots[i]), _growable(robots[i]))
            by_physics.setdefault(key, []).append(i)
        groups = []
        for (*_, growable), members in by_physics.items():
            if not growable:
                groups += [[i] for i in members]
                continue
            groups.append([members[0]] + sorted(members[1:]))
        return groups
    hosts: list[int] = []
    fits: dict[int, list[int]] = {}  # robot -> the hosts it embeds in
    for i in order:
        fits[i] = [
            h
            for h in hosts
            if physics_key(robots[i]) == physics_key(robots[h])
            and embed(robots[i], robots[h].model) is not None
        ]
        if not fits[i]:
            hosts.append(i)
    groups = {h: [h] for h in hosts}
    for i in range(len(robots)):
        if i not in groups:
            host = min(fits[i], key=lambda h: (robots[h].model.nv, robots[h].model.nbody))
            groups[host].append(i)
    return [groups[h] for h in hosts]


def _growable(robot: Morphology) -> bool:
    """Whether a union may grow to take ``robot``: its collision bits are 0 or 1 (a union
    gives each family of robots a bit of its own) and its bodies and geoms are named."""
    m = robot.model
    bits = np.concatenate([m.geom_contype, m.geom_conaffinity])
    named = all(m.body(b).name for b in range(1, m.nbody))
    return bool(np.isin(bits, (0, 1)).all()) and named


def build_union(robots: tuple[Morphology, ...], grow: bool = False) -> Union:
    """The union of ``robots`` on the tree of the first: every other must embed in it,
    or with ``grow`` the tree grows until each does (``_grow``)."""
    host = robots[0].model
    if grow:
        plain, host = _grow(robots)
    else:
        plain = host
    embeddings = []
    for robot in robots:
        found = embed(robot, plain)
        if found is None:
            raise ValueError(f"{robot.name} does not embed in {robots[0].name}'s tree")
        embeddings.append(found)
    return Union(model=host, robots=tuple(robots), embeddings=tuple(embeddings))


_GEOM_COPIED = (
    "type", "size", "pos", "quat", "fromto", "friction", "condim", "contype", "conaffinity",
    "margin", "gap", "solref", "solimp", "solmix", "priority", "density", "mass", "rgba",
    "group",
)  # fmt: skip


def _grow(robots: tuple[Morphology, ...]) -> tuple[mujoco.MjModel, mujoco.MjModel]:
    """The first robot's tree grown until every robot embeds in it, in turn: each robot's
    bodies merge into the union's (children in order, a limb into the first later child
    with its joints), its geoms join their body's, and what finds no place is attached:
    a subtree as a new last child, a geom as its body's last. Returns the union compiled
    with the robots' own collision bits (for ``embed``) and as it runs: each family of
    robots (the same geom collision bits) on a bit of its own, so that no two families'
    geoms pair (the floor takes every family's)."""
    spec = mujoco.MjSpec.from_string(robots[0].xml)
    drop_textures(spec)
    origin = {}  # union geom name -> the robot it came from (unnamed: the host's)
    largest_first = sorted(range(1, len(robots)), key=lambda k: -robots[k].model.nbody)
    for k in largest_first:
        robot = robots[k]
        union = spec.compile()
        if embed(robot, union) is not None:
            continue
        own = mujoco.MjSpec.from_string(robot.xml)
        for i, geom in enumerate(own.geoms):  # named, so that the union knows its own
            geom.name = geom.name or f"geom{i}"
        _Grower(spec, union, robot, own, f"k{k}/", origin, k).merge(0, 0)
    plain = spec.compile()
    families = _families(robots)
    if len(set(families)) > 1:
        index = {f: i for i, f in enumerate(dict.fromkeys(families))}
        for geom in spec.geoms:
            if geom.parent.name == "world":
                bits = [index[f] for f in families]  # the floor collides with every family
            else:
                bits = [index[families[origin.get(geom.name, 0)]]]
            geom.contype = sum(int(geom.contype) << b for b in set(bits))
            geom.conaffinity = sum(int(geom.conaffinity) << b for b in set(bits))
    return plain, spec.compile()


def _families(robots: tuple[Morphology, ...]) -> list[frozenset]:
    """Each robot's collision family: its limbs' (contype, conaffinity) pairs."""
    out = []
    for robot in robots:
        m = robot.model
        limbs = m.geom_bodyid > 0
        pairs = zip(m.geom_contype[limbs].tolist(), m.geom_conaffinity[limbs].tolist(), strict=True)
        out.append(frozenset(pairs))
    return out


class _Grower:
    """Merges ``robot`` (its spec ``own``) into the union ``spec`` (compiled: ``union``)."""

    def __init__(self, spec, union, robot, own, prefix, origin, k):
        self.spec, self.union, self.own, self.prefix = spec, union, own, prefix
        self.origin, self.k = origin, k
        self.embedder = _Embedder(robot.model, union)
        self.robot = robot.model

    def merge(self, rb: int, ub: int) -> None:
        r, u, e = self.robot, self.union, self.embedder
        r_geoms = [_signature(r, _GEOM_STATIC, g) for g in _geoms(r, rb)]
        u_geoms = [_signature(u, _GEOM_STATIC, g) for g in _geoms(u, ub)]
        j = 0
        body = self.spec.body(u.body(ub).name)
        for g, sig in zip(_geoms(r, rb), r_geoms, strict=True):
            while j < len(u_geoms) and u_geoms[j] != sig:
                j += 1
            if j < len(u_geoms):
                j += 1
                continue
            j = len(u_geoms)  # every later geom of this body goes after the union's
            source = self.own.body(r.body(rb).name).geoms[g - r.body_geomadr[rb]]
            copy_ = body.add_geom(name=self.prefix + source.name)
            for attr in _GEOM_COPIED:
                setattr(copy_, attr, getattr(source, attr))
            self.origin[copy_.name] = self.k
        slots, start, attached = e.u_children[ub], 0, False
        for rc in e.r_children[rb]:
            if not attached:
                placed = next(
                    (i for i in range(start, len(slots)) if e.body_map(rc, slots[i], False)),
                    None,
                )
                if placed is None:
                    placed = next(
                        (i for i in range(start, len(slots)) if e.joints_fit(rc, slots[i])),
                        None,
                    )
                    if placed is not None:
                        self.merge(rc, slots[placed])
                if placed is not None:
                    start = placed + 1
                    continue
            # No later child of the union's takes it: a new last child, and so the rest.
            attached = True
            sub = self.own.body(r.body(rc).name)
            for b in [sub, *sub.find_all(mujoco.mjtObj.mjOBJ_BODY)]:
                for geom in b.geoms:
                    self.origin[self.prefix + geom.name] = self.k
            body.add_frame().attach_body(sub, self.prefix, "")


def _per_element_fields(model: mujoco.MjModel) -> dict[str, str]:
    """Array field -> the size its first axis runs over (``_AXES``)."""
    out = {}
    for name in dir(model):
        if name.startswith("_"):
            continue
        value = getattr(model, name)
        if not isinstance(value, np.ndarray) or value.ndim == 0:
            continue
        for prefix, axis in _AXES.items():
            if name.startswith(prefix) and value.shape[0] == getattr(model, axis):
                out[name] = axis
                break
    return out


def robot_model(union: Union, k: int, robot: Morphology | None = None) -> mujoco.MjModel:
    """The union's model carrying robot ``k``'s numbers (``robot``: a variant of robot
    ``k``, of the same tree, in its place), its other elements dummies."""
    robot = robot or union.robots[k]
    small, emb = robot.model, union.embeddings[k]
    model = copy.deepcopy(union.model)
    for name, axis in _per_element_fields(model).items():
        target = getattr(model, name)
        if np.issubdtype(target.dtype, np.floating) or name in _SHORTCUTS:
            target[emb.of(axis)] = getattr(small, name)
    _make_dummies(model, emb)
    # MuJoCo C culls geom pairs within a body by a tree of boxes compiled from the
    # union's own shapes, not the robot's; without it, its narrow phase decides (what it
    # keeps the robot's own model keeps too; MJX never culls so).
    model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_MIDPHASE
    # MuJoCo C scales its solver's tolerance by 1 / (meaninertia · nv): the robot's own product.
    model.stat.meaninertia = small.stat.meaninertia * small.nv / model.nv
    return model


def _unmapped(size: int, mapped: np.ndarray) -> np.ndarray:
    return np.setdiff1d(np.arange(size), mapped)


def _make_dummies(model: mujoco.MjModel, emb: Embedding) -> None:
    body = _unmapped(model.nbody, emb.body)
    model.body_mass[body] = 0.0
    model.body_inertia[body] = 0.0
    model.body_subtreemass[body] = 0.0
    model.body_gravcomp[body] = 0.0
    jnt = _unmapped(model.njnt, emb.jnt)
    model.jnt_range[jnt] = (-DUMMY_RANGE, DUMMY_RANGE)
    model.jnt_stiffness[jnt] = 0.0
    model.jnt_margin[jnt] = 0.0
    dof = _unmapped(model.nv, emb.dof)
    model.dof_armature[dof] = DUMMY_ARMATURE
    model.dof_damping[dof] = 0.0
    model.dof_frictionloss[dof] = 0.0
    qpos = _unmapped(model.nq, emb.qpos)
    model.qpos0[qpos] = 0.0
    model.qpos_spring[qpos] = 0.0
    geom = _unmapped(model.ngeom, emb.geom)
    model.geom_margin[geom] = DUMMY_MARGIN
    model.geom_gap[geom] = 0.0
    motor = _unmapped(model.nu, emb.actuator)
    model.actuator_gear[motor] = 0.0
