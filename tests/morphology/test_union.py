"""Unions against MuJoCo C: every registered robot, stepped as a variant of its union's
model, moves as its own model does; the union's other bodies never move or touch."""

import functools

import mujoco
import numpy as np
import pytest

from solar_jax.morphology import ROBOTS, load
from solar_jax.morphology.union import (
    DUMMY_MARGIN,
    build_union,
    embed,
    plan_unions,
    robot_model,
)

STEPS = 120  # env steps of random actions, 4 physics steps each: falls and contacts


@functools.cache
def _unions(grow: bool):
    """Every registered robot in unions: one per physics setting (``grow``), or a union
    per family."""
    robots = tuple(load(name) for name in ROBOTS)
    groups = plan_unions(robots, grow)
    return [build_union(tuple(robots[i] for i in group), grow) for group in groups]


def _place(name, grow):
    for union in _unions(grow):
        for k, robot in enumerate(union.robots):
            if robot.name == name:
                return union, k
    raise AssertionError(name)


def test_every_registered_robot_joins_its_family_s_largest():
    hosts = {u.robots[0].name: sorted(r.name for r in u.robots) for u in _unions(False)}
    assert set(hosts) == {"humanoid_2d_9_full", "walker_7_flipped", "hopper_5", "cheetah_7_full"}
    assert sum(len(v) for v in hosts.values()) == len(ROBOTS)
    for host, members in hosts.items():
        family = host.split("_")[0]
        assert all(name.startswith(family) for name in members), members


def test_a_grown_union_holds_every_robot_of_its_physics_and_keeps_families_apart():
    unions = _unions(True)
    assert [(u.robots[0].name, len(u.robots)) for u in unions] == [
        ("humanoid_2d_9_full", 23),  # walkers and hoppers too: RK4 at 0.002 s
        ("cheetah_7_full", 15),  # Euler at 0.01 s
    ]
    union = unions[0]
    assert (union.model.nbody, union.model.nv) == (13, 14)  # the torso, chains of 4, 3, 2, 2
    # Each family's geoms on a bit of their own: hoppers' collide with each other and the
    # floor, walkers' and humanoids' only with the floor, never across families.
    bits = {}
    for robot, emb in zip(union.robots, union.embeddings, strict=True):
        limbs = emb.geom[robot.model.geom_bodyid > 0]
        model = union.model
        pairs = set(zip(model.geom_contype[limbs], model.geom_conaffinity[limbs], strict=True))
        assert len(pairs) == 1, robot.name
        bits[robot.family] = pairs.pop()
    assert bits == {"hopper": (2, 2), "walker": (1, 0), "humanoid_2d": (1, 0)}
    assert (union.model.geom_contype[0], union.model.geom_conaffinity[0]) == (3, 3)  # floor


@pytest.mark.parametrize("grow", [False, True])
def test_embeddings_keep_each_robot_s_order_and_types(grow):
    for union in _unions(grow):
        for robot, emb in zip(union.robots, union.embeddings, strict=True):
            model = robot.model
            for axis in (emb.body, emb.jnt, emb.dof, emb.qpos, emb.geom):
                assert (np.diff(axis) > 0).all()
            # A grown union's attached motors come after its host's (their joints' order
            # is the tree's): each dof has one, so their order changes no sum.
            assert len(set(emb.actuator)) == len(emb.actuator)
            # Parents map to parents; joints, geoms and motors to their own kinds.
            np.testing.assert_array_equal(
                union.model.body_parentid[emb.body[1:]], emb.body[model.body_parentid[1:]]
            )
            np.testing.assert_array_equal(union.model.jnt_type[emb.jnt], model.jnt_type)
            np.testing.assert_array_equal(union.model.geom_type[emb.geom], model.geom_type)
            np.testing.assert_array_equal(
                union.model.actuator_trnid[emb.actuator, 0], emb.jnt[model.actuator_trnid[:, 0]]
            )


