"""Training throughput: rounds of ``train``, both update modes, and the time projected to
10M steps.

    python -m solar_jax.bench train morph=humanoid++ [rounds=5] [warmup_rounds=2]
        [updates=sequential,fused] [lanes=1] [key=value ...] [out=PATH]

For each update mode this builds the trainer of the given config (the paper's by
default), compiles its round (each program's tracing and XLA compile reported), runs
``warmup_rounds`` unmeasured rounds with the policy acting (``td3.warmup_steps=0`` unless
given, so episode lengths are the policy's), then times ``rounds`` rounds: env steps/s of the
collection (every morphology's recorded steps), TD3 iterations/s (one iteration = one
morphology's batch in sequential mode, every training morphology's in fused mode), and
seconds per counted env step projected to 10M steps beside the paper's 23 h per 2M
(algorithm.md §6). ``lanes=S`` runs seeds ``seed`` to ``seed + S - 1`` as the lanes of
one sweep (steps and iterations summed, hours per 10M steps of each) with the device's
memory in use beside the predicted peak of S lanes at ``total_steps``.
"""

import dataclasses
import time
import typing

import numpy as np

from solar_jax.bench.common import Part, markdown
from solar_jax.config import TrainConfig
from solar_jax.env.batch import MultiEnv
from solar_jax.training.lanes import Lanes, SingleLane
from solar_jax.training.memory import device_bytes, lane_peak_bytes
from solar_jax.training.programs import RoundPrograms, play_round
from solar_jax.training.trainer import Trainer
from solar_jax.xla.cache import enable_compilation_cache

PAPER_HOURS_PER_2M = 23.0  # humanoid++, one GTX 2080 Ti (algorithm.md §6)


@dataclasses.dataclass(frozen=True)
class Options:
    rounds: int = 5
    """Rounds timed per update mode."""
    warmup_rounds: int = 2
    """Rounds run first, not timed."""
    updates: tuple[typing.Literal["sequential", "fused"], ...] = ("sequential", "fused")
    """Update modes, one row each."""
    lanes: int = 1
    """Seeds trained as the lanes of one sweep."""
    out: str = ""
    """The JSON's path; default ``bench_train_<device>.json`` here."""

    def __post_init__(self):
        if self.rounds < 1 or self.lanes < 1 or self.warmup_rounds < 0:
            raise ValueError("train: rounds and lanes must be >= 1, warmup_rounds >= 0")


def _round(programs: RoundPrograms, state):
    state, stats, metrics, (collect_s, train_s) = play_round(programs, state)
    steps = int(stats.steps.sum())  # the reference's counter: every morphology's
    iterations = int(np.sum(metrics["iterations"]))  # every lane's
    return state, dict(collect_s=collect_s, train_s=train_s, steps=steps, iterations=iterations)


def measure(config: TrainConfig, env: MultiEnv, options: Options) -> dict:
    """One update mode's row (module docstring), with each phase's seconds said as it ends
    (a run cut short by a time limit still says where its time went)."""
    begin = time.perf_counter()

    def progress(what: str) -> None:
        print(f"  {config.update}: {what} at {time.perf_counter() - begin:.0f} s", flush=True)

    def seconds(row: dict) -> str:
        return f"collect {row['collect_s']:.1f} s, train {row['train_s']:.1f} s"

    lanes = options.lanes
    trainer = Trainer(config, env)
    programs = RoundPrograms(SingleLane(trainer) if lanes == 1 else Lanes(trainer, lanes))
    state = programs.lanes.place([trainer.init(config.seed + i) for i in range(lanes)])
    progress("initialised")
    start = time.perf_counter()
    programs.compile(state)
    compile_s = time.perf_counter() - start
    progress(f"compiled in {compile_s:.0f} s")
    for i in range(options.warmup_rounds):
        state, row = _round(programs, state)
        progress(f"warm-up round {i + 1} ({seconds(row)})")
    rows = []
    for i in range(options.rounds):
        state, row = _round(programs, state)
        rows.append(row)
        progress(f"round {i + 1} ({seconds(row)})")
    total = {k: sum(r[k] for r in rows) for k in rows[0]}
    per_step = (total["collect_s"] + total["train_s"]) / (total["steps"] / lanes)
    device = programs.lanes.devices[0]
    morphs = trainer.num_train if config.update == "fused" else 1
    return {
        "morph": config.morph,
        "net": config.net,
        "update": config.update,
        "lanes": lanes,
        "collect": config.collect,
        "parts": len(trainer.parts),
        "compile_s": compile_s,
        # Each program: trace (or load) and lower, then XLA's compile in its own thread.
        "programs": programs.compile_timings,
        "rounds": options.rounds,
        "counted_steps": total["steps"],
        "env_steps_per_s": total["steps"] / total["collect_s"],
        "iterations_per_s": total["iterations"] / total["train_s"],
        "samples_per_s": total["iterations"] * config.td3.batch_size * morphs / total["train_s"],
        "collect_share": total["collect_s"] / (total["collect_s"] + total["train_s"]),
        "s_per_counted_step": per_step,
        "hours_per_10M": per_step * 10_000_000 / 3600,
        "device_peak_bytes": (device.memory_stats() or {}).get("peak_bytes_in_use"),
        "device_bytes_limit": device_bytes(device),
        "predicted_peak_bytes": lanes * lane_peak_bytes(trainer, config.total_steps),
        "replay_slots_now": int(state.replay.capacity),
    }


def run(config: TrainConfig, options: Options, config_argv=()) -> dict:
    config = dataclasses.replace(config, progress=False)
    if not any(arg.startswith("td3.warmup_steps=") for arg in config_argv):  # the policy acts
        config = dataclasses.replace(config, td3=dataclasses.replace(config.td3, warmup_steps=0))
    enable_compilation_cache()
    env = MultiEnv(config.morph, config.num_envs, config.env)
    rows = []
    for update in options.updates:
        rows.append(measure(dataclasses.replace(config, update=update), env, options))
        row = rows[-1]
        print(
            f"  measured {update}: {row['env_steps_per_s']:,.0f} env steps/s, "
            f"{row['iterations_per_s']:,.1f} iterations/s",
            flush=True,
        )
    return {"rows": rows, "paper_hours_per_10M": PAPER_HOURS_PER_2M * 5}


def table(result: dict) -> str:
    columns = {
        "morph": "{morph}",
        "net": "{net}",
        "update": "{update}",
        "lanes": "{lanes}",
        "compile s": "{compile_s:.0f}",
        "env steps/s": "{env_steps_per_s:,.0f}",
        "iterations/s": "{iterations_per_s:,.1f}",
        "samples/s": "{samples_per_s:,.0f}",
        "collect share": "{collect_share:.2f}",
        "h per 10M": "{hours_per_10M:,.1f}",
    }
    paper = f"the paper: {result['paper_hours_per_10M']:.0f} h per 10M steps (humanoid++)"
    return markdown(columns, result["rows"]) + "\n" + paper


PART = Part("train", __doc__, Options(), run, table)
