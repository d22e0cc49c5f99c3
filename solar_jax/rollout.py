"""``python -m solar_jax.rollout morph=NAME steps=200 seed=0 out=traj.npz``

Runs one robot with uniform random actions (deterministic for a seed) and saves per
step: qpos, qvel (after the step), the unpadded observation ``[N, 19]`` the action
was taken from, action ``[N - 1]``, reward, terminated, truncated. For debugging and
for checking against other simulators.
"""

import dataclasses
import sys

import numpy as np

from solar_jax.cli import help_text, parse_overrides, wants_help
from solar_jax.config import ConfigError, EnvConfig
from solar_jax.env.single import make_env, random_rollout
from solar_jax.morphology import MorphologyError
from solar_jax.xla.cache import enable_compilation_cache
from solar_jax.xla.options import jit_physics


@dataclasses.dataclass(frozen=True)
class RolloutConfig:
    morph: str = "walker_7_main"
    """A registered robot name or an MJCF path."""
    steps: int = 200
    """Environment steps (episodes auto-reset)."""
    seed: int = 0
    """Seed of the reset noise and the actions."""
    out: str = "traj.npz"
    """Output file (NumPy .npz)."""
    env: EnvConfig = EnvConfig()
    """Physics and task settings."""

    def __post_init__(self):
        if self.steps < 1:
            raise ValueError(f"steps must be >= 1, got {self.steps}")


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    try:
        asked, section = wants_help(argv)
        if asked:
            print(help_text(RolloutConfig(), __doc__, section))
            return 0
        config = parse_overrides(RolloutConfig(), argv)
        env = make_env(config.morph, config.env)
    except (ConfigError, MorphologyError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    enable_compilation_cache()
    trajectory = jit_physics(random_rollout, static_argnums=(0, 1))(env, config.steps, config.seed)
    arrays = {k: np.asarray(v) for k, v in trajectory.items()}
    np.savez(config.out, **arrays, agents=np.array(env.morph.agents))
    episodes = int(arrays["terminated"].sum() + arrays["truncated"].sum())
    print(
        f"{env.morph.name}: {config.steps} steps, return {arrays['reward'].sum():.2f}, "
        f"{episodes} episode ends -> {config.out}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
