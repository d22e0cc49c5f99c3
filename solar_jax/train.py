"""``python -m solar_jax.train morph=humanoid++ [key=value ...]``: one training run.

Runs the paper's configuration (algorithm.md §3-6) for a suite; every field of
``solar_jax.config.TrainConfig`` can be overridden (``method=amorpheus``,
``total_steps=2e6``, ``update=fused``, ``net=tiny``, ``td3.lr=3e-4``, ...).
``resume=RUN_DIR`` continues a run from its last checkpoint. An experiment file first
(``python -m solar_jax.train experiments/quickstart.toml [key=value ...]``) supplies
the keys (``solar_jax.experiments``). At the end: a summary table and the figures in
RUN_DIR/plots. ``--help [SECTION]`` lists every key.
"""

import sys

from solar_jax.cli import help_text, parse_config
from solar_jax.config import TrainConfig
from solar_jax.experiments import command_main
from solar_jax.training.memory import memory_plan
from solar_jax.training.runner import Runner
from solar_jax.training.trainer import plan
from solar_jax.viz.report import Redraw, format_summary, summary, write_figures
from solar_jax.viz.runs import load_run
from solar_jax.xla.cache import enable_compilation_cache


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv

    def usage(section):
        return help_text(TrainConfig(), __doc__, section)

    return command_main(argv, "train", usage, train)


def train(argv: list[str]) -> int:
    """One run of a command line: its plan with ``dry_run``, else the run, then its
    summary and figures; 1 when the health check stopped it (``Runner.failures``, said
    when it happened). Errors propagate to ``one_line_errors``."""
    config = parse_config(argv)
    enable_compilation_cache()
    runner = Runner(config)
    if config.dry_run:
        print(plan(runner.trainer))
        print(memory_plan(runner.trainer, 1, runner.layout.devices, config.total_steps))
        return 0

    def figures(run_dirs=()) -> list:
        return write_figures(load_run(runner.run_dirs[0])) if config.plots else []

    runner.run(on_eval=Redraw(figures))  # at most once a minute, and at the end
    if runner.failures:  # the figures show the run up to its failed round
        figures()
        return 1
    print(format_summary(summary(load_run(runner.run_dirs[0])), figures()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
