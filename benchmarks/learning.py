"""Evidence of learning: a real training run, its deterministic evaluation curve against
the uniform random policy's return.

    python benchmarks/learning.py [key=value ...]      (any TrainConfig field)

Defaults: ``morph=hopper_3 net=tiny total_steps=100000 eval_every=5000
eval_episodes=5``, everything else the paper's (algorithm.md §5). The random baseline is
the mean return of the warm-up rounds' episodes (uniform random actions). Prints a table
and writes ``benchmarks/results/learning_<morph>_<method>_<device>.json`` with the curve.
"""

import json
import platform
import sys
import time
from pathlib import Path

if __package__ in (None, ""):  # run as a script: make the repository importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    import solar_jax  # noqa: F401  (before jax: its settings for jaxlib's logs, XLA, MuJoCo)

import jax  # noqa: E402
import numpy as np  # noqa: E402

from solar_jax.cli import (  # noqa: E402
    help_text,
    parse_config,  # noqa: E402
    wants_help,
)
from solar_jax.config import TrainConfig  # noqa: E402
from solar_jax.training.logger import read_metrics  # noqa: E402
from solar_jax.training.runner import Runner  # noqa: E402
from solar_jax.xla.cache import enable_compilation_cache  # noqa: E402

DEFAULTS = [
    "morph=hopper_3",
    "net=tiny",
    "total_steps=100000",
    "eval_every=5000",
    "eval_episodes=5",
    "checkpoint_every=0",
]


def main(argv: list[str]) -> int:
    asked, section = wants_help(argv)
    if asked:
        extra = (("defaults", "", " ".join(DEFAULTS)),)
        print(help_text(TrainConfig(), __doc__, section, extra))
        return 0
    given = {arg.partition("=")[0] for arg in argv}
    argv = [a for a in DEFAULTS if a.partition("=")[0] not in given] + argv
    config = parse_config(argv)
    if not config.out:
        stamp = time.strftime("%Y%m%d-%H%M%S")
        config = parse_config([*argv, f"out=runs/learning-{config.morph}-{stamp}"])
    enable_compilation_cache()
    start = time.perf_counter()
    Runner(config).run()
    wall = time.perf_counter() - start
    records = read_metrics(config.out)
    rounds = [r for r in records if r["kind"] == "round"]
    evals = [r for r in records if r["kind"] == "eval"]
    resolved = json.loads((Path(config.out) / "config.json").read_text())["resolved"]
    warmup = config.td3.warmup_steps * len(resolved["morphologies"])
    random_returns = [r["episode/train_return"] for r in rounds if r["env_steps"] <= warmup]
    random_return = float(np.mean(random_returns))
    curve = [(r["env_steps"], r["eval/train_return"]) for r in evals]
    print(f"\n{config.morph}, {config.method}, net={config.net}, {jax.devices()[0].platform}")
    print(f"uniform random policy (warm-up episodes): {random_return:8.1f}")
    print("| env steps | deterministic eval return |\n|---:|---:|")
    for steps, ret in curve:
        print(f"| {steps:,} | {ret:.1f} |")
    device = jax.devices()[0].platform
    out = (
        Path(__file__).parent / "results" / f"learning_{config.morph}_{config.method}_{device}.json"
    )
    result = {
        "config": argv,
        "device": device,
        "machine": platform.machine(),
        "wall_s": wall,
        "random_return": random_return,
        "random_episodes": len(random_returns),
        "curve": curve,
        "final_eval_return": curve[-1][1],
        "best_eval_return": max(ret for _, ret in curve),
        "train_episode_returns": [(r["env_steps"], r["episode/train_return"]) for r in rounds],
        "run_dir": str(config.out),
    }
    out.write_text(json.dumps(result, indent=1))
    print(f"-> {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
