"""The SMP/SOLAR robot families as code, and the registry of all 38 named robots.

Geometry, joint and actuator numbers follow the SMP ``modular_rl`` morphologies
(MIT licence, Copyright (c) 2020 Wenlong Huang, Deepak Pathak) and algorithm.md §1.
Walkers and hoppers were authored in world coordinates (``coordinate="global"``,
which MuJoCo >= 2.3.4 rejects): their descriptions below keep those world numbers and
convert to local frames in one place, ``_localise``.
"""

import dataclasses
from collections.abc import Callable

from solar_jax.morphology.description import (
    Body,
    Camera,
    Defaults,
    Geom,
    Joint,
    Robot,
    Task,
    Vec3,
)

_Y_DOWN: Vec3 = (0.0, -1.0, 0.0)  # limb hinge axis of walkers, hoppers and humanoid knees
_Y_UP: Vec3 = (0.0, 1.0, 0.0)
_TRACK_XYAXES = (1.0, 0.0, 0.0, 0.0, 0.0, -1.0)
_TILTED_XYAXES = (1.0, -0.9, 0.0, 0.0, 0.0, -1.0)


def _root_joints(
    x: str, z: str, y: str, *, z_ref: float, pitch_pos: Vec3, armature: float = 0.0
) -> tuple[Joint, ...]:
    """The torso's unactuated planar joints: slide x, slide z, hinge y (algorithm.md §1)."""
    free = dict(armature=armature, damping=0.0, stiffness=0.0)
    return (
        Joint(x, axis=(1.0, 0.0, 0.0), type="slide", **free),
        Joint(z, axis=(0.0, 0.0, 1.0), type="slide", ref=z_ref, **free),
        Joint(y, axis=(0.0, 1.0, 0.0), pos=pitch_pos, **free),
    )


def _sub(a: Vec3, b: Vec3) -> Vec3:
    # Rounded so that e.g. 0.52 - 0.136 is written as 0.384, not 0.38400000000000006.
    return tuple(round(x - y, 12) for x, y in zip(a, b, strict=True))  # type: ignore[return-value]


def _localise(bodies: tuple[Body, ...]) -> tuple[Body, ...]:
    """World-frame body, joint, geom and camera positions -> MJCF local frames."""
    world = {b.name: b.pos for b in bodies}
    out = []
    for b in bodies:
        origin = b.pos
        parent_origin = world[b.parent] if b.parent else (0.0, 0.0, 0.0)
        joints = tuple(dataclasses.replace(j, pos=_sub(j.pos, origin)) for j in b.joints)
        geoms = tuple(
            dataclasses.replace(
                g,
                pos=_sub(g.pos, origin),
                fromto=(*_sub(g.fromto[:3], origin), *_sub(g.fromto[3:], origin))
                if g.fromto
                else None,
            )
            for g in b.geoms
        )
        cameras = tuple(dataclasses.replace(c, pos=_sub(c.pos, origin)) for c in b.cameras)
        out.append(
            dataclasses.replace(
                b, pos=_sub(origin, parent_origin), joints=joints, geoms=geoms, cameras=cameras
            )
        )
    return tuple(out)


def _vertical(name: str, top: float, bottom: float, radius: float, **kw) -> Geom:
    return Geom(name, size=(radius,), fromto=(0.0, 0.0, top, 0.0, 0.0, bottom), **kw)


# --------------------------------------------------------------------------- walkers

# Segment k of a walker leg, world frame: (top z, bottom z, radius). Segment 3 is the
# horizontal foot, 0.2 long at z 0.136.
_WALKER_SEGMENTS = {1: (1.0, 0.52, 0.056), 2: (0.52, 0.136, 0.0448), 3: (0.136, 0.136, 0.06)}
# Healthy torso height of walker_N (algorithm.md §2); pitch |θ| < 1 for all.
_WALKER_Z_RANGE = {2: (0.54, 1.74), 3: (0.54, 1.74), 4: (0.664, 1.864)}
_WALKER_Z_RANGE_TALL = (0.8, 2.0)  # walker_5/6/7


