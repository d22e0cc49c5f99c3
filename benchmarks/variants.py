"""Robot variants in one compiled program: build, compile and step costs against the
nominal robot's, per batch size.

    python benchmarks/variants.py [robot=humanoid_2d_9_full] [batches=1,100,1000]
                                  [steps=10] [repeats=3] [properties=all] [tag=NAME]

Each row runs in a child process (nothing compiled before it, no persistent cache):
``MultiEnv`` of the robot at batch ``B``, either nominal or with ``B`` variants of it
(every property of ``properties`` varied: ``morphology.variants``), environment ``b``
running variant ``b``. Columns: the seconds to draw and compile the variants with
MuJoCo C and stack them (``build``), to trace and compile a jitted ``lax.scan`` of
``steps`` env steps (each ``frame_skip`` physics steps) with random actions, how many
times it was traced (1: one program for all variants), and env steps per second over
the best of ``repeats`` timed calls. Prints a table and writes
``benchmarks/results/variants_<robot>[_tag]_<device>.json``.
"""

import json
import subprocess
import sys
import time
from pathlib import Path

if __package__ in (None, ""):  # run as a script: make the repository importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.options import parse_options  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
OPTIONS = {
    "robot": "humanoid_2d_9_full",
    "batches": "1,100,1000",
    "steps": "10",
    "repeats": "3",
    "properties": "all",
    "tag": "",
}


def child(robot: str, batch: int, varied: bool, properties: str, steps: int, repeats: int):
    """One row, timed in this process (module docstring)."""
    import solar_jax  # noqa: F401, I001  (before jax: the package's XLA flags)
    import jax
    import jax.numpy as jnp
    from solar_jax.env.batch import MultiEnv
    from solar_jax.morphology import load
    from solar_jax.morphology.variants import Variation, make_variants
    from solar_jax.xla.options import jit_physics

    morph = load(robot)
    start = time.perf_counter()
    variants = None
    if varied:
        variation, props = Variation.parse(properties)
        variants = [[v.morph for v in make_variants(morph, props, batch, 0, variation)]]
    env = MultiEnv([morph], batch, variants=variants)
    build_s = time.perf_counter() - start
    traces = []

    def run(state, key):
        traces.append(1)  # runs only while tracing

        def step(state, key):
            actions = jax.random.uniform(key, (1, batch, env.n_max), minval=-1, maxval=1)
            state, transition = env.step(state, actions)
            return state, transition.reward

        state, rewards = jax.lax.scan(step, state, jax.random.split(key, steps))
        return state, rewards.sum()

    program = jit_physics(run)
    key = jax.random.key(0)
    state = jax.block_until_ready(jit_physics(env.reset)(key))
    start = time.perf_counter()
    compiled = program.lower(state, key).compile()
    compile_s = time.perf_counter() - start
    out = jax.block_until_ready(compiled(state, key))
    times = []
    for r in range(repeats):
        start = time.perf_counter()
        out = jax.block_until_ready(compiled(out[0], jax.random.key(r + 1)))
        times.append(time.perf_counter() - start)
    finite = bool(jnp.isfinite(out[1]))
    return dict(
        build_s=build_s,
        compile_s=compile_s,
        traces=len(traces),
        best_s=min(times),
        env_steps_per_s=batch * steps / min(times),
        finite=finite,
    )


def main(argv: list[str]) -> int:
    if argv[:1] == ["--child"]:
        robot, batch, varied, properties, steps, repeats = argv[1:]
        row = child(robot, int(batch), varied == "1", properties, int(steps), int(repeats))
        print("ROW " + json.dumps(row), flush=True)
        return 0
    options = parse_options(argv, OPTIONS, __doc__)
    import jax

    from solar_jax.bench.common import machine

    batches = [int(b) for b in options["batches"].split(",")]
    rows = []
    for batch in batches:
        for varied in (False, True):
            command = [sys.executable, __file__, "--child", options["robot"], str(batch)]
            command += ["1" if varied else "0", options["properties"]]
            command += [options["steps"], options["repeats"]]
            done = subprocess.run(command, capture_output=True, text=True)
            found = [json.loads(x[4:]) for x in done.stdout.splitlines() if x[:4] == "ROW "]
            row = found[-1] if found else {"error": done.stderr[-500:]}
            rows.append({"batch": batch, "variants": batch if varied else 0, **row})
            print(json.dumps(rows[-1]), flush=True)
    device = jax.devices()[0].platform
    lines = [
        f"{options['robot']}, {options['steps']} env steps per call, {device}",
        "| batch | variants | build s | compile s | traces | env steps/s |",
        "|---:|---:|---:|---:|---:|---:|",
    ]
    for row in rows:
        if "error" in row:
            lines.append(f"| {row['batch']} | {row['variants']} | failed | | | |")
            continue
        lines.append(
            f"| {row['batch']:,} | {row['variants']:,} | {row['build_s']:.1f} | "
            f"{row['compile_s']:.1f} | {row['traces']} | {row['env_steps_per_s']:,.0f} |"
        )
    print("\n".join(lines))
    tag = f"_{options['tag']}" if options["tag"] else ""
    out = RESULTS / f"variants_{options['robot']}{tag}_{device}.json"
    meta = {"options": options, "machine": machine()}
    out.write_text(json.dumps({"meta": meta, "rows": rows}, indent=1))
    print(f"-> {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
