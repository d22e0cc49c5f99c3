"""``python -m solar_jax.sweep morph=walker++ seeds=4 [td3.lr=[1e-4,3e-4]] [key=value ...]``

Trains every lane of a sweep (each seed × each combination of swept scalar
hyper-parameters) in one process as one program (``solar_jax.training.lanes``), compiled
once, its lanes split across the devices and vmapped on each. Every other key is ``train``'s
(``method=amorpheus``, ``net=tiny``, ``total_steps=2e6``, ...); seeds are ``seed``,
``seed + 1``, ... (``seeds`` of them; the paper's 4 by default).

The sweep directory holds ``sweep.json`` (the base config and the lanes), one run
directory per lane in ``train``'s format (``seed0/``, ``td3.lr=0.0003-seed1/``, ...:
``config.json``, ``metrics.jsonl``, ``checkpoints/``; ``train resume=`` and ``plot``
read them as single runs) and ``aggregate.json`` (final returns per variant: mean and
95% confidence interval over seeds). ``resume=SWEEP_DIR`` continues every lane from its
last checkpoint.
"""

import dataclasses
import itertools
import json
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

from solar_jax.cli import apply_overrides, help_text, parse_config, split_arguments, valid_keys
from solar_jax.compilation_cache import enable_compilation_cache
from solar_jax.config import TD3_TRACED, ConfigError, TrainConfig, config_from_dict, config_to_dict
from solar_jax.experiments import command_main
from solar_jax.stats import mean_ci
from solar_jax.training.logger import read_metrics
from solar_jax.training.memory import memory_plan
from solar_jax.training.programs import RoundPrograms
from solar_jax.training.rundir import (
    AGGREGATE_FILE,
    CONFIG_FILE,
    SWEEP_FILE,
    RunLock,
    check_resumable,
    default_run_dir,
    make_run_dir,
    read_json,
    write_file,
)
from solar_jax.training.runner import Runner
from solar_jax.training.trainer import TrainerState, plan
from solar_jax.viz.curves import plot_curves
from solar_jax.viz.report import Redraw, write_figures
from solar_jax.viz.runs import load_runs

SWEEPABLE = TD3_TRACED
"""``td3.<name>`` fields that may take a list: the scalars the jitted update reads as
traced values (``config.TD3_TRACED``), so lanes can differ."""
DEFAULT_SEEDS = 4  # the paper's
SWEEP_KEYS = (
    (
        f"seeds={DEFAULT_SEEDS}",
        "int",
        "How many seeds, from ``seed`` on: the lanes of one program (the paper's 4).",
    ),
    (
        "td3.<name>=[a,b,...]",
        "list",
        "A grid over a scalar hyper-parameter, crossed with the seeds: "
        + ", ".join(f"td3.{n}" for n in SWEEPABLE),
    ),
)


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


def _swept_values(key: str, text: str) -> tuple[float, ...]:
    if key not in valid_keys(TrainConfig):
        apply_overrides(TrainConfig(), {key: "0"})  # raises the unknown-key error
    name = key.removeprefix("td3.")
    if not key.startswith("td3.") or name not in SWEEPABLE:
        valid = ", ".join(f"td3.{n}" for n in SWEEPABLE)
        raise ConfigError(f"{key}={text}: only scalar hyper-parameters can be swept ({valid})")
    if not text.endswith("]"):
        raise ConfigError(f"{key}={text}: a list is written [a,b,...]")
    items = [item.strip() for item in text[1:-1].split(",") if item.strip()]
    if not items:
        raise ConfigError(f"{key}={text}: the list is empty")
    values = tuple(getattr(apply_overrides(TrainConfig(), {key: item}).td3, name) for item in items)
    if len(set(values)) != len(values):
        raise ConfigError(f"{key}={text}: a value is repeated")
    return values