def walker(name: str, left: int, right: int) -> Robot:
    """A planar walker whose legs have ``left`` and ``right`` segments (0-3 each)."""
    torso_z = 1.6
    torso = Body(
        "torso",
        None,
        pos=(0.0, 0.0, torso_z),
        joints=_root_joints("rootx", "rootz", "rooty", z_ref=1.25, pitch_pos=(0.0, 0.0, 1.25)),
        geoms=(_vertical("torso_geom", 1.6, 1.0, 0.07, friction=0.9),),
        limb_type=0,
        cameras=(
            Camera("tilted", (2.7, 3.0, 1.0), _TILTED_XYAXES),
            Camera("track", (0.0, 3.0, 1.0), _TRACK_XYAXES),
        ),
    )
    bodies = [torso]
    for side, segments in (("left", left), ("right", right)):
        parent = "torso"
        for k in range(1, segments + 1):
            top, bottom, radius = _WALKER_SEGMENTS[k]
            foot_x = 0.2 if k == 3 else 0.0
            body = f"{side}{k}"
            bodies.append(
                Body(
                    body,
                    parent,
                    pos=(0.0, 0.0, top),
                    joints=(Joint(f"{body}_joint", _Y_DOWN, pos=(0.0, 0.0, top), range=(-75, 75)),),
                    geoms=(
                        Geom(
                            f"{body}_geom",
                            size=(radius,),
                            fromto=(0.0, 0.0, top, foot_x, 0.0, bottom),
                            friction=0.9,
                        ),
                    ),
                    gear=100.0,
                    limb_type=k,
                )
            )
            parent = body
    n_agents = len(bodies)
    return Robot(
        name=name,
        family="walker",
        bodies=_localise(tuple(bodies)),
        defaults=Defaults(joint_armature=0.01, joint_damping=0.1, geom_friction=(0.7, 0.1, 0.1)),
        floor=Geom("floor", size=(40.0, 40.0, 40.0), type="plane", conaffinity=1, condim=3),
        task=Task(z_range=_WALKER_Z_RANGE.get(n_agents, _WALKER_Z_RANGE_TALL)),
        angle="degree",
        timestep=0.002,
        integrator="RK4",
        limb_type_names=("torso", "segment 1", "segment 2", "foot"),
    )


# --------------------------------------------------------------------------- hoppers

# Shank segments under a hopper's torso, top to bottom: (name, length, radius).
# The thigh's body frame sits at its top (its joint); the others' at their middle.
_HOPPER_SEGMENTS = {"thigh": (0.45, 0.05), "leg": (0.5, 0.04), "lower_leg": (0.5, 0.04)}
_HOPPER_LIMB_TYPE = {"thigh": 1, "leg": 2, "lower_leg": 2}


def hopper(name: str, segments: tuple[str, ...], torso_z: float, min_z: float) -> Robot:
    """A one-legged hopper: torso, the named shank segments in order, then a foot."""
    torso = Body(
        "torso",
        None,
        pos=(0.0, 0.0, torso_z),
        joints=_root_joints(
            "rootx", "rootz", "rooty", z_ref=torso_z, pitch_pos=(0.0, 0.0, torso_z)
        ),
        geoms=(_vertical("torso_geom", torso_z + 0.2, torso_z - 0.2, 0.05, friction=0.9),),
        limb_type=0,
        cameras=(
            Camera("tilted", (2.7, 3.0, 1.0), _TILTED_XYAXES),
            Camera("track", (0.0, 3.0, 1.0), _TRACK_XYAXES),
        ),
    )
    bodies = [torso]
    top = torso_z - 0.2
    for segment in segments:
        length, radius = _HOPPER_SEGMENTS[segment]
        bottom = round(top - length, 12)
        frame_z = top if segment == "thigh" else round((top + bottom) / 2, 12)
        bodies.append(
            Body(
                segment,
                bodies[-1].name,
                pos=(0.0, 0.0, frame_z),
                joints=(Joint(f"{segment}_joint", _Y_DOWN, pos=(0.0, 0.0, top), range=(-150, 0)),),
                geoms=(_vertical(f"{segment}_geom", top, bottom, radius, friction=0.9),),
                gear=200.0,
                limb_type=_HOPPER_LIMB_TYPE[segment],
            )
        )
        top = bottom
    # The reference writes the foot's x as "0.13/2", which MuJoCo read as 0.065.
    bodies.append(
        Body(
            "foot",
            bodies[-1].name,
            pos=(0.065, 0.0, top),
            joints=(Joint("foot_joint", _Y_DOWN, pos=(0.0, 0.0, top), range=(-45, 45)),),
            geoms=(
                Geom(
                    "foot_geom",
                    size=(0.06,),
                    fromto=(-0.13, 0.0, top, 0.26, 0.0, top),
                    friction=2.0,
                ),
            ),
            gear=200.0,
            limb_type=3,
        )
    )
    return Robot(
        name=name,
        family="hopper",
        bodies=_localise(tuple(bodies)),
        defaults=Defaults(
            joint_armature=1.0,
            joint_damping=1.0,
            geom_conaffinity=1,
            geom_condim=1,
            geom_margin=0.001,
            geom_solimp=(0.8, 0.8, 0.01),
            geom_solref=(0.02, 1.0),
        ),
        floor=Geom("floor", size=(20.0, 20.0, 0.125), type="plane", condim=3),
        task=Task(z_range=(min_z, float("inf")), max_abs_state=100.0),
        angle="degree",
        timestep=0.002,
        integrator="RK4",
        limb_type_names=("torso", "thigh", "leg", "foot"),
    )


