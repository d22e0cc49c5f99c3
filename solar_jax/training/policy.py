"""A run's trained policy, restored for rollouts (videos, zero-shot evaluation)."""

from pathlib import Path

import jax

from solar_jax.training.checkpoint import Checkpointer, CheckpointError
from solar_jax.training.rundir import BEST, CHECKPOINTS, has_checkpoint, saved_config
from solar_jax.training.runner import restore_run
from solar_jax.training.trainer import Trainer, TrainerState


def restore_policy(
    run_dir: str | Path, checkpoint: str = "latest"
) -> tuple[Trainer, TrainerState, int]:
    """(trainer, state, round) of a run's latest readable checkpoint, restored as a resume
    restores it (``restore_run``), or (``checkpoint="best"``) of its best evaluation's
    policy (``checkpoints/best``: the state's actor and clusterings; the rest of it is
    shapes only). A run without such a checkpoint is a one-line ``CheckpointError``."""
    if not has_checkpoint(run_dir):
        raise CheckpointError(f"{run_dir}: no checkpoints/ to take a policy from")
    config = saved_config(run_dir)
    trainer = Trainer(config)
    if checkpoint == "best":
        best = Path(run_dir) / CHECKPOINTS / BEST
        if not best.is_dir():
            raise CheckpointError(
                f"{run_dir}: no {CHECKPOINTS}/{BEST} (no evaluation after training)"
            )
        shapes = jax.eval_shape(lambda: trainer.init(config.seed))
        template = {"actor": shapes.agent.actor, "synergy": shapes.synergy}
        checkpointer = Checkpointer(best, keep=1)
        try:
            policy, meta = checkpointer.restore(template)
        finally:
            checkpointer.close()
        agent = shapes.agent.replace(actor=policy["actor"])
        return trainer, shapes.replace(agent=agent, synergy=policy["synergy"]), int(meta["step"])
    state, meta, checkpointer = restore_run(trainer, config, Path(run_dir))
    checkpointer.close()
    return trainer, state, int(meta["step"])