def parse_sweep(argv: list[str]) -> Sweep:
    """The sweep of a command line (``seeds=N``, lists for ``SWEEPABLE`` keys, the rest as
    ``train``'s), or of a saved sweep with ``resume=SWEEP_DIR``."""
    overrides = split_arguments(TrainConfig, argv)
    if "resume" in overrides:
        return _resumed(overrides.pop("resume"), overrides)
    seeds_text = overrides.pop("seeds", str(DEFAULT_SEEDS))
    try:
        count = int(seeds_text)
    except ValueError:
        raise ConfigError(f"seeds={seeds_text}: expected an int (how many seeds)") from None
    if count < 1:
        raise ConfigError(f"seeds={seeds_text}: must be >= 1")
    grid = tuple(
        (key, _swept_values(key, text)) for key, text in overrides.items() if text.startswith("[")
    )
    fixed = [f"{key}={text}" for key, text in overrides.items() if not text.startswith("[")]
    config = parse_config(fixed)
    if not config.out:
        config = dataclasses.replace(config, out=str(default_run_dir(config, sweep=True)))
    sweep = Sweep(config, tuple(range(config.seed, config.seed + count)), grid)
    try:
        _ = sweep.lanes  # each lane's config validates its values
    except ValueError as err:
        raise ConfigError(str(err)) from None
    return sweep


def _resumed(directory: str, overrides: dict[str, str]) -> Sweep:
    path = Path(directory) / SWEEP_FILE
    if not path.is_file():
        raise ConfigError(f"resume={directory}: no {SWEEP_FILE} there (not a sweep directory)")
    check_resumable(directory, overrides, "sweep")
    saved = read_json(path)
    try:
        config = config_from_dict(TrainConfig, saved["config"])
        grid = tuple((key, tuple(values)) for key, values in saved.get("grid", {}).items())
        sweep = Sweep(config, tuple(saved["seeds"]), grid, resume=True)
        _ = sweep.lanes  # checks every name and value
    except (KeyError, TypeError, AttributeError, ValueError) as err:
        raise ConfigError(f"{path}: damaged ({type(err).__name__}: {err})") from None
    config = apply_overrides(dataclasses.replace(config, out=directory), overrides)
    return dataclasses.replace(sweep, config=config)


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


def summary(aggregate: dict) -> str:
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


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv

    def usage(section):
        return help_text(TrainConfig(), __doc__, section, SWEEP_KEYS)

    return command_main(argv, "sweep", usage, run_sweep)


def run_sweep(argv: list[str]) -> int:
    """One sweep of a command line: its plan with ``dry_run``, else every lane, then the
    aggregate and the figures (RUN_DIR/plots, unless ``plots=false``); 1 when the health
    check stopped a lane. Errors propagate to ``one_line_errors``."""
    sweep = parse_sweep(argv)
    enable_compilation_cache()
    runner = SweepRunner(sweep)
    if sweep.config.dry_run:
        print(plan(runner.trainer))
        print(
            f"{len(runner.specs)} lanes ({', '.join(spec.name for spec in runner.specs)}) on "
            f"{len(runner.runner.lanes.devices)} device(s): replay and parameters "
            f"x{len(runner.specs)}"
        )
        lanes, total = runner.runner.lanes, int(max(runner.runner.totals))
        print(memory_plan(runner.trainer, lanes.num_lanes, lanes.devices, total))
        return 0

    def figures(run_dirs: list[Path]) -> list[Path]:
        """The lanes' curves together, and each of ``run_dirs``' own figures."""
        if not sweep.config.plots:
            return []
        runs = load_runs([sweep.directory])
        paths = plot_curves(runs, sweep.directory / "plots", "eval")
        if all(run.records_of("round") for run in runs):
            paths += plot_curves(runs, sweep.directory / "plots", "episode")
        return paths + [p for run in runs if run.path in run_dirs for p in write_figures(run)]

    runner.run(on_eval=Redraw(figures))  # at most once a minute, and at the end
    print(summary(json.loads((sweep.directory / AGGREGATE_FILE).read_text())))
    for path in figures(runner.runner.run_dirs):
        if path.suffix == ".png":
            print(f"figure: {path}")
    print(f"done -> {sweep.directory}")
    if runner.runner.failures:  # each said when it happened
        print(f"error: {len(runner.runner.failures)} lane(s) stopped early", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