# --------------------------------------------------------------------- 2-D humanoids


def _humanoid_limb(
    name: str,
    parent: str,
    pos: Vec3,
    joint: Joint,
    geoms: tuple[Geom, ...],
    gear: float,
    limb_type: int,
) -> Body:
    return Body(name, parent, pos, (joint,), geoms, gear=gear, limb_type=limb_type)


def humanoid_2d_full() -> Robot:
    """humanoid_2d_9_full: torso, two legs (thigh, shin), two arms (upper, lower).

    Per-joint armature, damping and stiffness are the reference's, asymmetries
    included (the left knee has stiffness 1, the right none). Limb types follow the
    joint names SMP meant to match (hip, knee, shoulder, elbow); the torso has none.
    """
    torso = Body(
        "torso",
        None,
        pos=(0.0, 0.0, 1.4),
        joints=_root_joints(
            "abdomen_x", "abdomen_z", "abdomen_y", z_ref=1.25, pitch_pos=(0, 0, 1.1), armature=0.02
        ),
        geoms=(
            Geom("torso1", size=(0.07,), fromto=(0, -0.07, 0, 0, 0.07, 0)),
            Geom("head", size=(0.09,), type="sphere", pos=(0, 0, 0.19)),
            Geom("uwaist", size=(0.06,), fromto=(-0.01, -0.06, -0.12, -0.01, 0.06, -0.12)),
            Geom("lwaist", size=(0.06,), fromto=(-0.01, -0.06, -0.26, -0.01, 0.06, -0.26)),
            Geom("butt", size=(0.09,), fromto=(-0.02, -0.07, -0.425, -0.02, 0.07, -0.425)),
        ),
        cameras=(
            Camera("tilted", (3.6, 4.0, -0.2), _TILTED_XYAXES),
            Camera("track", (0.0, 4.0, 0.0), _TRACK_XYAXES),
        ),
    )
    limbs = []
    for side, s in (("right", -1.0), ("left", 1.0)):
        limbs += [
            _humanoid_limb(
                f"{side}_thigh",
                "torso",
                (0, 0.1 * s, -0.465),
                Joint(
                    f"{side}_hip_y",
                    _Y_UP,
                    range=(-110, 20),
                    armature=0.008 if side == "right" else 0.01,
                    damping=5.0,
                    stiffness=20.0,
                ),
                (Geom(f"{side}_thigh1", size=(0.06,), fromto=(0, 0, 0, 0, -0.01 * s, -0.34)),),
                gear=150.0,
                limb_type=0,
            ),
            _humanoid_limb(
                f"{side}_shin",
                f"{side}_thigh",
                (0, -0.01 * s, -0.403),
                Joint(
                    f"{side}_knee",
                    _Y_DOWN,
                    pos=(0, 0, 0.02),
                    range=(-160, -2),
                    armature=0.006,
                    stiffness=1.0 if side == "left" else None,
                ),
                (
                    Geom(f"{side}_shin1", size=(0.049,), fromto=(0, 0, 0, 0, 0, -0.3)),
                    Geom(f"{side}_foot", size=(0.075,), type="sphere", pos=(0, 0, -0.35)),
                ),
                gear=100.0,
                limb_type=1,
            ),
        ]
    for side, s in (("right", -1.0), ("left", 1.0)):
        limbs += [
            _humanoid_limb(
                f"{side}_upper_arm",
                "torso",
                (0, 0.17 * s, 0.06),
                Joint(
                    f"{side}_shoulder1",
                    _Y_DOWN,
                    range=(-85, 60) if side == "right" else (-60, 85),
                    armature=0.006,
                    stiffness=1.0,
                ),
                (Geom(f"{side}_uarm1", size=(0.04,), fromto=(0, 0, 0, 0.16, 0.16 * s, -0.16)),),
                gear=12.5,
                limb_type=2,
            ),
            _humanoid_limb(
                f"{side}_lower_arm",
                f"{side}_upper_arm",
                (0.18, 0.18 * s, -0.18),
                Joint(f"{side}_elbow", _Y_DOWN, range=(-90, 50), armature=0.0028, stiffness=0.0),
                (
                    Geom(
                        f"{side}_larm",
                        size=(0.031,),
                        fromto=(0.01, -0.01 * s, 0.01, 0.17, -0.17 * s, 0.17),
                    ),
                    Geom(f"{side}_hand", size=(0.04,), type="sphere", pos=(0.18, -0.18 * s, 0.18)),
                ),
                gear=12.5,
                limb_type=3,
            ),
        ]
    return Robot(
        name="humanoid_2d_9_full",
        family="humanoid_2d",
        bodies=(torso, *limbs),
        defaults=Defaults(joint_armature=1.0, joint_damping=1.0, geom_friction=(0.7, 0.1, 0.1)),
        floor=Geom("floor", size=(20.0, 20.0, 0.125), type="plane", conaffinity=1, condim=3),
        task=Task(z_range=(0.4, 2.1)),
        angle="degree",
        timestep=0.002,
        integrator="RK4",
        limb_type_names=("thigh", "shin", "upper arm", "lower arm"),
        reference_zeroes_limb_types=True,
    )


