"""Worlds: several robots merged into one MuJoCo model, plus the static index maps
that let jitted code address each robot's slice of it.

Why merge: an MJX model per morphology, stepped in one traced function, compiles
once per morphology (~20 s each for RK4 on a 2-core CPU with MJX's own step, about a
third of that with ``integrator.py``'s); a merged world compiles once (see
``benchmarks/README.md`` for the measured trade-off). Merging is exact:

- every robot keeps its own copy of its floor (contact parameters are mixed per
  geom pair, and floors differ between families);
- robot ``r``'s geoms and floor get the private collision bit ``1 << r`` in place of
  bit 0, so robots never touch each other or each other's floors, and MJX generates
  no contact pair across robots;
- robots keep their pre-order, so their bodies, joints, qpos, dofs and actuators are
  contiguous blocks of the world's.

What is not exact: the constraint solver sees one problem per world, so solver
iterations and line searches are shared across the world's robots (they converge to
the same solution; a non-finite state anywhere resets the whole world).
"""

import dataclasses

import mujoco
import numpy as np

from solar_jax.morphology import Morphology
from solar_jax.morphology.morphology import drop_textures, option_fields, physics_key

OBS_SIZE = 19  # per agent: pos 3, lin vel 3, ang vel 3, expmap 3, limb type 4, angle 1, range 2
MAX_ROBOTS_PER_WORLD = 31  # one private int32 collision bit per robot


@dataclasses.dataclass(frozen=True, eq=False)
class World:
    """A merged model of ``R`` robots and its static maps (NumPy, host side).

    Per-agent arrays are padded to ``n_max`` agents; padded entries point at body 0
    (the world body) and are masked.
    """

    morphs: tuple[Morphology, ...]
    model: mujoco.MjModel
    n_max: int
    frame_skip: int
    body_ids: np.ndarray  # [R, n_max] world body id of each agent
    agent_mask: np.ndarray  # [R, n_max] bool
    qpos_adr: np.ndarray  # [R, n_max] qpos address of each agent's hinge (torso: pitch)
    root_qpos: np.ndarray  # [R] qpos address of each robot's root slide x
    qpos_robot: np.ndarray  # [nq] robot owning each qpos entry
    dof_robot: np.ndarray  # [nv] robot owning each dof
    ctrl_robot: np.ndarray  # [nu] robot of each actuator
    ctrl_agent: np.ndarray  # [nu] agent (pre-order index) each actuator drives
    actuated: np.ndarray  # [R, n_max] bool: real agents with a motor (not the torso)

    @property
    def num_robots(self) -> int:
        return len(self.morphs)

    @property
    def dt(self) -> float:
        return float(self.model.opt.timestep) * self.frame_skip


def _check_mergeable(morph: Morphology) -> None:
    bits = np.concatenate([morph.model.geom_contype, morph.model.geom_conaffinity])
    if not np.isin(bits, (0, 1)).all():
        raise ValueError(
            f"{morph.name}: geom contype/conaffinity other than 0/1 cannot share a world; "
            "give it a world of its own"
        )


def _copy_world_geoms(world: mujoco.MjSpec, child: mujoco.MjSpec, prefix: str) -> None:
    """The robot's floor (and any other world geom), with its own contact parameters."""
    attrs = ("type", "size", "pos", "quat", "friction", "condim", "solref", "solimp", "solmix")
    attrs += ("margin", "gap", "priority", "contype", "conaffinity", "rgba")
    for geom in child.worldbody.geoms:
        copy = world.worldbody.add_geom(name=prefix + (geom.name or "floor"))
        for attr in attrs:
            setattr(copy, attr, getattr(geom, attr))


def build_world(morphs: tuple[Morphology, ...], n_max: int) -> World:
    """Merges ``morphs`` (same ``physics_key``, at most 31) into one ``World``."""
    if not 1 <= len(morphs) <= MAX_ROBOTS_PER_WORLD:
        raise ValueError(f"a world holds 1 to {MAX_ROBOTS_PER_WORLD} robots, got {len(morphs)}")
    keys = {physics_key(m) for m in morphs}
    if len(keys) != 1:
        raise ValueError(f"robots with different physics settings cannot share a world: {keys}")
    first = mujoco.MjSpec.from_string(morphs[0].xml)
    spec = mujoco.MjSpec()
    spec.modelname = "world"
    for name in option_fields(spec.option):  # all of the robots' shared <option>
        setattr(spec.option, name, getattr(first.option, name))
    for r, morph in enumerate(morphs):
        if len(morphs) > 1:
            _check_mergeable(morph)
        child = mujoco.MjSpec.from_string(morph.xml)
        prefix = f"r{r}/"
        _copy_world_geoms(spec, child, prefix)
        spec.worldbody.add_frame().attach_body(child.body(morph.agents[0]), prefix, "")
    if len(morphs) > 1:
        # Private collision bit per robot (module docstring): bit 0 -> bit r.
        owner = _geom_owners(spec, len(morphs))
        for geom, r in owner:
            geom.contype = (1 << r) if geom.contype else 0
            geom.conaffinity = (1 << r) if geom.conaffinity else 0
    drop_textures(spec)  # the robots' XML still has them: 11.5 MB each
    model = spec.compile()
    return _index(morphs, model, n_max, morphs[0].task.frame_skip)


