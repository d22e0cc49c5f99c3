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
import json
import sys
from pathlib import Path

from solar_jax.cli import apply_overrides, help_text, parse_config, split_arguments, valid_keys
from solar_jax.config import ConfigError, TrainConfig, config_from_dict
from solar_jax.experiments import command_main
from solar_jax.training.memory import memory_plan
from solar_jax.training.rundir import (
    AGGREGATE_FILE,
    SWEEP_FILE,
    check_resumable,
    default_run_dir,
    read_json,
)
from solar_jax.training.sweep import SWEEPABLE, Sweep, SweepRunner, aggregate_table
from solar_jax.training.trainer import plan
from solar_jax.viz.curves import plot_curves
from solar_jax.viz.report import Redraw, write_figures
from solar_jax.viz.runs import load_runs
from solar_jax.xla.cache import enable_compilation_cache

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
            f"{len(runner.runner.layout.devices)} device(s): replay and parameters "
            f"x{len(runner.specs)}"
        )
        lanes, total = runner.runner.layout, int(max(runner.runner.totals))
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
    print(aggregate_table(json.loads((sweep.directory / AGGREGATE_FILE).read_text())))
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