# --------------------------------------------------------------------------- cheetahs


def _cheetah_limb(name, parent, pos, damping, range_, stiffness, geom_pos, angle, half, gear, kind):
    return Body(
        name,
        parent,
        pos,
        (Joint(name, _Y_UP, range=range_, damping=damping, stiffness=stiffness),),
        (Geom(name, size=(0.046, half), pos=geom_pos, axisangle=(0, 1, 0, angle)),),
        gear=gear,
        limb_type=kind,
    )


def cheetah_full() -> Robot:
    """cheetah_7_full: the half-cheetah with back and front thigh, shin and foot."""
    torso = Body(
        "torso",
        None,
        pos=(0.0, 0.0, 0.7),
        joints=_root_joints("rootx", "rootz", "rooty", z_ref=0.0, pitch_pos=(0.0, 0.0, 0.0)),
        geoms=(
            Geom("torso", size=(0.046,), fromto=(-0.5, 0, 0, 0.5, 0, 0)),
            Geom("head", size=(0.046, 0.15), pos=(0.6, 0, 0.1), axisangle=(0, 1, 0, 0.87)),
        ),
        limb_type=0,
        cameras=(
            Camera("tilted", (2.9, 3.2, 0.3), _TILTED_XYAXES),
            Camera("track", (0.0, 3.0, 0.3), _TRACK_XYAXES),
        ),
    )
    # fmt: off
    limbs = (
        _cheetah_limb("bthigh", "torso", (-0.5, 0, 0), 6.0, (-0.52, 1.05), 240.0,
                      (0.1, 0, -0.13), -3.8, 0.145, 120.0, 1),
        _cheetah_limb("bshin", "bthigh", (0.16, 0, -0.25), 4.5, (-0.785, 0.785), 180.0,
                      (-0.14, 0, -0.07), -2.03, 0.15, 90.0, 2),
        _cheetah_limb("bfoot", "bshin", (-0.28, 0, -0.14), 3.0, (-0.4, 0.785), 120.0,
                      (0.03, 0, -0.097), -0.27, 0.094, 60.0, 3),
        _cheetah_limb("fthigh", "torso", (0.5, 0, 0), 4.5, (-1.0, 0.7), 180.0,
                      (-0.07, 0, -0.12), 0.52, 0.133, 120.0, 1),
        _cheetah_limb("fshin", "fthigh", (-0.14, 0, -0.24), 3.0, (-1.2, 0.87), 120.0,
                      (0.065, 0, -0.09), -0.6, 0.106, 60.0, 2),
        _cheetah_limb("ffoot", "fshin", (0.13, 0, -0.18), 1.5, (-0.5, 0.5), 60.0,
                      (0.045, 0, -0.07), -0.6, 0.07, 30.0, 3),
    )
    # fmt: on
    return Robot(
        name="cheetah_7_full",
        family="cheetah",
        bodies=(torso, *limbs),
        defaults=Defaults(
            joint_armature=0.1,
            joint_damping=0.01,
            joint_stiffness=8.0,
            joint_solref_limit=(0.02, 1.0),
            joint_solimp_limit=(0.0, 0.8, 0.03),
            geom_friction=(0.4, 0.1, 0.1),
            geom_solimp=(0.0, 0.8, 0.01),
            geom_solref=(0.02, 1.0),
        ),
        floor=Geom("floor", size=(40.0, 40.0, 40.0), type="plane", conaffinity=1, condim=3),
        # algorithm.md §2: Δx/dt - 0.1 Σa², never terminates; reset U(±0.1), N(0, 0.1²).
        task=Task(
            alive_bonus=0.0,
            ctrl_cost=0.1,
            terminates=False,
            max_abs_pitch=None,
            reset_qpos_noise=0.1,
            reset_qvel_noise=0.1,
            reset_qvel_normal=True,
        ),
        angle="radian",
        timestep=0.01,
        integrator="Euler",
        limb_type_names=("torso", "thigh", "shin", "foot"),
    )