def test_a_robot_that_does_not_fit_is_refused():
    hopper, walker = load("hopper_3"), load("walker_7_main")
    assert embed(hopper, walker.model) is None  # hoppers' geoms collide with each other
    assert embed(walker, load("hopper_5").model) is None  # two legs in one
    assert embed(load("cheetah_2_back"), walker.model) is None  # Euler at 0.01 s
    with pytest.raises(ValueError, match="hopper_3 does not embed in walker_7_main's tree"):
        build_union((walker, hopper))


def _settled(model):
    model.opt.iterations, model.opt.ls_iterations = 4, 8  # the env's solver settings
    # MuJoCo C's within-body culling: off in the robot's union model (``robot_model``).
    model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_MIDPHASE
    return model


def _rows(contact) -> int:
    return 1 if contact.dim == 1 else 2 * (contact.dim - 1)  # pyramidal cone


@pytest.mark.parametrize("grow", [False, True], ids=["family", "grown"])
@pytest.mark.parametrize("name", list(ROBOTS))
def test_the_union_steps_each_robot_as_its_own_model(name, grow):
    union, k = _place(name, grow)
    robot, emb = union.robots[k], union.embeddings[k]
    own, joint = _settled(robot.model), _settled(robot_model(union, k))
    alone, inside = mujoco.MjData(own), mujoco.MjData(joint)
    rng = np.random.default_rng(0)
    alone.qpos[:] = own.qpos0 + rng.uniform(-0.005, 0.005, own.nq)
    dummy_qpos = np.setdiff1d(np.arange(joint.nq), emb.qpos)
    dummy_dofs = np.setdiff1d(np.arange(joint.nv), emb.dof)
    dummy_geoms = set(np.setdiff1d(np.arange(joint.ngeom), emb.geom).tolist())
    open_loop, one_step = 0.0, 0.0
    follower = mujoco.MjData(joint)
    follower.qpos[emb.qpos] = alone.qpos
    for _ in range(STEPS):
        # From the robot's own state: one step's physics, no accumulated chaos.
        inside.qpos[:], inside.qvel[:] = 0.0, 0.0
        inside.qpos[emb.qpos], inside.qvel[emb.dof] = alone.qpos, alone.qvel
        inside.qacc_warmstart[:] = 0.0
        inside.qacc_warmstart[emb.dof] = alone.qacc_warmstart
        action = rng.uniform(-1, 1, own.nu)
        alone.ctrl[:] = action
        inside.ctrl[:] = follower.ctrl[:] = 0.0
        inside.ctrl[emb.actuator] = follower.ctrl[emb.actuator] = action
        for _ in range(robot.task.frame_skip):
            for model, data in ((own, alone), (joint, inside), (joint, follower)):
                mujoco.mj_step(model, data)
            for c in follower.contact[: follower.ncon]:  # a dummy's contacts push nothing
                if set(c.geom.tolist()) & dummy_geoms and c.efc_address >= 0:
                    rows = slice(c.efc_address, c.efc_address + _rows(c))
                    assert (follower.efc_force[rows] == 0).all()
        one_step = max(one_step, np.abs(inside.qpos[emb.qpos] - alone.qpos).max())
        open_loop = max(open_loop, np.abs(follower.qpos[emb.qpos] - alone.qpos).max())
        assert (follower.qpos[dummy_qpos] == 0).all() and (follower.qvel[dummy_dofs] == 0).all()
    assert one_step < 1e-12, f"one step: {one_step:.2e}"
    rk4 = own.opt.integrator == mujoco.mjtIntegrator.mjINT_RK4
    if rk4 and not grow and (emb.dof == np.arange(own.nv)).all():
        # No dummy between an RK4 robot's dofs: MuJoCo C's arithmetic is the robot's own,
        # bit for bit. Elsewhere sums run over the union's dofs in another order (the
        # cheetahs' Euler constraint solve: 1e-13 in one step, which their falls amplify).
        assert open_loop == 0.0
    assert (joint.geom_margin[list(dummy_geoms)] == DUMMY_MARGIN).all()
