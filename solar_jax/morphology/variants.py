"""Dynamics and kinematics variants of a robot: the same tree, other numbers.

The SOLAR paper's zero-shot variants (appendix, "Dynamics and kinematics variations",
MetaMorph's ranges), per limb:

    armature      [0.1, 2]              each limb hinge's, absolute
    density       [0.8, 1.2] x          each body's geoms (the torso's too)
    damping       [0.01, 5.0]           each limb hinge's, absolute
    gear          [0.8, 1.2] x          each motor's
    limb_radius   [0.03, 0.05]          each limb's capsule, absolute
    limb_height   [0.15, 0.45]          each limb's capsule, its full length, absolute
    joint_range   one of 13 ranges      each limb hinge's, degrees

A variant is an edited MJCF (``mujoco.MjSpec``) compiled by MuJoCo C, so every quantity
MuJoCo derives at compile time (masses and inertias from density and shape, inertial
frames of multi-geom bodies, ``invweight0``, bounding volumes) is MuJoCo's own. A
longer or shorter limb keeps its joint end: its capsule's far end, its child bodies and
its other geoms move along the capsule's axis in proportion. A robot whose legs changed
is lifted or lowered so that its lowest point at ``qpos0`` stays where the nominal
robot's is (it starts standing, neither in the floor nor in the air); its root slide
keeps its ``ref``, so the task's height bounds stay relative to where it stands.

Draws are per limb and deterministic: property ``p``'s draws for variant ``k`` of robot
``name`` come from ``seed``, ``name``, ``p`` and ``k`` alone, so a variant of all
properties carries the same armature as the armature-only variant of that index.
"""

import dataclasses
import warnings
import zlib

import mujoco
import numpy as np

from solar_jax.morphology.morphology import Morphology, drop_textures

DYNAMICS = ("armature", "density", "damping", "gear")
KINEMATICS = ("limb_radius", "limb_height", "joint_range")
PROPERTIES = DYNAMICS + KINEMATICS
GROUPS = {"dynamics": DYNAMICS, "kinematics": KINEMATICS, "all": PROPERTIES}
SCALED = ("density", "gear")  # factors of the robot's own value; the rest are absolute
JOINT_RANGES = (
    (-30, 0), (0, 30), (-30, 30), (-45, 45), (-45, 0), (0, 45), (-60, 0),
    (0, 60), (-60, 60), (-90, 0), (0, 90), (-60, 30), (-30, 60),
)  # fmt: skip
DIGITS = 6  # draws are rounded to this many significant digits: the MJCF text holds them


class VariationError(ValueError):
    """A variation that cannot be built; the message names the property and the problem."""


@dataclasses.dataclass(frozen=True)
class Variation:
    """The ranges variants are drawn from (the paper's table by default), uniform per limb.

    ``joint_range`` is a list of (low, high) degree ranges, one drawn per hinge."""

    armature: tuple[float, float] = (0.1, 2.0)
    density: tuple[float, float] = (0.8, 1.2)
    damping: tuple[float, float] = (0.01, 5.0)
    gear: tuple[float, float] = (0.8, 1.2)
    limb_radius: tuple[float, float] = (0.03, 0.05)
    limb_height: tuple[float, float] = (0.15, 0.45)
    joint_range: tuple[tuple[float, float], ...] = JOINT_RANGES

    def __post_init__(self):
        for name in PROPERTIES[:-1]:
            low, high = getattr(self, name)
            if not (np.isfinite(low) and np.isfinite(high)) or low > high:
                raise VariationError(f"variation {name}: range {low:g}:{high:g} is not low <= high")
            if low < 0 or (low == 0 and name != "damping"):
                raise VariationError(f"variation {name}: range {low:g}:{high:g} must be positive")
        if not self.joint_range:
            raise VariationError("variation joint_range: no ranges to draw from")
        for low, high in self.joint_range:
            if not -180 <= low < high <= 180:
                raise VariationError(
                    f"variation joint_range: {low:g}:{high:g} is not -180 <= low < high <= 180"
                )

    @classmethod
    def parse(cls, text: str) -> tuple["Variation", tuple[str, ...]]:
        """``"dynamics,limb_height=0.2:0.4,joint_range=-45:45/0:60"`` -> the variation and
        the properties named (groups expanded, in ``PROPERTIES`` order)."""
        ranges, chosen = {}, set()
        for item in filter(None, (part.strip() for part in text.split(","))):
            name, _, value = item.partition("=")
            if name in GROUPS and not value:
                chosen.update(GROUPS[name])
                continue
            if name not in PROPERTIES:
                valid = ", ".join((*GROUPS, *PROPERTIES))
                raise VariationError(f"unknown variation property '{name}'; valid: {valid}")
            chosen.add(name)
            if value:
                ranges[name] = _parse_range(name, value)
        if not chosen:
            raise VariationError("no variation property named; valid: " + ", ".join(GROUPS))
        return cls(**ranges), tuple(p for p in PROPERTIES if p in chosen)


