"""Physics throughput: the suite's MJX step (``MultiEnv``) beside native MuJoCo C.

    python -m solar_jax.bench physics morph=hopper++ [batch_sizes=16,128]
        [robots_per_world=1,31] [steps=50] [native=true] [env.solver_iterations=4] [out=PATH]

For each world layout and batch size: the compile seconds of a jitted rollout of
``steps`` env steps (uniform random actions inside one ``lax.scan``, no learning) and
its env steps/s (robot-steps: every morphology's every environment counts; one env step
is ``frame_skip`` physics steps). The native row runs ``mujoco.rollout`` (C, one thread
per core) on the same robots, batch and solver settings.
"""

import dataclasses
import os
import time

import jax
import mujoco
import numpy as np
from mujoco import rollout

from solar_jax.bench.common import Part, markdown
from solar_jax.config import EnvConfig, TrainConfig
from solar_jax.env.batch import MultiEnv
from solar_jax.morphology import get_suite, load
from solar_jax.xla.options import jit_physics


@dataclasses.dataclass(frozen=True)
class Options:
    steps: int = 50
    """Env steps per timed rollout."""
    batch_sizes: tuple[int, ...] = ()
    """Environments per morphology, one row each; none given: ``num_envs``."""
    robots_per_world: tuple[int, ...] = ()
    """World layouts (``env.robots_per_world``), one row each; none given: the config's."""
    native: bool = True
    """MuJoCo C (``mujoco.rollout``) beside, on the host's cores."""
    out: str = ""
    """The JSON's path; default ``bench_physics_<device>.json`` here."""

    def __post_init__(self):
        if self.steps < 1 or min((*self.batch_sizes, *self.robots_per_world), default=1) < 1:
            raise ValueError("physics: steps, batch_sizes and robots_per_world must be >= 1")


def measure_mjx(suite: str, batch: int, steps: int, config: EnvConfig) -> dict:
    env = MultiEnv(suite, batch, config)

    def run(state, key):
        def body(state, key):
            actions = jax.random.uniform(key, (env.num_morphs, batch, env.n_max), minval=-1)
            state, transition = env.step(state, actions)
            return state, transition.reward.mean()

        return jax.lax.scan(body, state, jax.random.split(key, steps))

    state = jit_physics(env.reset)(jax.random.key(0))
    start = time.perf_counter()
    compiled = jit_physics(run, donate_argnums=0).lower(state, jax.random.key(1)).compile()
    compile_s = time.perf_counter() - start
    state, _ = compiled(state, jax.random.key(2))  # warm-up
    jax.block_until_ready(state)
    start = time.perf_counter()
    state, rewards = compiled(state, jax.random.key(3))
    jax.block_until_ready(rewards)
    run_s = time.perf_counter() - start
    return {
        "backend": "mjx",
        "suite": suite,
        "robots_per_world": config.robots_per_world,
        "worlds": len(env.worlds),
        "batch": batch,
        "morphologies": env.num_morphs,
        "compile_s": compile_s,
        "env_steps_per_s": env.num_morphs * batch * steps / run_s,
    }


def measure_native(suite: str, batch: int, steps: int, config: EnvConfig) -> dict:
    """``mujoco.rollout`` per morphology, all cores; the solver settings of ``config``."""
    threads = os.cpu_count() or 1
    total_s, robot_steps = 0.0, 0
    rng = np.random.default_rng(0)
    members = get_suite(suite).members
    for name in members:
        morph = load(name)
        model = morph.model
        model.opt.iterations = config.solver_iterations
        model.opt.ls_iterations = config.ls_iterations
        data = [mujoco.MjData(model) for _ in range(threads)]
        full = mujoco.mjtState.mjSTATE_FULLPHYSICS
        state = np.zeros((batch, mujoco.mj_stateSize(model, full)))
        mujoco.mj_getState(model, data[0], state[0], full)
        state[:] = state[0]
        control = rng.uniform(-1, 1, (batch, steps * morph.task.frame_skip, model.nu))
        rollout.rollout([model] * batch, data, state, control, persistent_pool=True)  # warm-up
        start = time.perf_counter()
        rollout.rollout([model] * batch, data, state, control, persistent_pool=True)
        total_s += time.perf_counter() - start
        robot_steps += batch * steps
    return {
        "backend": f"mujoco C, {threads} threads",
        "suite": suite,
        "robots_per_world": None,
        "worlds": None,
        "batch": batch,
        "morphologies": len(members),
        "compile_s": 0.0,
        "env_steps_per_s": robot_steps / total_s,
    }


def run(config: TrainConfig, options: Options, config_argv=()) -> dict:
    rows = []
    for batch in options.batch_sizes or (config.num_envs,):
        for per_world in options.robots_per_world or (config.env.robots_per_world,):
            env = dataclasses.replace(config.env, robots_per_world=per_world)
            rows.append(measure_mjx(config.morph, batch, options.steps, env))
            print(f"  measured {_line(rows[-1])}", flush=True)
        if options.native:
            rows.append(measure_native(config.morph, batch, options.steps, config.env))
            print(f"  measured {_line(rows[-1])}", flush=True)
    solver = {"solver_iterations": config.env.solver_iterations}
    return {"rows": rows, "solver": solver | {"ls_iterations": config.env.ls_iterations}}


def _line(row: dict) -> str:
    return (
        f"{row['backend']} batch {row['batch']}: {row['env_steps_per_s']:,.0f} env steps/s, "
        f"compile {row['compile_s']:.1f} s"
    )


def table(result: dict) -> str:
    rows = [r | {"per_world": r["robots_per_world"] or "-"} for r in result["rows"]]
    for r in rows:
        r["worlds_cell"] = r["worlds"] or "-"
    columns = {
        "backend": "{backend}",
        "suite": "{suite}",
        "robots per world": "{per_world}",
        "worlds": "{worlds_cell}",
        "batch": "{batch}",
        "compile s": "{compile_s:.1f}",
        "env steps/s": "{env_steps_per_s:,.0f}",
    }
    return markdown(columns, rows)


PART = Part("physics", __doc__, Options(), run, table)
