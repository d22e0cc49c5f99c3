"""The learner alone: TD3 iterations per second without physics, per network preset.

    python benchmarks/learner.py [presets=tiny,small,default] [robots=hopper_3,humanoid_2d_9_full]
                                 [method=solar] [batch=100] [iterations=50]

One jitted ``fori_loop`` of ``iterations`` TD3 iterations (``agent.update``: critic
every iteration, actor and targets every 2nd, synergy module every 4th) on a fixed
random batch of one robot's shapes, padded to its own N; compilation timed apart, then
the best of 3 timed calls. Prints a table (with each preset's cost relative to the
first) and writes ``benchmarks/results/learner_<device>.json``.
"""

import json
import platform
import sys
import time
from pathlib import Path

if __package__ in (None, ""):  # run as a script: make the repository importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402

from solar_jax.agent import Hyper, Structure, make_td3  # noqa: E402
from solar_jax.cli import help_text, wants_help  # noqa: E402
from solar_jax.config import TD3Config  # noqa: E402
from solar_jax.morphology import load  # noqa: E402
from solar_jax.networks import OBS_SIZE, NetworkConfig, make_networks, pad_traversal  # noqa: E402
from solar_jax.replay import Batch  # noqa: E402
from solar_jax.synergy.discovery import SuiteAffinity  # noqa: E402


def measure(preset: str, robot: str, method: str, batch: int, iterations: int) -> dict:
    morph = load(robot)
    n = len(morph.parents)
    nets = make_networks(method, NetworkConfig.preset(preset), n_max=n)
    td3_config = TD3Config(batch_size=batch)
    td3 = make_td3(nets, td3_config)
    synergy = jax.tree.map(lambda x: x[0], SuiteAffinity([morph.parents], n).cluster())
    structure = Structure(jnp.ones(n, bool), synergy, pad_traversal(morph.traversal, n))
    keys = jax.random.split(jax.random.PRNGKey(0), 4)
    data = Batch(
        obs=jax.random.normal(keys[0], (batch, n, OBS_SIZE)),
        action=jax.random.uniform(keys[1], (batch, n), minval=-1, maxval=1),
        reward=jax.random.normal(keys[2], (batch,)),
        next_obs=jax.random.normal(keys[3], (batch, n, OBS_SIZE)),
        terminated=jnp.zeros(batch, bool),
    )
    hyper = Hyper.from_config(td3_config)

    def run(state):
        def body(i, state):
            return td3.update(state, data, structure, i, jax.random.fold_in(keys[0], i), hyper)[0]

        return jax.lax.fori_loop(0, iterations, body, state)

    state = jax.jit(td3.init)(jax.random.PRNGKey(1))
    start = time.perf_counter()
    compiled = jax.jit(run).lower(state).compile()
    compile_s = time.perf_counter() - start
    times = []
    for _ in range(3):
        start = time.perf_counter()
        jax.block_until_ready(compiled(state))
        times.append(time.perf_counter() - start)
    best = min(times)
    return {
        "preset": preset,
        "robot": robot,
        "n": n,
        "method": method,
        "batch": batch,
        "compile_s": compile_s,
        "ms_per_iteration": 1000 * best / iterations,
        "iterations_per_s": iterations / best,
    }


def main(argv: list[str]) -> int:
    options = {"presets": "tiny,small,default", "robots": "hopper_3,humanoid_2d_9_full"}
    options |= {"method": "solar", "batch": "100", "iterations": "50"}
    if wants_help(argv)[0]:
        print(help_text(None, __doc__, extra=[(f"{k}={v}", "str", "") for k, v in options.items()]))
        return 0
    for arg in argv:
        key, _, value = arg.partition("=")
        if key not in options:
            print(f"error: unknown option {key!r}; valid: {', '.join(options)}", file=sys.stderr)
            return 2
        options[key] = value
    rows = []
    for robot in options["robots"].split(","):
        for preset in options["presets"].split(","):
            rows.append(
                measure(
                    preset,
                    robot,
                    options["method"],
                    int(options["batch"]),
                    int(options["iterations"]),
                )
            )
    print(f"{options['method']}, batch {options['batch']}, {jax.devices()[0].platform}")
    print("| robot (N) | preset | ms / iteration | vs first preset | compile s |")
    print("|---|---|---:|---:|---:|")
    for row in rows:
        first = next(r for r in rows if r["robot"] == row["robot"])
        ratio = row["ms_per_iteration"] / first["ms_per_iteration"]
        print(
            f"| {row['robot']} ({row['n']}) | {row['preset']} | {row['ms_per_iteration']:.1f} "
            f"| {ratio:.1f}x | {row['compile_s']:.0f} |"
        )
    device = jax.devices()[0].platform
    path = Path(__file__).parent / "results" / f"learner_{device}.json"
    meta = {"options": options, "device": device, "machine": platform.machine()}
    path.write_text(json.dumps({"meta": meta, "rows": rows}, indent=1))
    print(f"-> {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
