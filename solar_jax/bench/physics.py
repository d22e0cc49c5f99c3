"""Physics throughput: the suite's MJX step (``MultiEnv``) beside native MuJoCo C.

    python -m solar_jax.bench physics morph=hopper++ [batch_sizes=16,128]
        [layouts=union,family,per_robot] [steps=50] [native=true]
        [env.solver_iterations=4] [out=PATH]

For each layout (``env.layout``) and batch size: the compile seconds of a jitted rollout of
``steps`` env steps (uniform random actions inside one ``lax.scan``, no learning) and
its env steps/s (robot-steps: every morphology's every environment counts; one env step
is ``frame_skip`` physics steps), and for a union the bodies each robot steps per body
of its own (mean over robots). The native row runs ``mujoco.rollout`` (C, one thread
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
    layouts: tuple[str, ...] = ()
    """Physics layouts (``env.layout``), one row each; none given: the config's."""
    native: bool = True
    """MuJoCo C (``mujoco.rollout``) beside, on the host's cores."""
    out: str = ""
    """The JSON's path; default ``bench_physics_<device>.json`` here."""

    def __post_init__(self):
        if not set(self.layouts) <= {"union", "family", "per_robot"}:
            raise ValueError(f"physics: layouts are union, family, per_robot: {self.layouts}")
        if self.steps < 1 or min(self.batch_sizes, default=1) < 1:
            raise ValueError("physics: steps and batch_sizes must be >= 1")


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
        "layout": config.layout,
        "worlds": len(env.worlds),
        "union_bodies_per_body": _union_bodies(env),
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
        "layout": "per_robot",
        "worlds": None,
        "union_bodies_per_body": None,
        "batch": batch,
        "morphologies": len(members),
        "compile_s": 0.0,
        "env_steps_per_s": robot_steps / total_s,
    }


def run(config: TrainConfig, options: Options, config_argv=()) -> dict:
    rows = []
    for batch in options.batch_sizes or (config.num_envs,):
        for env in _layouts(config.env, options):
            rows.append(measure_mjx(config.morph, batch, options.steps, env))
            print(f"  measured {_line(rows[-1])}", flush=True)
        if options.native:
            rows.append(measure_native(config.morph, batch, options.steps, config.env))
            print(f"  measured {_line(rows[-1])}", flush=True)
    solver = {"solver_iterations": config.env.solver_iterations}
    return {"rows": rows, "solver": solver | {"ls_iterations": config.env.ls_iterations}}


def _layouts(env: EnvConfig, options: Options) -> list[EnvConfig]:
    return [dataclasses.replace(env, layout=layout) for layout in options.layouts or (env.layout,)]


def _union_bodies(env: MultiEnv) -> float | None:
    """Bodies stepped per body of a robot's own, mean over the suite (None: no union)."""
    if all(u is None for u in env.unions):
        return None
    ratios = [1.0] * env.num_morphs
    for group, union in zip(env.groups, env.unions, strict=True):
        if union is not None:
            for i, ratio in zip(group, union.union.body_ratio, strict=True):
                ratios[i] = float(ratio)
    return float(np.mean(ratios))


def _line(row: dict) -> str:
    return (
        f"{row['backend']} {row['layout']} batch {row['batch']}: "
        f"{row['env_steps_per_s']:,.0f} env steps/s, "
        f"compile {row['compile_s']:.1f} s"
    )


def table(result: dict) -> str:
    rows = [dict(r) for r in result["rows"]]
    for r in rows:
        r["worlds_cell"] = r["worlds"] or "-"
        r.setdefault("layout", "per_robot")
        extra = r.get("union_bodies_per_body")
        r["extra_cell"] = f"{extra:.2f}" if extra else "-"
    columns = {
        "backend": "{backend}",
        "suite": "{suite}",
        "layout": "{layout}",
        "bodies per own body": "{extra_cell}",
        "worlds": "{worlds_cell}",
        "batch": "{batch}",
        "compile s": "{compile_s:.1f}",
        "env steps/s": "{env_steps_per_s:,.0f}",
    }
    return markdown(columns, rows)


PART = Part("physics", __doc__, Options(), run, table)
