"""What run and sweep directories hold, without JAX (``solar_jax.viz`` reads them too):
the one place their format is written down.

A run directory (default ``runs/<morph>-<method>-seed<seed>-<time>``): ``config.json``
(the config and what it resolved to), ``metrics.jsonl``, ``checkpoints/``. A sweep
directory (``runs/<morph>-<method>-sweep-<time>``): ``sweep.json``, ``aggregate.json``
and one run directory per lane.
"""

import json
import time
from pathlib import Path

from solar_jax.config import ConfigError, TrainConfig, config_from_dict

CONFIG_FILE = "config.json"
METRICS_FILE = "metrics.jsonl"
CHECKPOINTS = "checkpoints"
SWEEP_FILE = "sweep.json"
AGGREGATE_FILE = "aggregate.json"

RESUMABLE = (
    "total_steps",
    "eval_every",
    "eval_episodes",
    "checkpoint_every",
    "keep_checkpoints",
    "tensorboard",
    "progress",
    "plots",
)
"""Keys that may differ from the saved config when resuming; the rest must not."""

BOOKKEEPING = frozenset({"seed", "out", "resume", "dry_run", *RESUMABLE})
"""Top-level config keys that change neither the compiled programs nor what a line of
a plot compares: seeds are what a line averages over, the rest is bookkeeping. Traced
code must not read them: programs kept on disk are keyed without them
(``Trainer.fingerprint``)."""


def check_resumable(directory: str, overrides: dict[str, str], what: str) -> None:
    """One error line naming the ``overrides`` a resume of saved ``what`` (a run, a
    sweep) may not change."""
    fixed = sorted(k for k in overrides if k.split(".")[0] not in RESUMABLE)
    if fixed:
        raise ConfigError(
            f"resume={directory}: cannot change {', '.join(fixed)} of a saved {what}; "
            f"only {', '.join(RESUMABLE)} may be given"
        )


def default_run_dir(config: TrainConfig, sweep: bool = False) -> Path:
    """Where a run (or a sweep) without ``out`` writes: named by its suite, method and
    seed, and the time it started."""
    morph = Path(config.morph).stem if config.morph.endswith(".xml") else config.morph
    stamp = time.strftime("%Y%m%d-%H%M%S")
    what = "sweep" if sweep else f"seed{config.seed}"
    return Path("runs") / f"{morph}-{config.method}-{what}-{stamp}"


def has_checkpoint(run_dir: str | Path) -> bool:
    """Whether a run directory holds a checkpoint to resume from."""
    checkpoints = Path(run_dir) / CHECKPOINTS
    return checkpoints.is_dir() and any(checkpoints.iterdir())


def saved_config(run_dir: str | Path) -> TrainConfig:
    """The config a run directory was started with."""
    path = Path(run_dir) / CONFIG_FILE
    if not path.is_file():
        raise ConfigError(f"resume={run_dir}: no {CONFIG_FILE} there (not a run directory)")
    return config_from_dict(TrainConfig, json.loads(path.read_text())["config"])
