"""What run and sweep directories hold, without JAX (``solar_jax.viz`` reads them too).

A run directory: ``config.json`` (the config and what it resolved to),
``metrics.jsonl``, ``checkpoints/``. A sweep directory: ``sweep.json``,
``aggregate.json`` and one run directory per lane.
"""

from solar_jax.cli import ConfigError

CONFIG_FILE = "config.json"
METRICS_FILE = "metrics.jsonl"
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
