"""Warnings before and during a run that would take too long where it runs, from the
update cost measured on this project's CPUs and from the run's own rate."""

import jax

from solar_jax.config import TrainConfig
from solar_jax.training.logger import duration

LONG_RUN_S = 2 * 3600  # a projection above this is worth a warning
PROJECT_AFTER_ROUNDS = 3


def long_run_warning(done: int, total: int, steps: int, seconds: float) -> str | None:
    """A warning when, at ``steps`` counted steps in ``seconds`` so far, the remaining
    ``total - done`` steps take more than ``LONG_RUN_S``; else None."""
    if steps <= 0 or seconds <= 0 or done >= total:
        return None
    remaining = (total - done) * seconds / steps
    if remaining <= LONG_RUN_S:
        return None
    return (
        f"warning: at this run's rate so far ({steps / seconds:,.0f} counted env steps/s on "
        f"{jax.default_backend()}), the remaining {total - done:,} steps take about "
        f"{duration(remaining)}; a smaller net= or total_steps=, or an accelerator, finishes "
        "sooner (README: the quickstart). Continuing."
    )


CPU_PAPER_UPDATE_S = 0.026
"""The fastest TD3 update measured at the paper's network sizes on the project's 2-core
CPU (hopper_3; humanoid_2d_9_full: 0.065-0.072 s; benchmarks/results/learner_paper_*)."""


def paper_on_cpu_warning(config: TrainConfig, num_train: int, num_morphs: int) -> str | None:
    """Before compiling: the paper's networks on a CPU backend cannot finish a long run
    in reasonable time; a lower bound from the measured update cost, or None."""
    if jax.default_backend() != "cpu" or config.net != "default":
        return None
    # One per td3.update_every counted steps per training robot.
    updates = config.total_steps * num_train / num_morphs / config.td3.update_every
    floor = updates * CPU_PAPER_UPDATE_S
    if floor <= LONG_RUN_S:
        return None
    return (
        f"warning: the paper's network sizes on a CPU: {config.total_steps:,} steps need "
        f"~{updates:,.0f} TD3 updates, at least {CPU_PAPER_UPDATE_S * 1000:.0f} ms each "
        f"here (python -m solar_jax.bench learner), so at least {duration(floor)}; "
        "net=small or tiny, or an accelerator, finishes sooner (README: the quickstart). "
        "The run's own rate follows its first rounds. Continuing."
    )
