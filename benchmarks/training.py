"""Training throughput of the jitted round, both update modes, and the projected time.

    python benchmarks/training.py morph=humanoid++ [rounds=5] [warmup_rounds=2]
                                  [updates=sequential,fused] [lanes=1] [key=value ...]

For each update mode (``sequential``, the reference's, and ``fused``; ``updates``: these
alone) this builds the trainer of the given ``TrainConfig`` (the paper's by default),
compiles, runs ``warmup_rounds`` unmeasured rounds with the policy acting
(``td3.warmup_steps=0``, so episode lengths are the policy's), then times ``rounds``
rounds: env steps/s of the collection (all morphologies' recorded steps), TD3
iterations/s (one iteration = one morphology's batch in sequential mode, every training
morphology's in fused mode), and seconds per counted env step, projected to 10M steps
next to the paper's 23 h per 2M (algorithm.md §6). ``lanes=S`` runs seeds ``seed`` to
``seed + S - 1`` as the lanes of one sweep (their steps and iterations summed, hours per
10M steps of each) and reports the device's memory in use beside the predicted peak of
S lanes at ``total_steps`` (``training.memory``). Compilation is reported apart. Prints
each phase's seconds as it ends (a run cut short by a time limit still says where its
time went), a table, and writes
``benchmarks/results/training_<morph>_<net>_<device>.json``.
"""

import json
import platform
import sys
import time
from pathlib import Path

if __package__ in (None, ""):  # run as a script: make the repository importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    import solar_jax  # noqa: F401  (before jax: its settings for jaxlib's logs, XLA, MuJoCo)

import dataclasses  # noqa: E402

import jax  # noqa: E402
import numpy as np  # noqa: E402

from solar_jax.cli import (  # noqa: E402
    help_text,
    parse_config,  # noqa: E402
    wants_help,
)
from solar_jax.config import TrainConfig  # noqa: E402
from solar_jax.env.batch import MultiEnv  # noqa: E402
from solar_jax.training.lanes import Lanes, SingleLane  # noqa: E402
from solar_jax.training.memory import device_bytes, lane_peak_bytes  # noqa: E402
from solar_jax.training.programs import RoundPrograms, play_round  # noqa: E402
from solar_jax.training.trainer import Trainer  # noqa: E402
from solar_jax.xla.cache import enable_compilation_cache  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
PAPER_HOURS_PER_2M = 23.0  # humanoid++, one GTX 2080 Ti (algorithm.md §6)


def _round(programs: RoundPrograms, state):
    state, stats, metrics, (collect_s, train_s) = play_round(programs, state)
    return state, dict(
        collect_s=collect_s,
        train_s=train_s,
        steps=int(stats.steps.sum()),
        counted=int(stats.steps.sum()),  # the reference's counter: all morphologies
        iterations=int(np.sum(metrics["iterations"])),  # every lane's
    )


def _seconds(row: dict) -> str:
    return f"collect {row['collect_s']:.1f} s, train {row['train_s']:.1f} s"


def measure(config, env: MultiEnv, rounds: int, warmup_rounds: int, lanes: int = 1) -> dict:
    begin = time.perf_counter()

    def progress(what: str) -> None:
        print(f"  {config.update}: {what} at {time.perf_counter() - begin:.0f} s", flush=True)

    trainer = Trainer(config, env)
    programs = RoundPrograms(SingleLane(trainer) if lanes == 1 else Lanes(trainer, lanes))
    seeds = range(config.seed, config.seed + lanes)
    state = programs.lanes.place([trainer.init(seed) for seed in seeds])
    progress("initialised")
    start = time.perf_counter()
    programs.compile(state)
    compile_s = time.perf_counter() - start
    progress(f"compiled in {compile_s:.0f} s")
    for i in range(warmup_rounds):
        state, row = _round(programs, state)
        progress(f"warm-up round {i + 1} ({_seconds(row)})")
    rows = []
    for i in range(rounds):
        state, row = _round(programs, state)
        rows.append(row)
        progress(f"round {i + 1} ({_seconds(row)})")
    total = {k: sum(r[k] for r in rows) for k in rows[0]}
    per_step = (total["collect_s"] + total["train_s"]) / (total["counted"] / lanes)
    device = programs.lanes.devices[0]
    return {
        "update": config.update,
        "lanes": lanes,
        "collect": config.collect,
        "parts": len(trainer.parts),
        "compile_s": compile_s,
        # Each program: trace (or load) and lower, then XLA's compile in its own thread.
        "programs": programs.compile_timings,
        "rounds": rounds,
        "counted_steps": total["counted"],
        "env_sps": total["steps"] / total["collect_s"],
        "iterations_per_s": total["iterations"] / total["train_s"],
        "samples_per_s": total["iterations"]
        * config.td3.batch_size
        * (trainer.num_train if config.update == "fused" else 1)
        / total["train_s"],
        "collect_share": total["collect_s"] / (total["collect_s"] + total["train_s"]),
        "s_per_counted_step": per_step,
        "hours_per_10M": per_step * 10_000_000 / 3600,
        "device_peak_bytes": (device.memory_stats() or {}).get("peak_bytes_in_use"),
        "device_bytes_limit": device_bytes(device),
        "predicted_peak_bytes": lanes * lane_peak_bytes(trainer, config.total_steps),
        "replay_slots_now": int(state.replay.capacity),
    }


