"""``Morphology``: everything later layers need about one robot, computed once on the host.

``load(name_or_path)`` takes a registered robot name (``walker_7_main``) or the path of
any MJCF file in the same planar convention (algorithm.md §1): the torso is the
world's one child body with root joints slide x, slide z, hinge y (in that order);
every other body has exactly one limited hinge and exactly one motor on it.
"""

import dataclasses
import difflib
import functools
import warnings
from pathlib import Path

import mujoco
import numpy as np

from solar_jax.morphology import graph
from solar_jax.morphology.builder import build_xml
from solar_jax.morphology.description import Task
from solar_jax.morphology.families import ROBOTS

NUM_LIMB_TYPES = 4


def generic_task(model: mujoco.MjModel) -> Task:
    """The task of a user-supplied robot: the walkers' reward and reset, healthy while
    the torso's body origin stays above half its initial height and |pitch| < 1.

    z is qpos[1] (the root slide, offset by its ``ref``), so the bound is
    ``ref - h0 / 2`` for an initial body height ``h0``. Pass ``task=`` to ``load``
    to use another rule.
    """
    z_ref, h0 = float(model.qpos0[1]), float(model.body_pos[1, 2])
    return Task(z_range=(z_ref - 0.5 * h0, float("inf")), max_abs_pitch=1.0)


class MorphologyError(ValueError):
    """A robot that cannot be loaded; the message names the source and the problem."""


@dataclasses.dataclass(frozen=True, eq=False)
class Morphology:
    """One robot. Agents are bodies in pre-order, torso first (agent i = MuJoCo body i+1).

    Array fields are NumPy, ``N`` = number of agents = actuators + 1.
    """

    name: str
    family: str  # "walker", "hopper", "humanoid_2d", "cheetah", or "custom"
    source: str  # "registry" or the file's path
    xml: str
    model: mujoco.MjModel  # the physics' model: no textures (``textured_model``)
    agents: tuple[str, ...]  # body names
    parents: tuple[int, ...]  # parents[0] == -1
    joints: tuple[str, ...]  # each agent's hinge ("" for the torso)
    joint_range: np.ndarray  # [N, 2] degrees; the torso's row is 0
    limb_types: np.ndarray  # [N] int in [0, 4), -1 for none
    reference_limb_types: np.ndarray  # [N] as the reference code feeds them (algorithm.md §2)
    limb_type_names: tuple[str, ...]
    hop_distances: np.ndarray  # [N, N] int32
    traversal: np.ndarray  # [N, 3] int32: (pre, in, post) order in the LCRS tree
    actuators: np.ndarray  # [N] actuator index driving each agent, -1 for the torso
    qpos_adr: np.ndarray  # [N] qpos address of each agent's hinge (torso: its pitch)
    dof_adr: np.ndarray  # [N] dof address likewise
    task: Task

    @property
    def num_agents(self) -> int:
        return len(self.agents)

    @property
    def num_actuators(self) -> int:
        return self.model.nu

    @property
    def loaded_from(self) -> str:
        """What ``load`` builds it from again (a suite's member): the registered name, or
        the MJCF file's path (its ``name`` is then the file's stem)."""
        return self.name if self.source == "registry" else self.source

    def textured_model(self) -> mujoco.MjModel:
        """The robot's model with its textures (skybox, floor grid), compiled again from
        its MJCF, for drawing: ``model`` is the physics' own, without them."""
        if self.source == "registry":
            return mujoco.MjModel.from_xml_string(self.xml)
        return mujoco.MjModel.from_xml_path(self.source)  # its assets beside the file

    @property
    def dt(self) -> float:
        """Seconds per environment step (timestep x frame_skip)."""
        return float(self.model.opt.timestep) * self.task.frame_skip


# Set per environment by EnvConfig, so they need not agree between robots.
_CONFIGURED_OPTIONS = ("iterations", "ls_iterations")


def option_fields(option) -> list[str]:
    """The ``<option>`` fields (of an ``MjOption`` or a spec's) robots sharing an MJX model
    must agree in: all but those the env's config sets."""
    return [
        name
        for name in dir(option)
        if not name.startswith("_")
        and name not in _CONFIGURED_OPTIONS
        and not callable(getattr(option, name))
    ]


def options_key(model: mujoco.MjModel) -> tuple:
    """``model``'s values of ``option_fields``, comparable."""
    opt = model.opt
    return tuple(
        (name, tuple(np.ravel(getattr(opt, name)).round(12))) for name in option_fields(opt)
    )


