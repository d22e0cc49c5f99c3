"""``jax.jit`` for programs a test compiles only to check what they compute: on a CPU,
without LLVM's optimisations (XLA's ``xla_backend_optimization_level=0``).

Such a program runs a handful of times, so its compile is the test's cost: the
all-robots env's step compiles in 16 s instead of 31 s at -O0 (the Euler world, one
core), and the modules that use this helper spent 15% less CPU in the default suite (636
-> 539 s, two runs of one day; the other modules' 673 -> 682 s). Programs that run
many steps keep the default level (the tiny runs of ``tests.tiny``, the probe tasks: at
-O0 they ran 1.5-4x longer than they saved), and so does everything the package
compiles for users (CI's quickstart checks that path). The float
rounding differs from the default level's, which is why no test compares bits across
the two.
"""

import functools

import jax

from solar_jax.compilation_cache import physics_compiler_options

UNOPTIMISED = {"xla_backend_optimization_level": 0}


def _options(base: dict) -> dict:
    """``base`` at -O0 on a CPU; as it is elsewhere (accelerators are not measured)."""
    return {**base, **UNOPTIMISED} if jax.default_backend() == "cpu" else base


def jit(fn=None, **jit_options):
    """``jax.jit(fn, **jit_options)`` at -O0 on a CPU; also a decorator, bare or with options."""
    if fn is None:
        return functools.partial(jit, **jit_options)
    return jax.jit(fn, compiler_options=_options({}), **jit_options)


def jit_physics(fn, **jit_options):
    """``compilation_cache.jit_physics`` (the physics' skipped XLA passes) at -O0 on a CPU."""
    return jax.jit(fn, compiler_options=_options(physics_compiler_options()), **jit_options)
