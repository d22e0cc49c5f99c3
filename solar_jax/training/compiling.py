"""Compiling a run's programs, said aloud: what compiles, how long it took last time on
this machine (``solar_jax.xla.times``), and when the replay's growth recompiles."""

import hashlib
import json
import time

import jax

from solar_jax.config import TrainConfig, config_to_dict
from solar_jax.training.programs import RoundPrograms
from solar_jax.training.rundir import BOOKKEEPING
from solar_jax.training.trainer import Trainer
from solar_jax.xla.times import last_compile_time, save_compile_time


def report_growth(trainer: Trainer, before: int, state) -> None:
    """Says so when the replay grew past ``before`` slots (its update recompiles)."""
    if state.replay.capacity > before:
        slots = state.replay.capacity
        print(f"replay grown to {slots:,} slots per morphology (of {trainer.capacity:,})")


def program_key(config: TrainConfig, slots: int) -> str:
    """What a run's compiled programs depend on (the config less its bookkeeping keys, the
    replay allocation, JAX and the backend), hashed: the key of their compile time."""
    fields = {k: v for k, v in config_to_dict(config).items() if k not in BOOKKEEPING}
    text = json.dumps([fields, slots, jax.__version__, jax.default_backend()], sort_keys=True)
    return hashlib.sha1(text.encode()).hexdigest()[:16]


def compile_announced(
    programs: RoundPrograms, state, config: TrainConfig, robots: int, num_lanes: int = 1
) -> float:
    """``programs.compile(state)`` (a ``RoundPrograms`` of ``num_lanes`` lanes), saying first
    what compiles and how long it took last time on this machine; the seconds it took
    (0 when that replay size was compiled already)."""
    slots = state.replay.capacity
    if slots in programs.programs:
        programs.compile(state)
        return 0.0
    first = programs.part_programs is None
    key = program_key(config, slots) + ("" if first else "-grown")
    key += f"-{num_lanes}lanes" if num_lanes > 1 else ""
    last = last_compile_time(key)
    lanes = f", {num_lanes} lanes" if num_lanes > 1 else ""
    what = f"{robots} robot{'s' if robots > 1 else ''}{lanes}"
    which = "collection and update programs" if first else "the update program for the grown replay"
    print(
        f"compiling {config.morph} ({what}, {config.method}, net {config.net}, replay "
        f"{slots:,} slots) on {jax.default_backend()}: {which}; "
        + (f"last time {last:.0f} s" if last is not None else "first time on this machine"),
        flush=True,
    )
    start = time.perf_counter()
    programs.compile(state)
    seconds = time.perf_counter() - start
    save_compile_time(key, seconds)
    return seconds
