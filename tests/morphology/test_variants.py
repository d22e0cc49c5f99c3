"""Robot variants: the draws land in the MJCF as the paper's table says, MuJoCo C's
compile of that MJCF has the masses, inertias and positions geometry implies, and bad
variations are one line."""

import mujoco
import numpy as np
import pytest

from solar_jax.morphology import from_model, load
from solar_jax.morphology.variants import (
    JOINT_RANGES,
    PROPERTIES,
    Variation,
    VariationError,
    draw,
    make_variants,
)

ROBOTS = ("hopper_3", "walker_7_main", "humanoid_2d_9_full")
DIGITS6 = 5e-6  # relative: MuJoCo writes MJCF numbers to 6 significant digits
POSITION = 2e-6  # metres: 6 significant digits of a robot's sizes


def _compiled(variant) -> mujoco.MjModel:
    """MuJoCo C's model of the variant's MJCF text, read as any MJCF file is."""
    return mujoco.MjModel.from_xml_string(variant.morph.xml)


def _limb_joints(morph, model):
    return np.array([model.joint(name).id for name in morph.joints[1:]])


@pytest.mark.parametrize("name", ROBOTS)
def test_dynamics_draws_land_in_the_compiled_model(name):
    morph = load(name)
    nominal = morph.model
    for variant in make_variants(morph, ("armature", "damping", "gear", "joint_range"), 3, seed=4):
        model, d = _compiled(variant), variant.draws
        joints = _limb_joints(morph, model)
        dofs = model.jnt_dofadr[joints]
        np.testing.assert_allclose(model.dof_armature[dofs], d["armature"], rtol=1e-12)
        np.testing.assert_allclose(model.dof_damping[dofs], d["damping"], rtol=1e-12)
        motors = morph.actuators[1:]
        np.testing.assert_allclose(
            model.actuator_gear[motors, 0],
            nominal.actuator_gear[motors, 0] * d["gear"],
            rtol=DIGITS6,
        )
        # The MJCF holds radians to 6 digits, as the registry robots' own (60.00014 degrees).
        np.testing.assert_allclose(np.rad2deg(model.jnt_range[joints]), d["joint_range"], atol=3e-4)
        np.testing.assert_allclose(variant.morph.joint_range[1:], d["joint_range"], atol=3e-4)
        assert {tuple(r) for r in d["joint_range"]} <= set(JOINT_RANGES)
        for key, (low, high) in {"armature": (0.1, 2.0), "damping": (0.01, 5.0)}.items():
            assert (low <= d[key]).all() and (d[key] <= high).all()
        # Nothing else moved: same masses, inertias and geometry.
        for field in ("body_mass", "body_inertia", "body_pos", "geom_size", "geom_pos"):
            np.testing.assert_array_equal(getattr(model, field), getattr(nominal, field))


@pytest.mark.parametrize("name", ROBOTS)
def test_density_scales_each_body_s_mass_and_inertia(name):
    morph = load(name)
    for variant in make_variants(morph, ("density",), 2, seed=1):
        model, factor = _compiled(variant), variant.draws["density"]
        assert (
            factor.shape == (morph.num_agents,) and (0.8 <= factor).all() and (factor <= 1.2).all()
        )
        bodies = np.arange(1, morph.num_agents + 1)
        np.testing.assert_allclose(
            model.body_mass[bodies], morph.model.body_mass[bodies] * factor, rtol=DIGITS6
        )
        np.testing.assert_allclose(
            model.body_inertia[bodies],
            morph.model.body_inertia[bodies] * factor[:, None],
            rtol=DIGITS6,
        )
        np.testing.assert_allclose(model.body_ipos, morph.model.body_ipos, atol=1e-12)


def _capsule_mass(radius, half_length, density=1000.0):
    return density * np.pi * radius**2 * (2 * half_length + 4.0 / 3.0 * radius)


@pytest.mark.parametrize("name", ROBOTS)
def test_reshaped_limbs_have_the_drawn_size_and_the_mass_of_their_geometry(name):
    """The limb capsule has the drawn radius and full length; a single-capsule limb's
    mass is the capsule's (density 1000); its far end and everything beyond moved with
    it, its joint end did not; the robot still stands with its lowest point where the
    nominal robot's is."""
    morph = load(name)
    for variant in make_variants(morph, ("limb_radius", "limb_height"), 3, seed=2):
        model, d = _compiled(variant), variant.draws
        for i in range(1, morph.num_agents):
            b = i + 1
            first = model.body_geomadr[b]
            capsule = next(
                g
                for g in range(first, first + model.body_geomnum[b])
                if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_CAPSULE
            )
            radius, half = model.geom_size[capsule, :2]
            assert radius == pytest.approx(d["limb_radius"][i - 1], rel=1e-9)
            assert 2 * half == pytest.approx(d["limb_height"][i - 1], rel=DIGITS6)
            if model.body_geomnum[b] == 1:
                assert model.body_mass[b] == pytest.approx(_capsule_mass(radius, half), rel=1e-6)
            # The joint end stays at the joint's distance; the capsule grows from it.
            axis = np.zeros(3)
            mujoco.mju_rotVecQuat(axis, np.array([0.0, 0, 1]), model.geom_quat[capsule])
            ends = model.geom_pos[capsule] + np.outer([-half, half], axis)
            nominal_ends = morph.model.geom_pos[capsule] + np.outer(
                [-1, 1], morph.model.geom_size[capsule, 1] * axis
            )
            joint = model.jnt_pos[model.body_jntadr[b]]
            near = np.argmin(np.linalg.norm(nominal_ends - joint, axis=1))
            np.testing.assert_allclose(ends[near], nominal_ends[near], atol=POSITION)
            # A child attached at the nominal far end is attached at the new one.
            for child in np.flatnonzero(morph.model.body_parentid == b):
                if np.allclose(morph.model.body_pos[child], nominal_ends[1 - near], atol=1e-6):
                    np.testing.assert_allclose(model.body_pos[child], ends[1 - near], atol=POSITION)
        assert _lowest_point(model) == pytest.approx(_lowest_point(morph.model), abs=1e-5)


