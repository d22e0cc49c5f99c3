"""Merged worlds are exact unions of their robots (host side, no compilation)."""

import itertools

import numpy as np
import pytest

from solar_jax.env.world import build_world, plan_worlds
from solar_jax.morphology import load
from tests.tiny import ROBOT as TINY_ROBOT

NAMES = ("walker_7_main", "hopper_5", "humanoid_2d_9_full")
PER_BODY = ("body_mass", "body_inertia", "body_ipos", "body_pos", "body_quat")
PER_GEOM = (
    "geom_size",
    "geom_pos",
    "geom_quat",
    "geom_friction",
    "geom_condim",
    "geom_solref",
    "geom_solimp",
    "geom_margin",
    "geom_type",
)
PER_JOINT = ("jnt_type", "jnt_axis", "jnt_pos", "jnt_range", "jnt_stiffness", "qpos0")
PER_DOF = ("dof_armature", "dof_damping")
PER_ACTUATOR = ("actuator_gear", "actuator_ctrlrange")


def _collide(model, a, b):
    return bool(model.geom_contype[a] & model.geom_conaffinity[b]) or bool(
        model.geom_contype[b] & model.geom_conaffinity[a]
    )


def test_merged_world_slices_equal_each_robot():
    morphs = tuple(load(n) for n in NAMES)
    world = build_world(morphs, 9).model
    body = geom = jnt = dof = act = 0
    for m in morphs:
        own = m.model
        nb, ng, nj, nv, nu = own.nbody - 1, own.ngeom, own.njnt, own.nv, own.nu
        for name in PER_BODY:
            np.testing.assert_array_equal(
                getattr(world, name)[1 + body : 1 + body + nb], getattr(own, name)[1:]
            )
        # World geoms: each robot's floor first (in order), then its body geoms.
        robot_geoms = np.flatnonzero(world.geom_bodyid > 0)[geom : geom + ng - 1]
        for name in PER_GEOM:
            np.testing.assert_array_equal(getattr(world, name)[robot_geoms], getattr(own, name)[1:])
        for name in PER_JOINT:
            np.testing.assert_array_equal(getattr(world, name)[jnt : jnt + nj], getattr(own, name))
        for name in PER_DOF:
            np.testing.assert_array_equal(getattr(world, name)[dof : dof + nv], getattr(own, name))
        for name in PER_ACTUATOR:
            np.testing.assert_array_equal(getattr(world, name)[act : act + nu], getattr(own, name))
        body, geom, jnt, dof, act = body + nb, geom + ng - 1, jnt + nj, dof + nv, act + nu


def test_robots_never_collide_with_each_other_or_other_floors():
    morphs = tuple(load(n) for n in NAMES)
    world = build_world(morphs, 9)
    model = world.model
    owner = np.zeros(model.ngeom, int)
    for g in range(model.ngeom):
        owner[g] = (
            int(model.geom(g).name.split("/")[0][1:])
            if model.geom_bodyid[g] == 0
            else (int(model.body(model.geom_bodyid[g]).name.split("/")[0][1:]))
        )
    for a, b in itertools.combinations(range(model.ngeom), 2):
        if owner[a] != owner[b]:
            assert not _collide(model, a, b), (model.geom(a).name, model.geom(b).name)
    # Within a robot, the reference's collision relation is kept (hopper limbs collide).
    for r, m in enumerate(morphs):
        ours = np.flatnonzero(owner == r)
        for (a, b), (c, d) in zip(
            itertools.combinations(ours, 2),
            itertools.combinations(range(m.model.ngeom), 2),
            strict=True,
        ):
            assert _collide(model, a, b) == _collide(m.model, c, d)


def test_plan_worlds_groups_by_physics_and_cap():
    morphs = tuple(
        load(n) for n in ("walker_2_main", "cheetah_2_back", "hopper_3", "walker_3_main")
    )
    assert plan_worlds(morphs, 1) == [[0], [2], [3], [1]]  # grouped by physics first
    assert plan_worlds(morphs, 2) == [[0, 2], [3], [1]]
    assert plan_worlds(morphs, 31) == [[0, 2, 3], [1]]
    with pytest.raises(ValueError, match="robots_per_world must be >= 1"):
        plan_worlds(morphs, 0)
    with pytest.raises(ValueError, match="different physics settings"):
        build_world((morphs[0], morphs[1]), 3)


def test_worlds_and_robots_hold_no_texture_and_drawings_do():
    morphs = tuple(load(n) for n in NAMES)
    world = build_world(morphs, 9).model
    assert world.ntex == 0 and world.ntexdata == 0 and (world.mat_texid == -1).all()
    for m in (*morphs, load(TINY_ROBOT)):  # registered, and an MJCF file
        assert m.model.ntex == 0 and m.model.ntexdata == 0 and (m.model.mat_texid == -1).all()
        drawn = m.textured_model()  # what videos draw: skybox and floor grid
        assert drawn.ntex == 2 and drawn.ntexdata > 11_000_000
        # The physics is the drawing's: every other array equal (names shift with the
        # textures' names).
        fields = [f for f in dir(drawn) if isinstance(getattr(drawn, f), np.ndarray)]
        kept = [f for f in fields if not f.startswith(("_", "tex_", "name", "mat_texid"))]
        assert len(kept) > 200
        for field in kept:
            np.testing.assert_array_equal(getattr(m.model, field), getattr(drawn, field), field)