def _parse_range(name: str, text: str):
    def pair(part: str) -> tuple[float, float]:
        try:
            low, high = (float(x) for x in part.split(":"))
        except ValueError:
            raise VariationError(f"variation {name}: '{part}' is not low:high") from None
        return low, high

    if name == "joint_range":
        return tuple(pair(part) for part in text.split("/"))
    return pair(text)


@dataclasses.dataclass(frozen=True, eq=False)
class Variant:
    """One variant: the robot with its edited MJCF (``morph.xml``, without the nominal
    robot's textures: its floor and sky draw in their materials' colours) and the model
    MuJoCo compiles from it."""

    morph: Morphology  # same name, tree, task and agents as the nominal robot
    properties: tuple[str, ...]  # what varies
    index: int  # k of ``make_variants``
    draws: dict[str, np.ndarray]  # property -> per-limb values (joint_range: [L, 2] degrees)


def draw(morph: Morphology, variation: Variation, prop: str, index: int, seed: int) -> np.ndarray:
    """Property ``prop``'s per-limb values for variant ``index`` (``[L]``, or ``[L, 2]``
    degrees for ``joint_range``; L = limbs, the torso too for density)."""
    limbs = morph.num_agents - (0 if prop == "density" else 1)
    entropy = [seed, zlib.crc32(morph.name.encode()), PROPERTIES.index(prop), index]
    rng = np.random.default_rng(np.random.SeedSequence(entropy))
    if prop == "joint_range":
        choices = np.asarray(variation.joint_range, np.float64)
        return choices[rng.integers(len(choices), size=limbs)]
    low, high = getattr(variation, prop)
    values = rng.uniform(low, high, size=limbs)
    return np.array([float(f"{v:.{DIGITS}g}") for v in values])


def make_variants(
    morph: Morphology,
    properties: tuple[str, ...],
    count: int,
    seed: int = 0,
    variation: Variation | None = None,
) -> list[Variant]:
    """``count`` variants of ``morph`` in which every property of ``properties`` varies."""
    variation = variation or Variation()
    unknown = [p for p in properties if p not in PROPERTIES]
    if unknown:
        raise VariationError(f"unknown variation properties {unknown}; valid: {PROPERTIES}")
    if count < 1:
        raise VariationError(f"variant count must be >= 1, got {count}")
    out = []
    for k in range(count):
        draws = {p: draw(morph, variation, p, k, seed) for p in properties}
        out.append(Variant(edit(morph, draws), tuple(properties), k, draws))
    return out


def edit(morph: Morphology, draws: dict[str, np.ndarray]) -> Morphology:
    """``morph`` with ``draws`` (``draw``'s values per property) written into its MJCF."""
    spec = mujoco.MjSpec.from_string(morph.xml)
    drop_textures(spec)  # as the physics' model; writing them out costs 0.1 s a variant
    bodies = [spec.body(name) for name in morph.agents]
    joints = [None] + [spec.joint(name) for name in morph.joints[1:]]
    actuators = {a.target: a for a in spec.actuators}
    limbs = range(1, morph.num_agents)
    angle = np.deg2rad if not spec.compiler.degree else (lambda x: np.asarray(x, float))
    if "armature" in draws:
        for i in limbs:
            joints[i].armature = draws["armature"][i - 1]
    if "damping" in draws:
        for i in limbs:
            damping = np.array(joints[i].damping)
            damping[0] = draws["damping"][i - 1]
            joints[i].damping = damping
    if "gear" in draws:
        for i in limbs:
            motor = actuators[morph.joints[i]]
            motor.gear = np.asarray(motor.gear) * np.array([draws["gear"][i - 1], 1, 1, 1, 1, 1])
    if "density" in draws:
        for i, body in enumerate(bodies):
            _scale_density(morph, body, draws["density"][i])
    if "joint_range" in draws:
        for i in limbs:
            joints[i].range = angle(draws["joint_range"][i - 1])
    reshaped = "limb_radius" in draws or "limb_height" in draws
    if reshaped:
        for i in limbs:
            _reshape_limb(
                morph,
                i,
                bodies[i],
                draws.get("limb_radius", [None] * morph.num_agents)[i - 1],
                draws.get("limb_height", [None] * morph.num_agents)[i - 1],
            )
    if reshaped:  # stand on the floor as the nominal robot does (module docstring)
        lift = _lowest(morph.model) - _lowest(_compile(spec.to_xml(), morph.name))
        bodies[0].pos = np.asarray(bodies[0].pos) + [0.0, 0.0, lift]
    xml = spec.to_xml()
    model = _compile(xml, morph.name)  # the text's model: what any MJCF reader of it gets
    joint_range = morph.joint_range.copy()
    joint_range[1:] = np.rad2deg(model.jnt_range[[model.joint(j).id for j in morph.joints[1:]]])
    return dataclasses.replace(morph, xml=xml, model=model, joint_range=joint_range)


