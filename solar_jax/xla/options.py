"""XLA compiler options per kind of program, measured on this project's CPUs."""

import os
import re
from collections.abc import Callable

import jax

# XLA passes the physics program compiles without (``physics_compiler_options``): on a CPU,
# loop-invariant code motion and constant sinking over MJX's nested while loops take about
# a third of its compile time, and its steps run no slower without them (docs/design.md).
# Not measured on accelerators, where they stay on. XLA's older CPU fusion emitters compile
# one world faster but a suite's joint program slower, so the package keeps the new ones;
# the tests, whose programs are small, use the old (``tests/unoptimised.py``).
PHYSICS_SKIPPED_PASSES = ("while-loop-invariant-code-motion", "while-loop-constant-sinking")


def physics_compiler_options() -> dict[str, str]:
    """XLA options for programs with the physics: on a CPU, the passes ``XLA_FLAGS``
    disables (the option replaces that list) plus ``PHYSICS_SKIPPED_PASSES``."""
    if jax.default_backend() != "cpu":
        return {}
    flags = re.findall(r"--xla_disable_hlo_passes=(\S+)", os.environ.get("XLA_FLAGS", ""))
    disabled = [p for flag in flags for p in flag.split(",") if p]
    passes = dict.fromkeys([*disabled, *PHYSICS_SKIPPED_PASSES])  # ordered, no repeats
    return {"xla_disable_hlo_passes": ",".join(passes)}


def jit_physics(fn: Callable, **jit_options) -> Callable:
    """``jax.jit(fn, **jit_options)`` for a function that steps the physics, compiled with
    ``physics_compiler_options`` (also through ``.lower(...).compile()``)."""
    return jax.jit(fn, compiler_options=physics_compiler_options(), **jit_options)


# The networks' initialisation (threefry draws for every parameter, run once per run)
# compiled at LLVM's -O1 on a CPU: 1.1-2.5 s against 3.2-4.6 s at the default level,
# with the same bits (measured for SOLAR tiny, small and default, Amorpheus and the
# monolithic MLP); -O0 would change the bits.
INIT_COMPILER_OPTIONS = {"xla_backend_optimization_level": 1}
