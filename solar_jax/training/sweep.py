"""A sweep's lanes, their run, and the aggregate over seeds (``python -m solar_jax.sweep``).

A sweep is each seed × each combination of swept scalar hyper-parameters (``Lane``), one
run directory per lane inside the sweep's; ``SweepRunner`` trains them all through the
runner's one host loop as lanes of one program (``training.lanes``) and writes
``sweep.json`` and ``aggregate.json`` (final returns per variant: mean and 95% interval
over seeds).
"""

import dataclasses
import itertools
import json
from collections.abc import Callable
from pathlib import Path

import numpy as np

from solar_jax.config import TD3_TRACED, ConfigError, TrainConfig, config_to_dict
from solar_jax.stats import mean_ci
from solar_jax.training.logger import read_metrics
from solar_jax.training.programs import RoundPrograms
from solar_jax.training.rundir import (
    AGGREGATE_FILE,
    CONFIG_FILE,
    SWEEP_FILE,
    RunLock,
    make_run_dir,
    write_file,
)
from solar_jax.training.runner import Runner
from solar_jax.training.trainer import TrainerState

SWEEPABLE = TD3_TRACED
"""``td3.<name>`` fields that may take a list: the scalars the jitted update reads as
traced values (``config.TD3_TRACED``), so lanes can differ."""


@dataclasses.dataclass(frozen=True)
class Lane:
    """One run of a sweep."""

    name: str  # its run directory under the sweep's
    seed: int
    overrides: dict  # swept key -> value, e.g. {"td3.lr": 0.0003}
    config: TrainConfig


@dataclasses.dataclass(frozen=True)
class Sweep:
    config: TrainConfig  # the base: ``out`` is the sweep directory
    seeds: tuple[int, ...]
    grid: tuple[tuple[str, tuple[float, ...]], ...] = ()  # (("td3.lr", (1e-4, 3e-4)), ...)
    resume: bool = False

    @property
    def directory(self) -> Path:
        return Path(self.config.out)

    @property
    def variants(self) -> list[dict]:
        """Every combination of the swept values (one empty one without a grid)."""
        keys = [key for key, _ in self.grid]
        combinations = itertools.product(*(values for _, values in self.grid))
        return [dict(zip(keys, values, strict=True)) for values in combinations]

    @property
    def lanes(self) -> list[Lane]:
        """Each seed of each variant, named by its values written in full (``repr``: two
        different floats never share a name), its directory inside the sweep's."""
        lanes = []
        for overrides, seed in itertools.product(self.variants, self.seeds):
            name = lane_name(overrides, seed)
            run_dir = self.directory / name
            td3 = {key.removeprefix("td3."): value for key, value in overrides.items()}
            config = dataclasses.replace(
                self.config,
                seed=seed,
                out=str(run_dir),
                resume=str(run_dir) if self.resume and (run_dir / CONFIG_FILE).exists() else "",
                td3=dataclasses.replace(self.config.td3, **td3),
            )
            lanes.append(Lane(name, seed, overrides, config))
        if len({lane.name for lane in lanes}) < len(lanes):
            raise ConfigError(f"{self.directory}: two lanes of the sweep are the same run")
        return lanes

    def to_dict(self) -> dict:
        return {
            "config": config_to_dict(self.config),
            "seeds": list(self.seeds),
            "grid": {key: list(values) for key, values in self.grid},
            "lanes": [
                {"run_dir": lane.name, "seed": lane.seed, "overrides": lane.overrides}
                for lane in self.lanes
            ],
        }


def lane_name(overrides: dict, seed: int) -> str:
    """A lane's run directory name: ``td3.lr=0.0003-seed1``; a ``ConfigError`` for values
    that are not numbers (a ``sweep.json`` written by hand), so the name never leaves the
    sweep's directory."""
    for key, value in overrides.items():
        if key.removeprefix("td3.") not in SWEEPABLE or not isinstance(value, int | float):
            raise ConfigError(f"swept {key}={value!r}: not a sweepable number")
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise ConfigError(f"seed {seed!r}: expected an int")
    return "-".join([f"{k}={float(v)!r}" for k, v in overrides.items()] + [f"seed{seed}"])


class SweepRunner:
    """All lanes of a sweep: ``sweep.json``, then the lanes through the runner's one host
    loop (``solar_jax.training.runner.Runner``, S lanes: records, evaluation schedule,
    checkpoints into each lane's run directory), then ``aggregate.json``."""

    def __init__(self, sweep: Sweep, programs: RoundPrograms | None = None):
        self.sweep = sweep
        self.specs = sweep.lanes
        self.runner = Runner([spec.config for spec in self.specs], programs)
        self.trainer = self.runner.trainer
        self.config = sweep.config

    def run(
        self,
        on_round: Callable[[TrainerState, list[dict]], None] | None = None,
        on_eval: Callable[[list[Path]], None] | None = None,
    ) -> TrainerState:
        """Every lane to ``total_steps`` (``Runner.run``), then the aggregate."""
        directory = self.sweep.directory
        make_run_dir(directory)
        with RunLock(directory):
            if not self.sweep.resume and (directory / SWEEP_FILE).exists():
                raise ConfigError(
                    f"out={directory} already holds a sweep; continue it with "
                    f"resume={directory} or choose another out="
                )
            sweep_data = dataclasses.replace(self.sweep, config=self.config).to_dict()
            write_file(directory / SWEEP_FILE, json.dumps(sweep_data, indent=2))
            state = self.runner.run(on_round, on_eval)
            aggregate = aggregate_sweep(directory, self.sweep)
            write_file(directory / AGGREGATE_FILE, json.dumps(aggregate, indent=2))
        return state


FINAL_METRICS = ("eval/train_return", "eval/heldout_return")


def aggregate_sweep(directory: Path, sweep: Sweep) -> dict:
    """Per variant: each seed's last evaluation and the mean with its 95% confidence
    interval over seeds (Student t), for training and held-out morphologies."""
    variants = []
    lanes = sweep.lanes
    for overrides in sweep.variants:
        members = [lane for lane in lanes if lane.overrides == overrides]
        finals = []
        for member in members:
            evals = [r for r in read_metrics(directory / member.name) if r["kind"] == "eval"]
            finals.append(evals[-1] if evals else {})
        entry = {
            "overrides": overrides,
            "run_dirs": [member.name for member in members],
            "seeds": [member.seed for member in members],
            "env_steps": [final.get("env_steps") for final in finals],
        }
        for metric in FINAL_METRICS:
            values = [final[metric] for final in finals if metric in final]
            if len(values) == len(members):
                mean, low, high = mean_ci(np.asarray(values)[:, None])
                entry[metric] = {
                    "values": values,
                    "mean": float(mean[0]),
                    "ci95": [float(low[0]), float(high[0])],
                }
        variants.append(entry)
    return {
        "metric_note": "last evaluation of each seed; 95% Student-t interval",
        "variants": variants,
    }


def aggregate_table(aggregate: dict) -> str:
    """A table of the aggregate: one row per variant."""
    rows = ["variant | seeds | final train return (95% CI) | held-out"]
    for entry in aggregate["variants"]:
        name = " ".join(f"{k}={v:g}" for k, v in entry["overrides"].items()) or "-"
        cells = []
        for metric in FINAL_METRICS:
            if metric in entry:
                stats = entry[metric]
                low, high = stats["ci95"]
                cells.append(f"{stats['mean']:.1f} [{low:.1f}, {high:.1f}]")
            else:
                cells.append("-")
        rows.append(f"{name} | {len(entry['seeds'])} | {cells[0]} | {cells[1]}")
    return "\n".join(rows)
