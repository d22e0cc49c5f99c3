"""The tiny run that the trainer-level tests share: hopper_3, tiny networks, a short
warm-up. Its programs are compiled once per session (``tests/conftest.py`` fixtures and
the persistent cache, which the command-line runs load from). Its replay starts at 2048
slots (``trainer.replay_slots``), which runs of up to ~1000 steps never outgrow."""

from solar_jax.cli import parse_config

ARGS = [
    "morph=hopper_3",
    "net=tiny",
    "total_steps=600",  # the 500-step warm-up, then a few rounds of updates
    "td3.warmup_steps=500",
    "eval_every=500",
    "checkpoint_every=500",
    "progress=false",
]
CONFIG = parse_config(ARGS)


class Killed(Exception):
    """Stands in for the process dying between two rounds."""
