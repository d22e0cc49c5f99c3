"""The robots built from code are the reference's robots (algorithm.md §1)."""

from collections import Counter

import mujoco
import numpy as np
import pytest

from solar_jax.morphology import ROBOTS, load, write_all
from tests.conftest import REPO
from tests.morphology.reference import COMPARED_FIELDS, field_errors, world_pose_error

# Measured: every compared field is bit-identical to the reference (error 0.0) for all
# 38 robots; the tolerance only absorbs float noise of other platforms' compilers.
TOLERANCE = 1e-9


def test_registry_holds_the_38_reference_robots():
    families = Counter(name.split("_")[0] for name in ROBOTS)
    assert families == {"walker": 12, "hopper": 3, "humanoid": 8, "cheetah": 15}
    assert sum(name.endswith("_main") for name in ROBOTS) == 6
    assert sum(name.endswith("_flipped") for name in ROBOTS) == 6


@pytest.mark.parametrize("name", list(ROBOTS))
def test_built_robot_equals_reference_file(name, reference_dir):
    ours = load(name).model
    reference = mujoco.MjModel.from_xml_path(str(reference_dir / f"{name}.xml"))
    errors = field_errors(ours, reference)
    errors["world poses at qpos0"] = world_pose_error(ours, reference)
    assert {k: v for k, v in errors.items() if v > TOLERANCE} == {}
    assert len(errors) == len(COMPARED_FIELDS) + 11 + 1


def test_committed_files_equal_a_fresh_build(tmp_path):
    fresh = {p.name: p.read_text() for p in write_all(tmp_path)}
    committed = {p.name: p.read_text() for p in (REPO / "morphologies").glob("*.xml")}
    assert sorted(committed) == sorted(fresh)
    stale = [name for name in fresh if committed[name] != fresh[name]]
    assert stale == [], "run: python -m solar_jax.morphology build"


def test_the_tests_euler_hopper_is_hopper_3_but_for_the_integrator():
    """``tests/robots/hopper_3_euler.xml`` (the trainer tests' robot, ``tests.tiny``)."""
    from tests.tiny import ROBOT

    ours, hopper = load(ROBOT).model, load("hopper_3").model
    assert ours.opt.integrator == mujoco.mjtIntegrator.mjINT_EULER
    assert hopper.opt.integrator == mujoco.mjtIntegrator.mjINT_RK4
    hopper.opt.integrator = mujoco.mjtIntegrator.mjINT_EULER
    assert {k: v for k, v in field_errors(ours, hopper).items() if v > 0} == {}
    assert world_pose_error(ours, hopper) == 0


def test_building_twice_gives_identical_text():
    from solar_jax.morphology import build_xml

    assert build_xml("humanoid_2d_9_full") == build_xml("humanoid_2d_9_full")


# algorithm.md §1: masses under modern MuJoCo (exact capsule inertia), per limb kind.
REFERENCE_MASSES = {
    "walker_7_main": [10.673, 5.465, 2.798, 3.167, 5.465, 2.798, 3.167],
    "hopper_5": [3.665, 4.058, 2.781, 2.781, 5.316],
    "humanoid_2d_9_full": [17.786, 4.752, 4.523, 4.752, 4.523, 1.661, 1.23, 1.661, 1.23],
}


@pytest.mark.parametrize("name", list(REFERENCE_MASSES))
def test_body_masses_match_spec(name):
    np.testing.assert_allclose(load(name).model.body_mass[1:], REFERENCE_MASSES[name], atol=6e-4)


def test_physics_settings_match_spec():
    for name in ROBOTS:
        opt = load(name).model.opt
        if name.startswith("cheetah"):
            assert (opt.timestep, opt.integrator) == (0.01, mujoco.mjtIntegrator.mjINT_EULER)
        else:
            assert (opt.timestep, opt.integrator) == (0.002, mujoco.mjtIntegrator.mjINT_RK4)


def test_geometry_facts_from_spec():
    walker = load("walker_7_main").model
    # MJCF is written with 6 significant digits: 75 degrees is stored as 1.309 rad.
    np.testing.assert_allclose(np.rad2deg(walker.jnt_range[3:]), [[-75, 75]] * 6, atol=1e-3)
    np.testing.assert_allclose(walker.jnt_axis[3:], [[0, -1, 0]] * 6)
    np.testing.assert_allclose(walker.actuator_gear[:, 0], 100)
    np.testing.assert_allclose(walker.dof_armature[3:], 0.01)
    np.testing.assert_allclose(walker.geom_friction[1:, 0], 0.9)
    assert walker.qpos0[1] == 1.25  # rootz ref
    hopper = load("hopper_5").model
    assert hopper.body_pos[1, 2] == 1.75
    np.testing.assert_allclose(hopper.geom_solimp[1:, :3], [[0.8, 0.8, 0.01]] * 5)
    np.testing.assert_array_equal(hopper.geom_condim[1:], 1)
    np.testing.assert_allclose(hopper.geom_friction[-1, 0], 2.0)
    np.testing.assert_allclose(hopper.body_pos[-1], [0.065, 0, -0.25])  # "0.13/2" read as 0.065
    humanoid = load("humanoid_2d_9_full").model
    np.testing.assert_allclose(
        humanoid.actuator_gear[:, 0], [150, 100, 150, 100, 12.5, 12.5, 12.5, 12.5]
    )
    np.testing.assert_allclose(np.rad2deg(humanoid.jnt_range[3]), [-110, 20], atol=1e-3)
    np.testing.assert_allclose(humanoid.jnt_stiffness[3], 20)


@pytest.mark.parametrize("name", list(ROBOTS))
def test_robot_steps_in_mujoco_without_nan(name):
    model = load(name).model
    data = mujoco.MjData(model)
    rng = np.random.default_rng(0)
    for _ in range(50):
        data.ctrl[:] = rng.uniform(-1, 1, model.nu)
        mujoco.mj_step(model, data)
    assert np.isfinite(data.qpos).all() and np.isfinite(data.qvel).all()