def _geom_owners(spec: mujoco.MjSpec, num_robots: int) -> list[tuple[mujoco.MjsGeom, int]]:
    owners = []
    for geom in spec.geoms:
        name = geom.name or ""
        if geom.parent.name == "world":
            r = int(name.split("/")[0][1:])
        else:
            r = int(geom.parent.name.split("/")[0][1:])
        assert 0 <= r < num_robots
        owners.append((geom, r))
    return owners


def slot(morph: Morphology, model: mujoco.MjModel, n_max: int) -> World:
    """A world of one robot slot with ``model`` (a union's: ``env.union``), whose robot maps
    come per environment from elsewhere: of its own it holds the model, ``morph``'s frame
    skip and the root joints at qpos 0-2; its per-agent maps are empty."""
    empty = np.zeros((1, n_max), np.int32)
    return World(
        morphs=(morph,),
        model=model,
        n_max=n_max,
        frame_skip=morph.task.frame_skip,
        body_ids=empty,
        agent_mask=empty.astype(bool),
        qpos_adr=empty,
        root_qpos=np.zeros(1, np.int32),
        qpos_robot=np.zeros(model.nq, np.int32),
        dof_robot=np.zeros(model.nv, np.int32),
        ctrl_robot=np.zeros(model.nu, np.int32),
        ctrl_agent=np.zeros(model.nu, np.int32),
        actuated=empty.astype(bool),
    )


def _index(morphs, model: mujoco.MjModel, n_max: int, frame_skip: int) -> World:
    num = len(morphs)
    body_ids = np.zeros((num, n_max), np.int32)
    mask = np.zeros((num, n_max), bool)
    qpos_adr = np.zeros((num, n_max), np.int32)
    root_qpos = np.zeros(num, np.int32)
    qpos_robot = np.zeros(model.nq, np.int32)
    dof_robot = np.zeros(model.nv, np.int32)
    ctrl_robot = np.zeros(model.nu, np.int32)
    ctrl_agent = np.zeros(model.nu, np.int32)
    body0 = qpos0 = dof0 = ctrl0 = 0
    for r, m in enumerate(morphs):
        n = m.num_agents
        if n > n_max:
            raise ValueError(f"{m.name} has {n} agents, more than n_max = {n_max}")
        body_ids[r, :n] = 1 + body0 + np.arange(n)
        mask[r, :n] = True
        qpos_adr[r, :n] = qpos0 + m.qpos_adr
        root_qpos[r] = qpos0
        qpos_robot[qpos0 : qpos0 + m.model.nq] = r
        dof_robot[dof0 : dof0 + m.model.nv] = r
        agents = np.flatnonzero(m.actuators >= 0)
        ctrl_robot[ctrl0 + m.actuators[agents]] = r
        ctrl_agent[ctrl0 + m.actuators[agents]] = agents
        body0, qpos0, dof0, ctrl0 = (
            body0 + n,
            qpos0 + m.model.nq,
            dof0 + m.model.nv,
            ctrl0 + m.model.nu,
        )
    assert (body0 + 1, qpos0, dof0, ctrl0) == (model.nbody, model.nq, model.nv, model.nu)
    return World(
        morphs=tuple(morphs),
        model=model,
        n_max=n_max,
        frame_skip=frame_skip,
        body_ids=body_ids,
        agent_mask=mask,
        qpos_adr=qpos_adr,
        root_qpos=root_qpos,
        qpos_robot=qpos_robot,
        dof_robot=dof_robot,
        ctrl_robot=ctrl_robot,
        ctrl_agent=ctrl_agent,
        actuated=mask & (np.arange(n_max) > 0),
    )


def plan_worlds(morphs: tuple[Morphology, ...], robots_per_world: int) -> list[list[int]]:
    """Groups robot indices into worlds: same physics, at most ``robots_per_world`` each.

    ``robots_per_world=1`` is one model per morphology. Groups keep the given order.
    """
    if robots_per_world < 1:
        raise ValueError(f"robots_per_world must be >= 1, got {robots_per_world}")
    cap = min(robots_per_world, MAX_ROBOTS_PER_WORLD)
    by_key: dict[tuple, list[int]] = {}
    for i, m in enumerate(morphs):
        by_key.setdefault(physics_key(m), []).append(i)
    groups = []
    for members in by_key.values():
        groups += [members[k : k + cap] for k in range(0, len(members), cap)]
    return groups


def model_bytes(model: mujoco.MjModel) -> bytes:
    """``model`` as MuJoCo's binary file (MJB): everything the physics reads, options
    included, for keys of programs traced from it."""
    buffer = np.zeros(mujoco.mj_sizeModel(model), np.uint8)
    mujoco.mj_saveModel(model, None, buffer)
    return buffer.tobytes()
