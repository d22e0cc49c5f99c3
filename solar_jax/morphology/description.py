"""Plain descriptions of robots, from which the builder writes MJCF.

Coordinates are local, as in MJCF: a body's ``pos`` is relative to its parent's
frame, a joint's or geom's to its own body's frame. No body is rotated in any
family here. Angles (joint ranges, geom axis-angles) are in the robot's ``angle``
unit, so a description can carry the reference's numbers verbatim.
"""

import dataclasses
from typing import Literal

Vec3 = tuple[float, float, float]

AngleUnit = Literal["degree", "radian"]


@dataclasses.dataclass(frozen=True)
class Geom:
    """One collision/inertia geom. A capsule is given by ``fromto`` or by ``pos`` (+ axisangle)."""

    name: str
    size: tuple[float, ...]  # radius (, half-length) or plane half-extents
    type: Literal["capsule", "sphere", "plane"] = "capsule"
    fromto: tuple[float, float, float, float, float, float] | None = None
    pos: Vec3 = (0.0, 0.0, 0.0)
    axisangle: tuple[float, float, float, float] | None = None
    friction: float | None = None  # sliding friction; None keeps the robot's default
    condim: int | None = None
    conaffinity: int | None = None


@dataclasses.dataclass(frozen=True)
class Joint:
    """A hinge or slide joint; ``None`` attributes take the robot's joint defaults."""

    name: str
    axis: Vec3
    pos: Vec3 = (0.0, 0.0, 0.0)
    type: Literal["hinge", "slide"] = "hinge"
    range: tuple[float, float] | None = None  # None: unlimited (root joints)
    ref: float = 0.0
    armature: float | None = None
    damping: float | None = None
    stiffness: float | None = None


@dataclasses.dataclass(frozen=True)
class Camera:
    """A torso-tracking camera (for rendering only; not part of the physics)."""

    name: str
    pos: Vec3
    xyaxes: tuple[float, float, float, float, float, float]


@dataclasses.dataclass(frozen=True)
class Body:
    """A torso (three root joints, no motor) or a limb (one hinge, one motor of ``gear``)."""

    name: str
    parent: str | None  # None for the torso
    pos: Vec3
    joints: tuple[Joint, ...]
    geoms: tuple[Geom, ...]
    gear: float | None = None
    limb_type: int = -1  # index into the 4-way limb-type one-hot; -1: none
    cameras: tuple[Camera, ...] = ()


@dataclasses.dataclass(frozen=True)
class Defaults:
    """The robot's default class: joint and geom attributes every element starts from."""

    joint_armature: float
    joint_damping: float
    joint_stiffness: float = 0.0
    joint_solref_limit: tuple[float, ...] | None = None
    joint_solimp_limit: tuple[float, ...] | None = None
    geom_friction: tuple[float, float, float] = (1.0, 0.005, 0.0001)
    geom_conaffinity: int = 0
    geom_condim: int = 3
    geom_margin: float = 0.0
    geom_solref: tuple[float, ...] | None = None
    geom_solimp: tuple[float, ...] | None = None
    geom_density: float = 1000.0


@dataclasses.dataclass(frozen=True)
class Task:
    """The locomotion task of one robot (algorithm.md §2): reward, termination, reset.

    A step is healthy while ``z_range[0] < z < z_range[1]`` and ``|pitch| <
    max_abs_pitch`` and every ``|qpos[2:]|, |qvel| < max_abs_state`` (z = qpos[1],
    pitch = qpos[2]); a bound of ``None`` is not checked. Non-finite states are never
    healthy. ``terminates=False`` ends episodes only by the time limit.
    """

    frame_skip: int = 4
    alive_bonus: float = 1.0
    ctrl_cost: float = 1e-3  # times sum of squared actions in [-1, 1]
    terminates: bool = True
    z_range: tuple[float, float] | None = None
    max_abs_pitch: float | None = 1.0
    max_abs_state: float | None = None
    reset_qpos_noise: float = 0.005  # qpos0 + U(-c, c)
    reset_qvel_noise: float = 0.005  # U(-c, c), or N(0, c^2) if reset_qvel_normal
    reset_qvel_normal: bool = False


@dataclasses.dataclass(frozen=True)
class Robot:
    """Everything the builder needs to write one robot's MJCF, plus its task."""

    name: str
    family: str
    bodies: tuple[Body, ...]  # pre-order, torso first
    defaults: Defaults
    floor: Geom
    task: Task
    angle: AngleUnit
    timestep: float
    integrator: Literal["RK4", "Euler"]
    limb_type_names: tuple[str, str, str, str]
    # True where the reference code feeds all-zero limb-type one-hots instead of the
    # bodies' types (algorithm.md §2: 2-D humanoids, a name-matching bug from SMP).
    reference_zeroes_limb_types: bool = False

    def without(self, *names: str, name: str) -> "Robot":
        """This robot with the named bodies and their subtrees removed, renamed ``name``."""
        unknown = set(names) - {b.name for b in self.bodies}
        if unknown:
            raise ValueError(f"{self.name} has no bodies {sorted(unknown)}")
        removed = set(names)
        kept = []
        for body in self.bodies:
            if body.name in removed or body.parent in removed:
                removed.add(body.name)
            else:
                kept.append(body)
        return dataclasses.replace(self, name=name, bodies=tuple(kept))