def physics_key(morph: Morphology) -> tuple:
    """Robots can share an MJX model only if their ``<option>`` fields and frame skips agree."""
    return (*options_key(morph.model), ("frame_skip", morph.task.frame_skip))


def _fail(source: str, problem: str) -> MorphologyError:
    return MorphologyError(f"{source}: {problem}")


def drop_textures(spec: mujoco.MjSpec) -> None:
    """``spec`` without its textures (materials keep their colours): physics never reads
    them, and ``compile`` generates them, the reference robots' 800 x 4800 RGB skybox
    in 40 ms and 11.5 MB of each robot (against 1-2 ms for the rest of the model)."""
    for material in spec.materials:
        material.textures = [""] * len(material.textures)
    for texture in list(spec.textures):
        spec.delete(texture)


def _compile(xml: str | None, path: Path | None, source: str) -> mujoco.MjModel:
    """The physics' model of an MJCF text or file: its textures dropped
    (``drop_textures``; ``Morphology.textured_model`` keeps them for drawing)."""
    try:
        if path is not None:
            spec = mujoco.MjSpec.from_file(str(path))
        else:
            spec = mujoco.MjSpec.from_string(xml)
        drop_textures(spec)
        with warnings.catch_warnings():  # silent, as ``MjModel.from_xml_*`` compiles: a bad
            warnings.simplefilter("ignore")  # robot gets ``from_model``'s one-line error
            return spec.compile()
    except ValueError as err:  # MuJoCo's parse and compile errors
        first_line = str(err).strip().splitlines()[0] if str(err).strip() else "unknown error"
        raise _fail(source, f"malformed MJCF: {first_line}") from None


def _describe_joint(model: mujoco.MjModel, j: int) -> str:
    kinds = {int(mujoco.mjtJoint.mjJNT_SLIDE): "slide", int(mujoco.mjtJoint.mjJNT_HINGE): "hinge"}
    kind = kinds.get(int(model.jnt_type[j]), "free/ball")
    return f"{kind}({' '.join(f'{a:g}' for a in model.jnt_axis[j])})"


def _check_root(model: mujoco.MjModel, source: str) -> None:
    world_children = [b for b in range(1, model.nbody) if model.body_parentid[b] == 0]
    if len(world_children) != 1:
        names = [model.body(b).name for b in world_children]
        raise _fail(source, f"expected one robot under <worldbody>, found bodies {names}")
    torso = model.body(1)
    expected = (
        (mujoco.mjtJoint.mjJNT_SLIDE, (1, 0, 0)),
        (mujoco.mjtJoint.mjJNT_SLIDE, (0, 0, 1)),
        (mujoco.mjtJoint.mjJNT_HINGE, (0, 1, 0)),
    )
    joints = range(model.body_jntadr[1], model.body_jntadr[1] + model.body_jntnum[1])
    ok = len(joints) == 3 and all(
        model.jnt_type[j] == kind and np.allclose(model.jnt_axis[j], axis)
        for j, (kind, axis) in zip(joints, expected, strict=True)
    )
    if not ok:
        found = ", ".join(_describe_joint(model, j) for j in joints) or "none"
        raise _fail(
            source,
            f"torso '{torso.name}' needs root joints slide x, slide z, hinge y in that "
            f"order, found: {found}",
        )


def _limb_joints(model: mujoco.MjModel, source: str) -> list[int]:
    joints = []
    for b in range(2, model.nbody):
        name = model.body(b).name or f"#{b}"
        n = model.body_jntnum[b]
        if n != 1:
            raise _fail(source, f"body '{name}' has {n} joints; every limb needs exactly one hinge")
        j = model.body_jntadr[b]
        if model.jnt_type[j] != mujoco.mjtJoint.mjJNT_HINGE:
            raise _fail(
                source, f"body '{name}' has a {_describe_joint(model, j)} joint, not a hinge"
            )
        if not model.jnt_limited[j]:
            raise _fail(source, f"joint '{model.joint(j).name}' of body '{name}' has no range")
        joints.append(int(j))
    return joints


def _actuator_per_limb(model: mujoco.MjModel, limb_joints: list[int], source: str) -> list[int]:
    by_joint: dict[int, list[int]] = {}
    for a in range(model.nu):
        if model.actuator_trntype[a] != mujoco.mjtTrn.mjTRN_JOINT:
            raise _fail(source, f"actuator #{a} does not drive a joint")
        by_joint.setdefault(int(model.actuator_trnid[a, 0]), []).append(a)
    out = []
    for j in limb_joints:
        found = by_joint.pop(j, [])
        if len(found) != 1:
            what = "no motor" if not found else f"{len(found)} actuators"
            raise _fail(source, f"joint '{model.joint(j).name}' has {what}; every limb needs one")
        out.append(found[0])
    if by_joint:
        names = [model.joint(j).name for j in by_joint]
        raise _fail(source, f"actuators on non-limb joints {names} (root joints are unactuated)")
    return out