def main(argv: list[str]) -> int:
    options = {"rounds": 5, "warmup_rounds": 2, "updates": "sequential,fused", "lanes": 1}
    asked, section = wants_help(argv)
    if asked:
        extra = [(f"{k}={v}", type(v).__name__, "") for k, v in options.items()]
        print(help_text(TrainConfig(), __doc__, section, extra))
        return 0
    rest = []
    for arg in argv:
        key, _, value = arg.partition("=")
        if key == "updates":
            options[key] = value
        elif key in options:
            if not value.isdigit():
                print(f"error: {arg}: expected a whole number", file=sys.stderr)
                return 2
            options[key] = int(value)
        else:
            rest.append(arg)
    if options["lanes"] < 1:
        print(f"error: lanes={options['lanes']}: at least one lane", file=sys.stderr)
        return 2
    if options["rounds"] < 1:
        print(f"error: rounds={options['rounds']}: at least one round to time", file=sys.stderr)
        return 2
    modes = options["updates"].split(",")
    if any(mode not in ("sequential", "fused") for mode in modes):
        print(f"error: updates={options['updates']}: expected sequential, fused", file=sys.stderr)
        return 2
    config = parse_config(["td3.warmup_steps=0", "progress=false", *rest])
    enable_compilation_cache()
    env = MultiEnv(config.morph, config.num_envs, config.env)
    rows = []
    for mode in modes:
        row = measure(
            dataclasses.replace(config, update=mode),
            env,
            options["rounds"],
            options["warmup_rounds"],
            options["lanes"],
        )
        print(f"measured {mode}: {json.dumps(row)}", flush=True)  # kept if a later one dies
        rows.append(row)
    device = jax.devices()[0].device_kind
    batch = config.td3.batch_size
    lanes = options["lanes"]
    print(f"\n{config.morph}, net={config.net}, batch {batch} per morphology", end="")
    print(f", {lanes} lane(s), {device}")
    columns = {
        "update": "{update}",
        "compile s": "{compile_s:.0f}",
        "env steps/s": "{env_sps:,.0f}",
        "iterations/s": "{iterations_per_s:,.1f}",
        "samples/s": "{samples_per_s:,.0f}",
        "collect share": "{collect_share:.2f}",
        "h per 10M": "{hours_per_10M:,.1f}",
    }
    print("| " + " | ".join(columns) + " | paper h per 10M |")
    print("|---" * (len(columns) + 1) + "|")
    for r in rows:
        cells = [fmt.format(**r) for fmt in columns.values()]
        print("| " + " | ".join(cells) + f" | {PAPER_HOURS_PER_2M * 5:.0f} |")
    RESULTS.mkdir(exist_ok=True)
    name = Path(config.morph).stem if config.morph.endswith(".xml") else config.morph
    suffix = f"_{lanes}lanes" if lanes > 1 else ""
    out = RESULTS / f"training_{name}_{config.net}{suffix}_{device.replace(' ', '_')}.json"
    meta = {"argv": argv, "device": device, "machine": platform.machine(), "options": options}
    out.write_text(json.dumps({"meta": meta, "rows": rows}, indent=2))
    print(f"-> {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
