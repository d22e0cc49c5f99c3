"""Typed, frozen configuration. Counts and shapes are static; derived values are
properties. Each field's docstring says what it does and where its default comes from.
"""

import dataclasses


@dataclasses.dataclass(frozen=True)
class EnvConfig:
    """Physics and task settings of the MJX environment (SPEC sections 1.3 and 2)."""

    solver_iterations: int = 4
    """Constraint solver (Newton) iterations. MuJoCo's default is 100, which makes MJX
    6-10x slower under vmap; 4 is converged for these robots (benchmarks/README.md)."""

    ls_iterations: int = 8
    """Line-search iterations of the solver (MuJoCo's default: 50)."""

    robots_per_world: int = 1
    """How many robots share one merged MJX model. 1 (one model per morphology) was
    measured best on CPU for whh++: 1.5x the throughput of 3 per world, and within
    1e-5 of MuJoCo C over 100 steps where merged worlds drift to 1e-2 (the solver's
    iterations are shared); merged worlds compile faster. See benchmarks/README.md."""

    fix_humanoid_limb_types: bool = False
    """The reference feeds all-zero limb-type one-hots for 2-D humanoids (SPEC 2);
    True gives them their hip/knee/shoulder/elbow types instead."""

    max_episode_steps: int = 1000
    """Time limit, ended as a truncation (bootstrapped through)."""

    def __post_init__(self):
        for name in ("solver_iterations", "ls_iterations", "robots_per_world", "max_episode_steps"):
            if getattr(self, name) < 1:
                raise ValueError(f"env.{name} must be >= 1, got {getattr(self, name)}")