def _lowest_point(model) -> float:
    """The robot's lowest surface point at qpos0, from MuJoCo's own collision test: the
    signed distance of every robot geom to the floor plane."""
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    floor = next(g for g in range(model.ngeom) if model.geom_bodyid[g] == 0)
    distances = [
        mujoco.mj_geomDistance(model, data, floor, g, 10.0, None)
        for g in range(model.ngeom)
        if model.geom_bodyid[g] > 0
    ]
    return min(distances) + float(model.geom_pos[floor, 2])


def test_the_walker_limb_chain_stays_connected():
    """walker_7_main's legs: each child hangs at the end of its parent's capsule."""
    morph = load("walker_7_main")
    (variant,) = make_variants(morph, ("limb_height",), 1, seed=3)
    model = _compiled(variant)
    for parent, child in [("left1", "left2"), ("left2", "left3"), ("right1", "right2")]:
        height = variant.draws["limb_height"][morph.agents.index(parent) - 1]
        np.testing.assert_allclose(model.body(child).pos, [0, 0, -height], atol=POSITION)


def test_variants_are_deterministic_by_seed_and_per_property():
    morph = load("walker_7_main")
    first = make_variants(morph, PROPERTIES, 3, seed=7)
    again = make_variants(morph, PROPERTIES, 3, seed=7)
    other = make_variants(morph, PROPERTIES, 3, seed=8)
    assert [v.morph.xml for v in first] == [v.morph.xml for v in again]
    assert all(a.morph.xml != b.morph.xml for a, b in zip(first, other, strict=True))
    assert len({v.morph.xml for v in first}) == 3
    # A property's draws do not depend on which others vary with it.
    (alone,) = make_variants(morph, ("armature",), 1, seed=7)
    np.testing.assert_array_equal(alone.draws["armature"], first[0].draws["armature"])
    # ... nor on the robot's company: they are keyed by its name.
    np.testing.assert_array_equal(draw(morph, Variation(), "gear", 2, 7), first[2].draws["gear"])


def test_a_variant_keeps_the_robot_s_identity():
    morph = load("hopper_3")
    (variant,) = make_variants(morph, PROPERTIES, 1)
    v = variant.morph
    assert (v.name, v.agents, v.parents, v.joints, v.task) == (
        morph.name,
        morph.agents,
        morph.parents,
        morph.joints,
        morph.task,
    )
    np.testing.assert_array_equal(v.actuators, morph.actuators)
    np.testing.assert_array_equal(v.qpos_adr, morph.qpos_adr)
    np.testing.assert_array_equal(v.model.qpos0, morph.model.qpos0)


def test_parse_names_groups_properties_and_ranges():
    variation, props = Variation.parse("dynamics,limb_height=0.2:0.4,joint_range=-45:45/0:60")
    assert props == ("armature", "density", "damping", "gear", "limb_height", "joint_range")
    assert variation.limb_height == (0.2, 0.4) and variation.armature == (0.1, 2.0)
    assert variation.joint_range == ((-45.0, 45.0), (0.0, 60.0))
    assert Variation.parse("all")[1] == PROPERTIES


@pytest.mark.parametrize(
    "text, message",
    [
        ("density=-0.5:1.2", "variation density: range -0.5:1.2 must be positive"),
        ("armature=2:0.1", "variation armature: range 2:0.1 is not low <= high"),
        ("stiffness", "unknown variation property 'stiffness'; valid: dynamics, kinematics"),
        ("gear=1.1", "variation gear: '1.1' is not low:high"),
        ("joint_range=30:-30", "variation joint_range: 30:-30 is not -180 <= low < high <= 180"),
        ("", "no variation property named"),
    ],
)
def test_bad_variations_are_one_line(text, message):
    with pytest.raises(VariationError) as err:
        Variation.parse(text)
    assert str(err.value).startswith(message) and "\n" not in str(err.value)


def test_bad_counts_and_unshapeable_limbs_are_one_line():
    morph = load("hopper_3")
    with pytest.raises(VariationError, match="variant count must be >= 1, got 0"):
        make_variants(morph, ("armature",), 0)
    with pytest.raises(VariationError, match="unknown variation properties"):
        make_variants(morph, ("mass",), 1)
    boxy = morph.xml.replace(
        'name="thigh_geom" size="0.05 0.225"', 'name="thigh_geom" size="0.05 0.05 0.225"'
    )
    boxy = boxy.replace('pos="0 0 -0.225" type="capsule"', 'pos="0 0 -0.225" type="box"', 1)
    model = mujoco.MjModel.from_xml_string(boxy)
    robot = from_model(model, boxy, name="boxy", source="test", task=morph.task)
    with pytest.raises(VariationError, match="limb 'thigh' has no capsule or cylinder to resize"):
        make_variants(robot, ("limb_radius",), 1)
