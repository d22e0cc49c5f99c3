"""One world's task as pure functions: ``reset(key)`` and ``step(state, actions)``.

Unbatched (one instance of the world, ``R`` robots); batching over environments is
a ``vmap`` at the caller. Each robot runs its own episode: reward, termination,
truncation and auto-reset are per robot (algorithm.md §2).
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from solar_jax.config import EnvConfig
from solar_jax.env.integrator import mjx, world_step  # mjx imported quietly there
from solar_jax.env.observation import ObservationLayout, observe
from solar_jax.env.variants import VariantPool, model_of, ranges_of
from solar_jax.env.world import OBS_SIZE, World


@struct.dataclass
class WorldState:
    data: mjx.Data
    obs: jnp.ndarray  # [R, N, 19] observation of the current state
    steps: jnp.ndarray  # [R] int32 steps into each robot's episode
    episode_return: jnp.ndarray  # [R] return so far
    key: jnp.ndarray  # PRNG key for resets
    variant: jnp.ndarray | None = None  # [R] int32 each robot's variant in the world's pool


@struct.dataclass
class WorldStep:
    """What one step produced, per robot ``[R, ...]``."""

    next_obs: jnp.ndarray  # [R, N, 19] true observation after the step (before any reset)
    reward: jnp.ndarray  # [R]
    terminated: jnp.ndarray  # [R] bool: the task ended (no bootstrap)
    truncated: jnp.ndarray  # [R] bool: time limit (bootstrap through it)
    nonfinite: jnp.ndarray  # [R] bool: physics blew up; transition must not be stored
    episode_return: jnp.ndarray  # [R] the finished episode's return where done, else 0
    episode_length: jnp.ndarray  # [R] the finished episode's length where done, else 0


class WorldFns(NamedTuple):
    reset: callable  # (key, variant [R] or None, nominal) -> WorldState
    blank: callable  # (key, variant) -> WorldState of reset's shapes (zeros; for compiling)
    step: callable  # (WorldState, actions [R, N]) -> (WorldState, WorldStep)
    observe_state: callable  # (qpos [nq], qvel [nv]) -> observations [R, N, 19]


class Tables(NamedTuple):
    """What a world's step reads of its robots: the observation layout, the motor map
    and the task numbers (``_task_arrays``), ``[R, ...]`` per robot or per qpos, dof or
    motor entry. NumPy constants for a world of its robots; for a union
    (``env.union``), each environment's robot's, gathered by its variant."""

    layout: ObservationLayout
    ctrl_agent: np.ndarray  # [nu] agent (pre-order index) each motor takes its action from
    actuated: np.ndarray  # [R, N] bool: real agents with a motor (not the torso)
    task: dict[str, np.ndarray]  # _task_arrays
    ctrl_on: np.ndarray | None = None  # [nu] bool: the robot's motors (None: all)
    draw_qpos: np.ndarray | None = None  # [nq] the reset draw each qpos entry takes
    draw_dof: np.ndarray | None = None  # [nv] likewise per dof (None: its own index)

    @classmethod
    def of(cls, world: World, fix_limb_types: bool) -> "Tables":
        return cls(
            layout=ObservationLayout.of(world, fix_limb_types),
            ctrl_agent=world.ctrl_agent,
            actuated=world.actuated,
            task=_task_arrays(world),
        )


def _task_arrays(world: World) -> dict[str, np.ndarray]:
    """Per-robot task numbers and per-entry reset noise, NumPy."""
    tasks = [m.task for m in world.morphs]
    z_lo = [t.z_range[0] if t.z_range else -np.inf for t in tasks]
    z_hi = [t.z_range[1] if t.z_range else np.inf for t in tasks]
    qpos_noise = np.array([tasks[r].reset_qpos_noise for r in world.qpos_robot])
    normal = np.array([tasks[r].reset_qvel_normal for r in world.dof_robot])
    qvel_scale = np.array([tasks[r].reset_qvel_noise for r in world.dof_robot])
    # |qpos[2:]| and |qvel| bounds (hoppers), as a per-entry limit; inf where unchecked.
    state_limit = [t.max_abs_state if t.max_abs_state else np.inf for t in tasks]
    qpos_limit = np.array([state_limit[r] for r in world.qpos_robot])
    qpos_limit[np.concatenate([world.root_qpos, world.root_qpos + 1])] = np.inf
    return dict(
        alive=np.array([t.alive_bonus for t in tasks], np.float32),
        ctrl_cost=np.array([t.ctrl_cost for t in tasks], np.float32),
        terminates=np.array([t.terminates for t in tasks]),
        z_lo=np.array(z_lo, np.float32),
        z_hi=np.array(z_hi, np.float32),
        max_pitch=np.array([t.max_abs_pitch or np.inf for t in tasks], np.float32),
        qpos_noise=qpos_noise.astype(np.float32),
        qvel_uniform=np.where(normal, 0.0, qvel_scale).astype(np.float32),
        qvel_normal=np.where(normal, qvel_scale, 0.0).astype(np.float32),
        qpos_limit=qpos_limit.astype(np.float32),
        qvel_limit=np.array([state_limit[r] for r in world.dof_robot], np.float32),
    )


def _per_robot_all(values: jnp.ndarray, owner: np.ndarray, num: int) -> jnp.ndarray:
    """``[num]`` bool: all ``values`` (bool, one per entry) of each robot hold."""
    return jax.ops.segment_min(values.astype(jnp.int32), owner, num_segments=num) > 0


def make_world_fns(
    world: World,
    config: EnvConfig,
    auto_reset: bool = True,
    pool: VariantPool | None = None,
    redraw: bool = False,
    tables: Tables | None = None,
    per_robot: int = 0,
) -> WorldFns:
    """The world's ``reset`` and ``step``; with ``auto_reset=False`` a done robot stays where
    its episode ended (for wrappers that reset themselves, e.g. brax's).

    With a ``pool`` of variants (``env.variants``) each robot steps as its variant
    ``state.variant[r]``: the one ``reset`` was given, or with ``redraw`` one drawn
    uniformly from its ``per_robot`` entries (0: the whole pool) at the start of each
    of its episodes. ``tables``: ``[P, ...]`` per pool entry (a union's robots,
    ``env.union``), gathered by variant; None: the world's own."""
    model = world.model
    model.opt.iterations = config.solver_iterations
    model.opt.ls_iterations = config.ls_iterations
    mx = mjx.put_model(model)
    physics_step = world_step(model)  # RK4's stages in one loop where it can (integrator.py)
    own = None  # the world's own tables, constants; None: a union's, gathered
    if tables is None:
        own = Tables.of(world, config.fix_humanoid_limb_types)
        own = own._replace(task={k: jnp.asarray(v) for k, v in own.task.items()})
    num, dt = world.num_robots, world.dt
    per_robot = per_robot or (pool.size if pool is not None else 0)
    root_x, root_z, root_pitch = world.root_qpos, world.root_qpos + 1, world.root_qpos + 2
    template = mjx.make_data(mx)

    def tables_of(variant) -> Tables:
        """The tables of robots stepping as ``variant`` ([R]; a union's world has R = 1)."""
        if own is not None:
            return own
        return jax.tree.map(lambda x: jnp.asarray(x)[variant[0]], tables)

    @jax.jit
    def _observed(data: mjx.Data) -> tuple[mjx.Data, jnp.ndarray]:
        # Body poses and com-based velocities at the current qpos/qvel (mjx.step
        # leaves those of the start of its last substep), and the observation [R, N, 19].
        # A nested jit: traced once per shape, then reused by reset, by both calls in
        # step and by every program of this world (XLA inlines it: the same bits).
        data = mjx.kinematics(mx, data)
        data = mjx.com_pos(mx, data)
        data = mjx.com_vel(mx, data)
        obs = observe(own.layout, data.qpos, data.xpos, data.xquat, data.cvel, data.subtree_com)
        return data, obs

    def _variant_observed(data: mjx.Data, variant, m=None) -> tuple[mjx.Data, jnp.ndarray]:
        """``_observed`` of robots stepping as ``variant`` ([R] or None: nominal); ``m``:
        their model when the caller has gathered it already."""
        if pool is None or variant is None:
            return _observed(data)
        m = model_of(mx, pool, variant) if m is None else m
        data = mjx.com_vel(m, mjx.com_pos(m, mjx.kinematics(m, data)))
        args = (data.qpos, data.xpos, data.xquat, data.cvel, data.subtree_com)
        if own is None:  # a union's: the layout is the robot's, its ranges included
            return data, observe(tables_of(variant).layout, *args)
        return data, observe(own.layout, *args, ranges=ranges_of(pool, variant))

    def _draw(key: jnp.ndarray, variant: jnp.ndarray) -> jnp.ndarray:
        """A variant of each robot's own ``per_robot`` (its first: ``_first``)."""
        return _first(variant) + jax.random.randint(key, (num,), 0, per_robot, jnp.int32)

    def _first(variant: jnp.ndarray) -> jnp.ndarray:
        """Each robot's nominal entry: its first of ``per_robot`` (a world's own pool: 0)."""
        return variant // per_robot * per_robot

    def _fresh(key: jnp.ndarray, variant) -> tuple[jnp.ndarray, jnp.ndarray]:
        """qpos, qvel of every robot at qpos0 plus its task's reset noise (algorithm.md §2),
        drawn over each robot's own entries (a union's: ``Tables.draw_qpos``)."""
        t = tables_of(variant)
        if own is not None:
            qpos0 = jnp.asarray(model.qpos0, jnp.float32)
        else:
            qpos0 = model_of(mx, pool, variant).qpos0
        k_pos, k_vel_u, k_vel_n = jax.random.split(key, 3)
        u_pos = jax.random.uniform(k_pos, qpos0.shape, minval=-1, maxval=1)
        u_vel = jax.random.uniform(k_vel_u, (mx.nv,), minval=-1, maxval=1)
        n_vel = jax.random.normal(k_vel_n, (mx.nv,))
        if t.draw_qpos is not None:
            u_pos, u_vel, n_vel = u_pos[t.draw_qpos], u_vel[t.draw_dof], n_vel[t.draw_dof]
        qpos = qpos0 + t.task["qpos_noise"] * u_pos
        return qpos, t.task["qvel_uniform"] * u_vel + t.task["qvel_normal"] * n_vel

    def reset(key: jnp.ndarray, variant: jnp.ndarray | None = None, nominal=False) -> WorldState:
        """``variant`` [R]: each robot's variant in the pool (with ``redraw``: drawn, or
        where ``nominal`` holds, the pool's first)."""
        key, k_reset = jax.random.split(key)
        if pool is not None and (redraw or variant is None):
            key, k_variant = jax.random.split(key)
            if variant is None:
                variant = jnp.zeros(num, jnp.int32)
            variant = jnp.where(nominal, _first(variant), _draw(k_variant, variant))
        qpos, qvel = _fresh(k_reset, variant)
        data, obs = _variant_observed(template.replace(qpos=qpos, qvel=qvel), variant)
        return WorldState(
            data=data,
            obs=obs,
            steps=jnp.zeros(num, jnp.int32),
            episode_return=jnp.zeros(num, jnp.float32),
            key=key,
            variant=variant,
        )

    def step(state: WorldState, actions: jnp.ndarray) -> tuple[WorldState, WorldStep]:
        """``actions [R, N]`` in [-1, 1] (clipped); torso and padded entries are ignored."""
        actions = jnp.clip(actions, -1.0, 1.0)
        tb = tables_of(state.variant)
        ctrl = actions[world.ctrl_robot, tb.ctrl_agent]
        if tb.ctrl_on is not None:  # a union's motors the robot lacks (gear 0) stay at 0
            ctrl = jnp.where(tb.ctrl_on, ctrl, 0.0)
        data = state.data.replace(ctrl=ctrl)
        x_before = data.qpos[root_x]
        m = mx if pool is None else model_of(mx, pool, state.variant)
        data = jax.lax.fori_loop(0, world.frame_skip, lambda _, d: physics_step(m, d), data)
        data, obs = _variant_observed(data, state.variant, m)
        qpos, qvel = data.qpos, data.qvel

        t = tb.task
        ctrl_cost = t["ctrl_cost"] * jnp.sum(jnp.where(tb.actuated, actions, 0.0) ** 2, axis=1)
        reward = (qpos[root_x] - x_before) / dt + t["alive"] - ctrl_cost
        finite = jnp.isfinite(qpos).all() & jnp.isfinite(qvel).all() & jnp.isfinite(reward).all()
        state_ok = _per_robot_all(
            jnp.abs(qpos) < t["qpos_limit"], world.qpos_robot, num
        ) & _per_robot_all(jnp.abs(qvel) < t["qvel_limit"], world.dof_robot, num)
        z, pitch = qpos[root_z], qpos[root_pitch]
        healthy = (t["z_lo"] < z) & (z < t["z_hi"]) & (jnp.abs(pitch) < t["max_pitch"]) & state_ok
        nonfinite = jnp.broadcast_to(~finite, (num,))
        terminated = t["terminates"] & ~healthy & ~nonfinite
        steps = state.steps + 1
        truncated = (steps >= config.max_episode_steps) & ~terminated & ~nonfinite
        done = terminated | truncated | nonfinite
        next_obs = jnp.where(finite, obs, 0.0)
        reward = jnp.where(finite, reward, 0.0)
        episode_return = state.episode_return + reward

        def outcome() -> WorldStep:
            return WorldStep(
                next_obs=next_obs,
                reward=reward,
                terminated=terminated,
                truncated=truncated,
                nonfinite=nonfinite,
                episode_return=jnp.where(done, episode_return, 0.0),
                episode_length=jnp.where(done, steps, 0),
            )

        if not auto_reset:
            return state.replace(
                data=data, obs=obs, steps=steps, episode_return=episode_return
            ), outcome()

        # Auto-reset: done robots get fresh qpos/qvel slices and a cold solver start. A
        # non-finite world is reset whole and scrubbed (every float field zeroed; the
        # next mjx.step recomputes all but the carried state), rather than merged with a
        # fresh mjx.Data, whose constant fields XLA would fold at compile time.
        key, k_reset = jax.random.split(state.key)
        variant = state.variant
        if pool is not None and redraw:
            key, k_variant = jax.random.split(key)
            variant = jnp.where(done, _draw(k_variant, variant), variant)
        fresh_qpos, fresh_qvel = _fresh(k_reset, variant)
        q_reset, v_reset = done[world.qpos_robot], done[world.dof_robot]
        scrubbed = jax.tree.map(
            lambda x: jnp.where(finite, x, 0) if jnp.issubdtype(x.dtype, jnp.floating) else x,
            data,
        )
        reset_data = scrubbed.replace(
            qpos=jnp.where(q_reset, fresh_qpos, scrubbed.qpos),
            qvel=jnp.where(v_reset, fresh_qvel, scrubbed.qvel),
            qacc_warmstart=jnp.where(v_reset, 0.0, scrubbed.qacc_warmstart),
        )
        reset_data, reset_obs = _variant_observed(reset_data, variant)
        new_state = WorldState(
            data=reset_data,
            obs=reset_obs,
            steps=jnp.where(done, 0, steps),
            episode_return=jnp.where(done, 0.0, episode_return),
            key=key,
            variant=variant,
        )
        return new_state, outcome()

    def blank(key: jnp.ndarray, variant: jnp.ndarray | None = None) -> WorldState:
        """A state with ``reset``'s shapes and types, without tracing MJX (its kinematics
        take a second or more per world to trace)."""
        return WorldState(
            data=template,
            obs=jnp.zeros((num, world.n_max, OBS_SIZE), jnp.float32),
            steps=jnp.zeros(num, jnp.int32),
            episode_return=jnp.zeros(num, jnp.float32),
            key=key,
            variant=None if pool is None else jnp.zeros(num, jnp.int32),
        )

    def observe_state(
        qpos: jnp.ndarray, qvel: jnp.ndarray, variant: jnp.ndarray | None = None
    ) -> jnp.ndarray:
        return _variant_observed(template.replace(qpos=qpos, qvel=qvel), variant)[1]

    return WorldFns(reset=reset, blank=blank, step=step, observe_state=observe_state)