def _compile(xml: str, name: str) -> mujoco.MjModel:
    spec = mujoco.MjSpec.from_string(xml)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            return spec.compile()
        except ValueError as err:
            raise VariationError(f"{name}: the variant does not compile: {err}") from None


def _scale_density(morph: Morphology, body: mujoco.MjsBody, factor: float) -> None:
    if body.explicitinertial:  # an <inertial> element: MuJoCo takes its mass as given
        body.mass *= factor
        body.inertia = np.asarray(body.inertia) * factor
        return
    for geom in body.geoms:
        if np.isnan(geom.mass):
            geom.density *= factor
        else:
            geom.mass *= factor


_ROUND = (int(mujoco.mjtGeom.mjGEOM_CAPSULE), int(mujoco.mjtGeom.mjGEOM_CYLINDER))


def _reshape_limb(morph: Morphology, agent: int, body: mujoco.MjsBody, radius, height) -> None:
    """Limb ``agent``'s first capsule (or cylinder) to ``radius`` and full length
    ``height`` (``None``: unchanged), its joint end fixed (module docstring)."""
    model = morph.model
    b = agent + 1  # MuJoCo body id (agent i = body i + 1)
    geoms = range(model.body_geomadr[b], model.body_geomadr[b] + model.body_geomnum[b])
    main = next((g for g in geoms if int(model.geom_type[g]) in _ROUND), None)
    if main is None:
        raise VariationError(
            f"{morph.name}: limb '{morph.agents[agent]}' has no capsule or cylinder to resize"
        )
    spec_geoms = list(body.geoms)
    geom = spec_geoms[main - model.body_geomadr[b]]
    half = float(model.geom_size[main, 1])
    center = model.geom_pos[main].copy()
    axis = np.zeros(3)
    mujoco.mju_rotVecQuat(axis, np.array([0.0, 0.0, 1.0]), model.geom_quat[main])
    joint = model.jnt_pos[model.body_jntadr[b]]
    ends = center + np.outer([-half, half], axis)
    near = int(np.argmin(np.linalg.norm(ends - joint, axis=1)))
    start, direction = ends[near], axis * (1.0 if near == 0 else -1.0)
    size = np.array(geom.size)
    size[:2] = model.geom_size[main, :2]
    if radius is not None:
        size[0] = radius
    if height is None:
        _place(geom, center, model.geom_quat[main])
        geom.size = size
        return
    stretch = 0.5 * height / half

    def moved(point: np.ndarray) -> np.ndarray:
        along = float(np.dot(point - start, direction))
        return point + (stretch - 1.0) * max(along, 0.0) * direction

    size[1] = 0.5 * height
    _place(geom, start + 0.5 * height * direction, model.geom_quat[main])
    geom.size = size
    for g, other in zip(geoms, spec_geoms, strict=True):
        if g != main:
            _place(other, moved(model.geom_pos[g]), model.geom_quat[g])
    for child in body.bodies:
        child.pos = moved(np.asarray(child.pos, float))
    for site in body.sites:
        site.pos = moved(np.asarray(site.pos, float))


def _place(geom: mujoco.MjsGeom, pos: np.ndarray, quat: np.ndarray) -> None:
    """``geom`` at ``pos`` and ``quat`` in its body's frame, as MuJoCo compiled it: any
    ``fromto`` or other orientation of the MJCF replaced."""
    geom.fromto = np.full(6, np.nan)
    geom.alt.type = mujoco.mjtOrientation.mjORIENTATION_QUAT
    geom.pos, geom.quat = pos, quat


def _lowest(model: mujoco.MjModel) -> float:
    """The lowest point of the robot's geoms (not the world's) at ``qpos0``."""
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    low = np.inf
    for g in range(model.ngeom):
        if model.geom_bodyid[g] == 0:
            continue
        z = data.geom_xpos[g, 2]
        up = data.geom_xmat[g].reshape(3, 3)[2]  # world z of the geom's local axes
        size, kind = model.geom_size[g], int(model.geom_type[g])
        if kind == int(mujoco.mjtGeom.mjGEOM_SPHERE):
            reach = size[0]
        elif kind == int(mujoco.mjtGeom.mjGEOM_CAPSULE):
            reach = size[0] + abs(up[2]) * size[1]
        elif kind == int(mujoco.mjtGeom.mjGEOM_CYLINDER):
            reach = abs(up[2]) * size[1] + size[0] * np.sqrt(max(0.0, 1.0 - up[2] ** 2))
        elif kind == int(mujoco.mjtGeom.mjGEOM_BOX):
            reach = float(np.abs(up) @ size)
        else:
            reach = float(model.geom_rbound[g])
        low = min(low, z - reach)
    return float(low)
