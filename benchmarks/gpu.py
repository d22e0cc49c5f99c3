"""The accelerator's numbers in one call: training rounds, a sweep, physics, the learner.

    python benchmarks/gpu.py [size=paper|tiny] [out=DIR] [parts=train,sweep,physics,learner]

Runs ``python -m solar_jax.bench``'s parts, on whatever device JAX finds, in this order
of value (or in ``parts``' order, those alone), and writes one JSON
(``DIR/gpu_<device>.json``, default ``benchmarks/results``; with ``parts``,
``DIR/gpu_<device>_<parts>.json``) holding each part's rows:

1. ``train``: the cold start of ``train morph=humanoid++`` (its eight robots as variants
   of one union model: one physics program; each program's tracing and lowering, and
   its XLA compile), then a few timed rounds in both update modes (env steps/s,
   iterations/s, hours per 10M steps beside the paper's 23 h per 2M);
2. ``sweep``: ``train lanes=4``, the paper's 4 seeds as lanes of one sweep, both update
   modes, with the device's memory in use beside the predicted peak of 4 lanes at 10M
   steps (the replay's full size);
3. ``physics``: MJX env steps/s of humanoid++ in its union (one program) at 1, 64 and
   4,096 environments per robot, MuJoCo C on the host's cores beside it;
4. ``learner``: TD3 iterations and samples/s, SOLAR and Amorpheus, sequential and fused,
   at N = 7 (walker_7_main) and N = 9 (humanoid_2d_9_full), batch 100, with FLOP/s
   beside the device's GEMM rate;
5. ``physics_per_robot``: humanoid++ as a model per robot (eight programs) at the same
   sizes, against the union.

``size=paper`` (default) is the paper's network sizes and suites: minutes on a GPU, hours
on a CPU. ``size=tiny`` runs the same five parts on tiny robots and networks, so that
the script is tested on a CPU (``tests/test_commands.py``). A part that fails is
recorded with its error and the others still run; the exit status is then 1. Each part
writes its own JSON (``DIR/gpu_part_<part>.json``) as it ends, so a lease that ends
mid-way keeps the parts done; ``parts=`` picks and orders them (one process per part,
each under its own time limit, is how a short lease is best spent).
"""

import json
import sys
import time
import traceback
from pathlib import Path

if __package__ in (None, ""):  # run as a script: make the repository importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    import solar_jax  # noqa: F401  (before jax: its settings for jaxlib's logs, XLA, MuJoCo)

from benchmarks.options import parse_options  # noqa: E402
from solar_jax.bench.__main__ import main as bench_main  # noqa: E402
from solar_jax.bench.common import machine  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"

# A tiny run's settings, for the train and sweep parts at size=tiny.
TINY_RUN = [
    "morph=hopper_3",
    "net=tiny",
    "num_envs=1",
    "td3.batch_size=8",
    "env.max_episode_steps=8",
    "replay_capacity=256",
]
# Each part: (bench part, argv) per size.
PARTS = {
    "paper": {
        "train": ("train", ["morph=humanoid++", "rounds=2", "warmup_rounds=1"]),
        # The paper's 4 seeds as lanes of one sweep; memory predicted at 10M steps.
        "sweep": (
            "train",
            ["morph=humanoid++", "lanes=4", "total_steps=10000000", "rounds=1", "warmup_rounds=1"],
        ),
        "physics": (
            "physics",
            ["morph=humanoid++", "batch_sizes=1,64,4096", "layouts=union"],
        ),
        "learner": (
            "learner",
            [
                "methods=solar,amorpheus",
                "presets=default",
                "robots=walker_7_main,humanoid_2d_9_full",
                "td3.batch_size=100",
                "iterations=50",
            ],
        ),
        "physics_per_robot": (
            "physics",
            ["morph=humanoid++", "batch_sizes=1,64,4096", "layouts=per_robot", "native=false"],
        ),
    },
    "tiny": {
        "train": ("train", [*TINY_RUN, "rounds=1", "warmup_rounds=0"]),
        "sweep": ("train", [*TINY_RUN, "lanes=2", "updates=fused", "rounds=1", "warmup_rounds=0"]),
        "physics": (
            "physics",
            ["morph=hopper_3", "batch_sizes=2", "layouts=union", "steps=3", "native=false"],
        ),
        "learner": (
            "learner",
            [
                "morph=hopper_3",
                "net=tiny",
                "updates=sequential,fused",
                "robots=hopper_3",
                "td3.batch_size=8",
                "iterations=2",
                "repeats=1",
            ],
        ),
        "physics_per_robot": (
            "physics",
            ["morph=hopper_3", "batch_sizes=2", "layouts=per_robot", "steps=3", "native=false"],
        ),
    },
}
NAMES = tuple(PARTS["paper"])


def run_part(name: str, size: str, out: Path) -> dict:
    """One part through ``solar_jax.bench``, its JSON written to ``out``; that JSON."""
    bench, argv = PARTS[size][name]
    path = out / f"gpu_part_{name}.json"
    start = time.perf_counter()
    try:
        status = bench_main([bench, *argv, f"out={path}"])
        error = None if status == 0 else f"exit {status}"
    except Exception:  # noqa: BLE001 - one part must not lose the others
        error = traceback.format_exc(limit=3)
    result = json.loads(path.read_text()) if path.exists() and not error else None
    seconds = time.perf_counter() - start
    return {"argv": [bench, *argv], "seconds": seconds, "error": error, "result": result}


def main(argv: list[str]) -> int:
    options = parse_options(
        argv, {"size": "paper", "out": str(RESULTS), "parts": ",".join(NAMES)}, __doc__
    )
    if options["size"] not in PARTS:
        print(f"error: size={options['size']}: expected paper or tiny", file=sys.stderr)
        return 2
    names = options["parts"].split(",")
    unknown = [name for name in names if name not in NAMES]
    if unknown or len(set(names)) != len(names):
        print(
            f"error: parts={options['parts']}: expected some of {', '.join(NAMES)}, each once",
            file=sys.stderr,
        )
        return 2
    out = Path(options["out"])
    out.mkdir(parents=True, exist_ok=True)
    parts = {}
    for name in names:
        print(f"== {name}: {' '.join(PARTS[options['size']][name][1])}", flush=True)
        parts[name] = run_part(name, options["size"], out)
        if parts[name]["error"]:
            print(f"{name} failed:\n{parts[name]['error']}", file=sys.stderr)
    meta = machine() | {"size": options["size"], "parts": names}
    kind = meta["device"].replace(" ", "_")
    subset = "" if names == list(NAMES) else "_" + "_".join(names)
    path = out / f"gpu_{kind}{subset}.json"
    path.write_text(json.dumps({"meta": meta, "parts": parts}, indent=1))
    print(f"-> {path}")
    return 1 if any(p["error"] for p in parts.values()) else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
