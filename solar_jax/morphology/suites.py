"""Suites: the sets of robots trained together, with SOLAR's train / held-out splits.

algorithm.md §1. ``cheetah++`` uses the SMP/Amorpheus split. A single robot name
(or MJCF path) is a valid suite of one.
"""

import dataclasses
import difflib
from pathlib import Path

from solar_jax.morphology.families import ROBOTS
from solar_jax.morphology.morphology import MorphologyError, load


@dataclasses.dataclass(frozen=True)
class Suite:
    name: str
    train: tuple[str, ...]
    held_out: tuple[str, ...] = ()

    @property
    def members(self) -> tuple[str, ...]:
        """Training robots first, then held-out ones: the order of the padded batch."""
        return self.train + self.held_out

    def max_agents(self) -> int:
        """N_max, the padded number of agents (builds each robot; cache the result)."""
        return max(load(name).num_agents for name in self.members)


def _suite(name: str, train: str, held_out: str = "") -> Suite:
    return Suite(name, tuple(train.split()), tuple(held_out.split()))


_WALKER = _suite(
    "walker++",
    "walker_2_main walker_4_main walker_5_main walker_7_main",
    "walker_3_main walker_6_main",
)
_HUMANOID = _suite(
    "humanoid++",
    "humanoid_2d_7_left_arm humanoid_2d_7_lower_arms humanoid_2d_7_right_leg "
    "humanoid_2d_8_left_knee humanoid_2d_8_right_knee humanoid_2d_9_full",
    "humanoid_2d_7_left_leg humanoid_2d_7_right_arm",
)
_HOPPER = _suite("hopper++", "hopper_3 hopper_4 hopper_5")
_CHEETAH = _suite(
    "cheetah++",
    "cheetah_2_back cheetah_2_front cheetah_3_back cheetah_3_front cheetah_4_allback "
    "cheetah_4_allfront cheetah_4_back cheetah_4_front cheetah_5_balanced cheetah_5_front "
    "cheetah_6_back cheetah_7_full",
    "cheetah_3_balanced cheetah_5_back cheetah_6_front",
)
_WHH = Suite(
    "whh++",
    _WALKER.train + _HUMANOID.train + _HOPPER.train,
    _WALKER.held_out + _HUMANOID.held_out + _HOPPER.held_out,
)

SUITES: dict[str, Suite] = {s.name: s for s in (_WALKER, _HUMANOID, _HOPPER, _WHH, _CHEETAH)}


def get_suite(name: str) -> Suite:
    """A registered suite, a single registered robot, or a single MJCF file."""
    if name in SUITES:
        return SUITES[name]
    if name in ROBOTS or (name.lower().endswith(".xml") and Path(name).is_file()):
        return Suite(name, (name,))
    close = difflib.get_close_matches(name, [*SUITES, *ROBOTS], n=3)
    hint = f" (did you mean {', '.join(close)}?)" if close else ""
    raise MorphologyError(
        f"unknown suite or morphology '{name}'{hint}; suites: {', '.join(SUITES)}; "
        f"robots: {', '.join(ROBOTS)}; or a path to an MJCF file"
    )