def from_model(
    model: mujoco.MjModel,
    xml: str,
    *,
    name: str,
    source: str,
    family: str = "custom",
    task: Task | None = None,
    limb_types: tuple[int, ...] | None = None,
    limb_type_names: tuple[str, ...] = ("torso", "depth 1", "depth 2", "depth >= 3"),
    zero_reference_limb_types: bool = False,
) -> Morphology:
    """Checks the planar convention and derives the graph facts of a compiled model.

    Without ``limb_types``, a body's type is its depth in the tree (torso 0, capped at 3),
    which is what the walkers' name-based types amount to.
    """
    if model.nbody < 2:
        raise _fail(source, "no robot body under <worldbody>")
    _check_root(model, source)
    limb_joints = _limb_joints(model, source)
    actuators = _actuator_per_limb(model, limb_joints, source)

    parents = graph.validate_parents([-1] + [int(p) - 1 for p in model.body_parentid[2:]])
    n = len(parents)
    joint_range = np.zeros((n, 2))
    joint_range[1:] = np.rad2deg(model.jnt_range[limb_joints])
    if limb_types is None:
        limb_types = tuple(int(min(d, NUM_LIMB_TYPES - 1)) for d in graph.depths(parents))
    limb_types_arr = np.asarray(limb_types, dtype=np.int32)
    root_pitch = int(model.body_jntadr[1]) + 2
    return Morphology(
        name=name,
        family=family,
        source=source,
        xml=xml,
        model=model,
        agents=tuple(model.body(b).name for b in range(1, model.nbody)),
        parents=parents,
        joints=("",) + tuple(model.joint(j).name for j in limb_joints),
        joint_range=joint_range,
        limb_types=limb_types_arr,
        reference_limb_types=np.full(n, -1, np.int32)
        if zero_reference_limb_types
        else limb_types_arr,
        limb_type_names=limb_type_names,
        hop_distances=graph.hop_distances(parents),
        traversal=graph.traversal_indices(parents),
        actuators=np.asarray([-1] + actuators, dtype=np.int32),
        qpos_adr=np.asarray([model.jnt_qposadr[j] for j in [root_pitch, *limb_joints]], np.int32),
        dof_adr=np.asarray([model.jnt_dofadr[j] for j in [root_pitch, *limb_joints]], np.int32),
        task=task or generic_task(model),
    )


def _unknown_name(name: str) -> MorphologyError:
    close = difflib.get_close_matches(name, ROBOTS, n=3)
    hint = f" (did you mean {', '.join(close)}?)" if close else ""
    return MorphologyError(
        f"unknown morphology '{name}'{hint}; valid names: {', '.join(ROBOTS)}, or a path to an "
        "MJCF file"
    )


@functools.cache
def _registered_xml(name: str) -> str:
    """A registered robot's MJCF text, built once per process: writing it is half the
    cost of a load (``python -m solar_jax.morphology list`` loads every robot twice)."""
    return build_xml(name)


def load(name_or_path: str | Path, *, task: Task | None = None) -> Morphology:
    """A registered robot by name, or an MJCF file by path (``.xml``).

    ``task`` overrides the robot's task (registered robots have the reference's;
    files get ``generic_task``).
    """
    key = str(name_or_path)
    if key in ROBOTS:
        robot = ROBOTS[key]()
        xml = _registered_xml(key)
        model = _compile(xml, None, f"morphology '{key}'")
        limb_types = tuple(b.limb_type for b in robot.bodies)
        return from_model(
            model,
            xml,
            name=key,
            source="registry",
            family=robot.family,
            task=task or robot.task,
            limb_types=limb_types,
            limb_type_names=robot.limb_type_names,
            zero_reference_limb_types=robot.reference_zeroes_limb_types,
        )
    path = Path(key)
    if path.suffix.lower() != ".xml" and not path.exists():
        raise _unknown_name(key)
    if not path.is_file():
        raise MorphologyError(f"{key}: MJCF file not found")
    model = _compile(None, path, key)
    return from_model(model, path.read_text(), name=path.stem, source=key, task=task)
