"""Morphologies: robots built from code (MjSpec), any planar MJCF, graph facts, suites.

>>> from solar_jax.morphology import load, get_suite
>>> load("walker_7_main").parents
(-1, 0, 1, 2, 0, 4, 5)
"""

from solar_jax.morphology.builder import build_spec, build_xml, write_all
from solar_jax.morphology.description import Robot, Task
from solar_jax.morphology.families import ROBOTS
from solar_jax.morphology.morphology import (
    Morphology,
    MorphologyError,
    from_model,
    generic_task,
    load,
)
from solar_jax.morphology.suites import SUITES, Suite, get_suite

__all__ = [
    "ROBOTS",
    "SUITES",
    "Morphology",
    "MorphologyError",
    "Robot",
    "Suite",
    "Task",
    "build_spec",
    "build_xml",
    "from_model",
    "generic_task",
    "get_suite",
    "load",
    "write_all",
]
