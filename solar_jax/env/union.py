"""A union's robots as one world: variants of one MJX model, stepped by one program.

``morphology.union`` embeds robots in one body tree. Here each robot, and each of its
variants, becomes an entry of one ``VariantPool`` over the union's model (entry
``k * P + p``: robot ``k``'s variant ``p``), with its ``physics.Tables`` beside it:
its observation layout, motor map and task numbers, on its own elements of the union.
An environment carries its entry and gathers both inside the traced step, so MJX
traces the union once for all its robots (a compile about one robot's), and every
environment steps its robot's own physics (MuJoCo C: tests/morphology/test_union.py).

Resets draw each robot's noise over its own qpos and dofs, in its own order
(``Tables.draw_qpos``): threefry's draws are per index, so a robot's start is the one
it draws in a world of its own from the same key.

``over_robots`` presents the one-robot world's functions for ``G`` robots at once
(``vmap``): a state ``[G, ...]``, per-robot keys, and results per robot, as a world of
``G`` robots gives them.
"""

import dataclasses

import jax
import numpy as np

from solar_jax.config import EnvConfig
from solar_jax.env.physics import Tables, WorldFns, WorldState, WorldStep, make_world_fns
from solar_jax.env.variants import VariantPool, model_pool
from solar_jax.env.world import World, build_world, slot
from solar_jax.morphology import Morphology
from solar_jax.morphology.union import Embedding, Union, build_union, robot_model

_PER_QPOS = ("qpos_noise", "qpos_limit")
_PER_DOF = ("qvel_uniform", "qvel_normal", "qvel_limit")
_FILL = {"qpos_limit": np.inf, "qvel_limit": np.inf}  # a dummy is never out of bounds


@dataclasses.dataclass(frozen=True, eq=False)
class UnionWorld:
    """``K`` robots with ``P`` variants each as pool entries of one union world."""

    union: Union
    world: World  # the union's model as a world of one robot slot (``world.slot``)
    pool: VariantPool  # K * P entries
    tables: Tables  # [K * P, ...]
    per_robot: int  # P

    @property
    def num_robots(self) -> int:
        return len(self.union.robots)


def build_union_world(
    robots: tuple[Morphology, ...],
    n_max: int,
    config: EnvConfig,
    variants: list[list[Morphology]] | None = None,
) -> UnionWorld:
    """The union world of ``robots`` (the first the host: ``morphology.union.plan_unions``);
    ``variants``: per robot, its ``P`` variants (the nominal robot alone without)."""
    union = build_union(robots, grow=config.layout == "union")
    variants = variants or [[robot] for robot in robots]
    models, tables = [], []
    for k, own in enumerate(variants):
        for variant in own:
            models.append(robot_model(union, k, variant))
            single = Tables.of(build_world((variant,), n_max), config.fix_humanoid_limb_types)
            tables.append(_mapped(single, union.embeddings[k], union.model))
    host = slot(robots[0], models[0], n_max)
    if not np.array_equal(union.embeddings[0].qpos[:3], [0, 1, 2]):
        raise ValueError(f"{robots[0].name}: the union's root joints are not its first")
    return UnionWorld(
        union=union,
        world=host,
        pool=model_pool(models[0], models),
        tables=jax.tree.map(lambda *xs: np.stack(xs), *tables),
        per_robot=len(variants[0]),
    )


def _scatter(values: np.ndarray, where: np.ndarray, size: int, fill=0) -> np.ndarray:
    out = np.full(size, fill, values.dtype)
    out[where] = values
    return out


def _mapped(tables: Tables, emb: Embedding, model) -> Tables:
    """A one-robot world's ``tables`` on the robot's elements of the union ``model``."""
    layout = tables.layout
    task = dict(tables.task)
    for name in _PER_QPOS:
        task[name] = _scatter(task[name], emb.qpos, model.nq, _FILL.get(name, 0))
    for name in _PER_DOF:
        task[name] = _scatter(task[name], emb.dof, model.nv, _FILL.get(name, 0))
    return Tables(
        layout=layout.replace(
            body_ids=emb.body[layout.body_ids],
            torso_ids=emb.body[layout.torso_ids],
            qpos_adr=emb.qpos[layout.qpos_adr],
        ),
        ctrl_agent=_scatter(tables.ctrl_agent, emb.actuator, model.nu),
        actuated=tables.actuated,
        task=task,
        ctrl_on=_scatter(np.ones(len(emb.actuator), bool), emb.actuator, model.nu),
        draw_qpos=_scatter(np.arange(len(emb.qpos), dtype=np.int32), emb.qpos, model.nq),
        draw_dof=_scatter(np.arange(len(emb.dof), dtype=np.int32), emb.dof, model.nv),
    )


def make_union_fns(union: UnionWorld, config: EnvConfig, redraw: bool = False) -> WorldFns:
    """The union world's functions for its ``K`` robots at once (``over_robots``)."""
    fns = make_world_fns(
        union.world,
        config,
        pool=union.pool,
        redraw=redraw,
        tables=union.tables,
        per_robot=union.per_robot,
    )
    return over_robots(fns)


def _per_robot(state: WorldState, index) -> WorldState:
    """``state``'s per-robot fields indexed: ``0`` drops a one-robot world's robot axis
    (obs [N, 19], steps [], ...), ``None`` puts it back."""
    return state.replace(
        obs=state.obs[index],
        steps=state.steps[index],
        episode_return=state.episode_return[index],
        variant=state.variant[index],
    )


def _one(state: WorldState) -> WorldState:
    return _per_robot(state, 0)


def over_robots(fns: WorldFns) -> WorldFns:
    """A one-robot world's ``fns`` over ``G`` robots: ``reset(keys [G], variant [G])``,
    ``step(state, actions [G, N])``; states ``[G, ...]`` (obs ``[G, N, 19]``, one key
    per robot) and ``WorldStep`` fields ``[G]``."""

    def reset(keys, variant, nominal=False):
        return jax.vmap(lambda k, v: _one(fns.reset(k, v[None], nominal)))(keys, variant)

    def blank(keys, variant):
        return jax.vmap(lambda k, v: _one(fns.blank(k, v[None])))(keys, variant)

    def step(state: WorldState, actions) -> tuple[WorldState, WorldStep]:
        def one(s, a):
            s, out = fns.step(_per_robot(s, None), a[None])
            return _one(s), jax.tree.map(lambda x: x[0], out)

        return jax.vmap(one)(state, actions)

    def observe_state(qpos, qvel, variant):
        return jax.vmap(lambda q, v, i: fns.observe_state(q, v, i[None])[0])(qpos, qvel, variant)

    return WorldFns(reset=reset, blank=blank, step=step, observe_state=observe_state)