# -------------------------------------------------------------------------- registry

_CHEETAH_LIMBS = ("bthigh", "bshin", "bfoot", "fthigh", "fshin", "ffoot")
_CHEETAH_VARIANTS = {  # name -> bodies kept besides the torso
    "cheetah_2_back": ("bthigh",),
    "cheetah_2_front": ("fthigh",),
    "cheetah_3_back": ("bthigh", "bshin"),
    "cheetah_3_balanced": ("bthigh", "fthigh"),
    "cheetah_3_front": ("fthigh", "fshin"),
    "cheetah_4_allback": ("bthigh", "bshin", "bfoot"),
    "cheetah_4_allfront": ("fthigh", "fshin", "ffoot"),
    "cheetah_4_back": ("bthigh", "bshin", "fthigh"),
    "cheetah_4_front": ("bthigh", "fthigh", "fshin"),
    "cheetah_5_back": ("bthigh", "bshin", "bfoot", "fthigh"),
    "cheetah_5_balanced": ("bthigh", "bshin", "fthigh", "fshin"),
    "cheetah_5_front": ("bthigh", "fthigh", "fshin", "ffoot"),
    "cheetah_6_back": ("bthigh", "bshin", "bfoot", "fthigh", "fshin"),
    "cheetah_6_front": ("bthigh", "bshin", "fthigh", "fshin", "ffoot"),
    "cheetah_7_full": _CHEETAH_LIMBS,
}
_HUMANOID_VARIANTS = {  # name -> bodies removed (with their subtrees) from 9_full
    "humanoid_2d_7_left_arm": ("left_upper_arm",),
    "humanoid_2d_7_left_leg": ("left_thigh",),
    "humanoid_2d_7_lower_arms": ("right_lower_arm", "left_lower_arm"),
    "humanoid_2d_7_right_arm": ("right_upper_arm",),
    "humanoid_2d_7_right_leg": ("right_thigh",),
    "humanoid_2d_8_left_knee": ("left_shin",),
    "humanoid_2d_8_right_knee": ("right_shin",),
    "humanoid_2d_9_full": (),
}
# walker_N: (left segments, right segments). The reference's walker_N_flipped files
# are byte-identical to walker_N_main; they are kept as names for SMP's experiments.
_WALKER_LEGS = {2: (1, 0), 3: (1, 1), 4: (2, 1), 5: (2, 2), 6: (3, 2), 7: (3, 3)}
_HOPPERS = {  # name -> (shank segments, torso height, healthy minimum z)
    "hopper_3": (("thigh",), 1.25, 0.45),
    "hopper_4": (("thigh", "leg"), 1.25, 0.6),
    "hopper_5": (("thigh", "leg", "lower_leg"), 1.75, 0.95),
}


def _registry() -> dict[str, Callable[[], Robot]]:
    robots: dict[str, Callable[[], Robot]] = {}
    for n, (left, right) in _WALKER_LEGS.items():
        for kind in ("main", "flipped"):
            name = f"walker_{n}_{kind}"
            robots[name] = lambda name=name, left=left, right=right: walker(name, left, right)
    for name, (segments, torso_z, min_z) in _HOPPERS.items():
        robots[name] = lambda name=name, s=segments, t=torso_z, z=min_z: hopper(name, s, t, z)
    for name, removed in _HUMANOID_VARIANTS.items():
        robots[name] = lambda name=name, r=removed: humanoid_2d_full().without(*r, name=name)
    for name, kept in _CHEETAH_VARIANTS.items():
        removed = tuple(b for b in _CHEETAH_LIMBS if b not in kept)
        robots[name] = lambda name=name, r=removed: cheetah_full().without(*r, name=name)
    return dict(sorted(robots.items()))


ROBOTS: dict[str, Callable[[], Robot]] = _registry()
"""Every named robot: name -> a function building its description."""
