"""Environment throughput: MJX (``MultiEnv``) beside native MuJoCo C, in one run.

    python -m benchmarks.throughput suites=hopper++,whh++ batch_sizes=16,128
    python benchmarks/throughput.py robots_per_world=1,31 [steps=50] [native=true]
        [solver_iterations=4] [ls_iterations=8] [out=PATH.json]

For each suite, world layout and batch size: compile seconds of the jitted rollout and
env steps/s (robot-steps: every morphology's every environment counts, 1 env step =
frame_skip physics steps), with uniform random actions inside one ``lax.scan``. The
native baseline runs ``mujoco.rollout`` (C, one thread per core) on the same robots,
batch and solver settings. Prints a table and writes JSON with the device kind.
"""

import dataclasses
import json
import os
import platform
import sys
import time
from pathlib import Path

if __package__ in (None, ""):  # run as a script: make the repository importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    import solar_jax  # noqa: F401  (before jax: its settings for jaxlib's logs, XLA, MuJoCo)

import jax
import mujoco
import numpy as np
from mujoco import rollout

from benchmarks.options import parse_options
from solar_jax.config import EnvConfig
from solar_jax.env.batch import MultiEnv
from solar_jax.morphology import get_suite, load
from solar_jax.xla.options import jit_physics

RESULTS = Path(__file__).resolve().parent / "results"


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
    """``mujoco.rollout`` per morphology, all cores; same solver settings as MJX."""
    threads = os.cpu_count() or 1
    total_s, robot_steps = 0.0, 0
    rng = np.random.default_rng(0)
    for name in get_suite(suite).members:
        morph = load(name)
        model = morph.model
        model.opt.iterations = config.solver_iterations
        model.opt.ls_iterations = config.ls_iterations
        data = [mujoco.MjData(model) for _ in range(threads)]
        state = np.zeros((batch, mujoco.mj_stateSize(model, mujoco.mjtState.mjSTATE_FULLPHYSICS)))
        mujoco.mj_getState(model, data[0], state[0], mujoco.mjtState.mjSTATE_FULLPHYSICS)
        state[:] = state[0]
        nstep = steps * morph.task.frame_skip
        control = rng.uniform(-1, 1, (batch, nstep, model.nu))
        rollout.rollout([model] * batch, data, state, control, persistent_pool=True)  # warm-up
        start = time.perf_counter()
        rollout.rollout([model] * batch, data, state, control, persistent_pool=True)
        total_s += time.perf_counter() - start
        robot_steps += batch * steps
    return {
        "backend": f"mujoco C rollout, {threads} threads",
        "suite": suite,
        "robots_per_world": None,
        "worlds": None,
        "batch": batch,
        "morphologies": len(get_suite(suite).members),
        "compile_s": 0.0,
        "env_steps_per_s": robot_steps / total_s,
    }


DEFAULTS = dict(
    suites="hopper++,whh++",
    batch_sizes="16,128",
    robots_per_world="1,31",
    steps="50",  # env steps per timed rollout
    solver_iterations=str(EnvConfig.solver_iterations),
    ls_iterations=str(EnvConfig.ls_iterations),
    native="true",  # MuJoCo C beside
    out="",
)


def main(argv: list[str] | None = None) -> list[dict]:
    o = parse_options(sys.argv[1:] if argv is None else argv, DEFAULTS, __doc__)
    steps = int(o["steps"])
    device = jax.devices()[0].device_kind
    base = EnvConfig(
        solver_iterations=int(o["solver_iterations"]), ls_iterations=int(o["ls_iterations"])
    )
    rows = []
    header = f"{'backend':<28} {'suite':<10} {'per world':>9} {'worlds':>6} {'batch':>6} "
    header += f"{'compile s':>9} {'env steps/s':>12}"
    print(f"device: {device}; solver {base.solver_iterations}/{base.ls_iterations}")
    print(header)
    for suite in o["suites"].split(","):
        for batch in (int(b) for b in o["batch_sizes"].split(",")):
            layouts = [int(k) for k in o["robots_per_world"].split(",")]
            layouts += [None] if o["native"] == "true" else []
            for per_world in layouts:
                if per_world is None:
                    row = measure_native(suite, batch, steps, base)
                else:
                    config = dataclasses.replace(base, robots_per_world=per_world)
                    row = measure_mjx(suite, batch, steps, config)
                rows.append(row)
                print(
                    f"{row['backend']:<28} {row['suite']:<10} {row['robots_per_world'] or '-':>9} "
                    f"{row['worlds'] or '-':>6} {row['batch']:>6} {row['compile_s']:>9.1f} "
                    f"{row['env_steps_per_s']:>12.0f}",
                    flush=True,
                )
    out = Path(o["out"]) if o["out"] else RESULTS / f"throughput_{device.replace(' ', '_')}.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    meta = {
        "device": device,
        "cpu_count": os.cpu_count(),
        "platform": platform.platform(),
        "jax": jax.__version__,
        "mujoco": mujoco.__version__,
        "steps": steps,
        "solver_iterations": base.solver_iterations,
        "ls_iterations": base.ls_iterations,
    }
    out.write_text(json.dumps({"meta": meta, "rows": rows}, indent=2))
    print(f"wrote {out}")
    return rows


if __name__ == "__main__":
    main()
