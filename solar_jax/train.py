"""``python -m solar_jax.train morph=humanoid++ [key=value ...]``: one training run.

Runs the paper's configuration (SPEC sections 3-6) for a suite; every field of
``solar_jax.config.TrainConfig`` can be overridden (``method=amorpheus``,
``total_steps=2e6``, ``update=fused``, ``net=tiny``, ``td3.lr=3e-4``, ...).
``resume=RUN_DIR`` continues a run from its last checkpoint. An experiment file first
(``python -m solar_jax.train experiments/quickstart.toml [key=value ...]``) supplies
the keys (``solar_jax.experiments``). At the end: a summary table and the figures in
RUN_DIR/plots. ``--help [SECTION]`` lists every key.
"""

import dataclasses
import sys

import jax

from solar_jax.checkpoint import CheckpointError
from solar_jax.cli import ConfigError, apply_overrides, help_text, split_arguments
from solar_jax.compilation_cache import enable_compilation_cache
from solar_jax.config import TrainConfig
from solar_jax.experiments import command_main
from solar_jax.morphology import MorphologyError
from solar_jax.networks import NetworkConfig
from solar_jax.rundir import check_resumable
from solar_jax.runner import Runner, saved_config
from solar_jax.trainer import Trainer
from solar_jax.viz.report import format_summary, summary, write_figures
from solar_jax.viz.runs import load_run


def parse_config(argv: list[str]) -> TrainConfig:
    """The config of a command line.

    ``net=tiny`` (or ``small``) starts from that network preset, ``network.*`` on top. With
    ``resume=RUN_DIR`` the saved run's config is the base, and only the keys in
    ``RESUMABLE`` may be given besides.
    """
    overrides = split_arguments(TrainConfig, argv)
    if "resume" in overrides:
        run_dir = overrides.pop("resume")
        check_resumable(run_dir, overrides, "run")
        base = dataclasses.replace(saved_config(run_dir), resume=run_dir, out=run_dir)
        return apply_overrides(base, overrides)
    base = TrainConfig()
    if overrides.get("net") in ("small", "tiny"):
        net = overrides["net"]
        base = TrainConfig(net=net, network=NetworkConfig.preset(net))
    return apply_overrides(base, overrides)


def plan(trainer: Trainer) -> str:
    """What a run would build: suite, sizes, parameter counts, replay memory."""
    config = trainer.config
    actor, critic = jax.eval_shape(trainer.networks.init, jax.random.PRNGKey(0))
    first = jax.eval_shape(trainer.init, config.seed).replay
    full = jax.eval_shape(lambda: trainer.init(config.seed, slots=trainer.capacity)).replay
    replay_bytes = _bytes(full)
    names = trainer.names
    return "\n".join(
        [
            f"suite {config.morph}: train {', '.join(names[: trainer.num_train])}",
            f"  held out: {', '.join(names[trainer.num_train :]) or '-'}",
            f"method {config.method}, update {config.update}, net {config.net}, "
            f"N_max {trainer.env.n_max}, {config.num_envs} env(s) per morphology",
            f"parameters: actor {_size(actor):,}, twin critics {_size(critic):,}",
            f"replay: {trainer.capacity:,} transitions per morphology, "
            f"{replay_bytes / 2**30:.2f} GiB on the device when full (allocated as it "
            f"fills, from {first.capacity:,}); a round's staging buffer "
            f"{_bytes(trainer.staging()) / 2**20:,.1f} MiB",
            f"total {config.total_steps:,} counted env steps (all morphologies); warm-up "
            f"{config.td3.warmup_steps * trainer.num_morphs:,}",
        ]
    )


def _bytes(tree) -> int:
    return sum(x.size * x.dtype.itemsize for x in jax.tree.leaves(tree))


def _size(tree) -> int:
    return sum(x.size for x in jax.tree.leaves(tree))


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv

    def usage(section):
        return help_text(TrainConfig(), __doc__, section)

    return command_main(argv, "train", usage, train)


def train(argv: list[str]) -> int:
    """One run of a command line: its plan with ``dry_run``, else the run, then its
    summary and figures; 2 after a one-line error."""
    try:
        config = parse_config(argv)
        enable_compilation_cache()
        runner = Runner(config)
    except (ConfigError, MorphologyError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    if config.dry_run:
        print(plan(runner.trainer))
        return 0

    def figures(record=None) -> list:
        return write_figures(load_run(runner.run_dir)) if config.plots else []

    try:
        runner.run(on_eval=figures)
    except (CheckpointError, ConfigError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(format_summary(summary(load_run(runner.run_dir)), figures()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
