"""The accelerator's numbers in one call: training rounds, physics throughput, learner.

    python benchmarks/gpu.py [size=paper|tiny] [out=DIR]
                             [parts=training,sweep,throughput,learner]

Runs, on whatever device JAX finds, in this order of value (or in ``parts``' order, those
alone), and writes one JSON (``DIR/gpu_<device>.json``, default ``benchmarks/results``;
with ``parts``, ``DIR/gpu_<device>_<parts>.json``) holding each part's rows:

1. ``training.py``: the cold start of ``train morph=humanoid++`` (each program's tracing
   and lowering, and its XLA compile, side by side: ``collect=auto`` compiles a program
   per world on an accelerator), then a few timed rounds in both update modes (env
   steps/s, iterations/s, hours per 10M steps beside the paper's 23 h per 2M);
2. ``training.py lanes=4``: the paper's 4 seeds as lanes of one sweep, both update
   modes, with the device's memory in use beside the predicted peak of 4 lanes at 10M
   steps (the replay's full size; a sweep that cannot fit is refused in one line);
3. ``throughput.py``: MJX env steps/s of the largest humanoid (one world) at 1, 64 and
   4,096 environments, MuJoCo C on the host's cores (``mujoco.rollout``) beside it;
4. ``learner.py``: TD3 iterations and samples/s, SOLAR and Amorpheus, sequential and
   fused, at N = 7 (walker_7_main) and N = 9 (humanoid_2d_9_full), batch 100, with
   FLOP/s beside the device's GEMM rate.

``size=paper`` (default) is the paper's network sizes and suites: minutes on a GPU, hours
on a CPU. ``size=tiny`` runs the same four parts on tiny robots and networks, so that
the script is tested on a CPU (``tests/test_commands.py``). A part that fails is
recorded with its error and the others still run; the exit status is then 1. Each part
writes its own JSON into ``DIR`` as it ends, so a lease that ends mid-way keeps the parts
done; ``parts=`` picks and orders them (one process per part, each under its own time
limit, is how a short lease is best spent).
"""

import json
import platform
import sys
import time
import traceback
from pathlib import Path

if __package__ in (None, ""):  # run as a script: make the repository importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    import solar_jax  # noqa: F401  (before jax: its settings for jaxlib's logs, XLA, MuJoCo)

import jax  # noqa: E402

from benchmarks import learner, throughput, training  # noqa: E402
from benchmarks.options import parse_options  # noqa: E402

# A tiny run's settings, for the training and sweep parts at size=tiny.
TINY_RUN = [
    "morph=hopper_3",
    "net=tiny",
    "num_envs=1",
    "td3.batch_size=8",
    "env.max_episode_steps=8",
    "replay_capacity=256",
]
# Each part: (module, argv) per size.
PARTS = {
    "paper": {
        "training": ["morph=humanoid++", "rounds=2", "warmup_rounds=1"],
        # The paper's 4 seeds as lanes of one sweep; memory predicted at 10M steps.
        "sweep": [
            "morph=humanoid++",
            "lanes=4",
            "total_steps=10000000",
            "rounds=1",
            "warmup_rounds=1",
        ],
        "throughput": [
            "--suites",
            "humanoid_2d_9_full",
            "--batch-sizes",
            "1",
            "64",
            "4096",
            "--robots-per-world",
            "1",
        ],
        "learner": [
            "methods=solar,amorpheus",
            "presets=default",
            "robots=walker_7_main,humanoid_2d_9_full",
            "batch=100",
            "iterations=50",
        ],
    },
    "tiny": {
        "learner": [
            "methods=solar",
            "presets=tiny",
            "robots=hopper_3",
            "batch=8",
            "iterations=2",
            "repeats=1",
        ],
        "throughput": [
            "--suites",
            "hopper_3",
            "--batch-sizes",
            "2",
            "--robots-per-world",
            "1",
            "--steps",
            "3",
            "--no-native",
        ],
        "training": [*TINY_RUN, "rounds=1", "warmup_rounds=0"],
        "sweep": [*TINY_RUN, "lanes=2", "updates=fused", "rounds=1", "warmup_rounds=0"],
    },
}
MODULES = {"training": training, "sweep": training, "throughput": throughput, "learner": learner}


def run_part(name: str, argv: list[str], out: Path) -> dict:
    """One benchmark's ``main(argv)`` with its results written under ``out``; its JSON."""
    module = MODULES[name]
    results, module.RESULTS = module.RESULTS, out  # each part writes its file there
    before = set(out.glob("*.json"))
    start = time.perf_counter()
    try:
        status = module.main(argv)
        error = None if status in (None, 0) or isinstance(status, list) else f"exit {status}"
    except (Exception, SystemExit):  # noqa: BLE001 - one part must not lose the others
        error = traceback.format_exc(limit=3)
    finally:
        module.RESULTS = results
    written = sorted(set(out.glob("*.json")) - before)
    return {
        "argv": argv,
        "seconds": time.perf_counter() - start,
        "error": error,
        "results": [json.loads(path.read_text()) for path in written],
    }


def main(argv: list[str]) -> int:
    options = parse_options(
        argv, {"size": "paper", "out": str(learner.RESULTS), "parts": ",".join(MODULES)}, __doc__
    )
    if options["size"] not in PARTS:
        print(f"error: size={options['size']}: expected paper or tiny", file=sys.stderr)
        return 2
    names = options["parts"].split(",")
    unknown = [name for name in names if name not in MODULES]
    if unknown or len(set(names)) != len(names):
        print(
            f"error: parts={options['parts']}: expected some of {', '.join(MODULES)}, each once",
            file=sys.stderr,
        )
        return 2
    out = Path(options["out"])
    out.mkdir(parents=True, exist_ok=True)
    device = jax.devices()[0]
    parts = {}
    for name in names:
        part_argv = PARTS[options["size"]][name]
        print(f"== {name}: {' '.join(part_argv)}", flush=True)
        parts[name] = run_part(name, part_argv, out)
        if parts[name]["error"]:
            print(f"{name} failed:\n{parts[name]['error']}", file=sys.stderr)
    kind = device.device_kind.replace(" ", "_")
    subset = "" if names == list(MODULES) else "_" + "_".join(names)
    path = out / f"gpu_{kind}{subset}.json"
    meta = {
        "size": options["size"],
        "device": device.device_kind,
        "platform": device.platform,
        "machine": platform.machine(),
        "jax": jax.__version__,
        "parts": names,
    }
    path.write_text(json.dumps({"meta": meta, "parts": parts}, indent=1))
    print(f"-> {path}")
    return 1 if any(p["error"] for p in parts.values()) else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
