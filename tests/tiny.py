"""The tiny run that the trainer-level tests share: hopper_3 with the Euler integrator
(``tests/robots/hopper_3_euler.xml``, loaded as a user's MJCF file: its episodes
program compiles in two thirds of RK4's time, and the file path is exercised end to
end; it falls, so episodes end at different steps), tiny networks of one layer, two
environments, 200-step episodes at most, a 100-step warm-up. Its programs are compiled
once per session (``tests/conftest.py`` fixtures and the persistent cache, which the
command-line runs load from).

Sizes: a round writes at most 2 × 200 transitions, so the replay starts at 1024 slots
(``trainer.replay_slots``) and grows to 2048 past 624 stored; the 300-step runs never
grow it, the kill-and-resume run (900 steps) grows it once."""

from pathlib import Path

from solar_jax.cli import parse_config

ROBOT = Path(__file__).parent / "robots" / "hopper_3_euler.xml"
NAME = ROBOT.stem  # how runs name it

ARGS = [
    f"morph={ROBOT}",
    "net=tiny",
    # One transformer layer, the intra-synergy one: the update compiles in 6 CPU-s
    # instead of 9.5 (the networks' tests check the inter-synergy layers).
    "network.num_layers=1",
    "num_envs=2",  # the first to finish steps on until the other does (training/test_round.py)
    "env.max_episode_steps=200",
    "total_steps=300",  # the 100-step warm-up, then a few rounds of updates
    "td3.warmup_steps=100",
    "eval_every=100",
    "checkpoint_every=150",
    "progress=false",
]
CONFIG = parse_config(ARGS)

BOUNDED_ARGS = [
    *ARGS,
    "schedule=fast",
    "num_envs=4",
    "td3.batch_size=32",
    "td3.update_every=2",
    "round_steps=25",  # shorter than most episodes (40-110 steps): they span rounds
    "replay_capacity=2048",  # allocated whole: the update compiled once
    "eval_envs=4",  # evaluations in a program of their own, as many as collect
]
"""The fast schedule's rounds of bounded length, small: 100 transitions a round, and
its evaluations apart."""
BOUNDED = parse_config(BOUNDED_ARGS)


class Killed(Exception):
    """Stands in for the process dying between two rounds."""
