"""``jax.jit`` for programs a test compiles only to check what they compute: on a CPU,
without LLVM's optimisations (XLA's ``xla_backend_optimization_level=0``).

Such a program runs a handful of times, so its compile is the test's cost: the
all-robots env's step compiles in 16 s instead of 31 s at -O0 (the Euler world, one
core), and the modules that use this helper spent 15% less CPU in the default suite (636
-> 539 s, two runs of one day; the other modules' 673 -> 682 s). Programs that run
many steps (the tiny runs of ``tests.tiny``, the probe tasks: at -O0 they ran 1.5-4x
longer than they saved) compile at -O1 in the test session (``SESSION_FLAGS``): the tiny
group's modules and the probe took 127 s against 155 s at the default level, alone in
one process. Every test program also uses XLA's older CPU fusion emitters: a tiny
update compiled in 4.2 s against 8.1 at -O0 (9.0 against 10.8 at -O1), the tests' Euler
hopper's step at -O1 in 7.7 s against 13.1, and both ran as fast or faster (the package
keeps the new ones: humanoid++'s 8-world physics compiled far slower with the old,
``solar_jax/xla/options.py``). The default suite: 641 -> 530 s in one
window (two workers). Everything the package compiles for users keeps its own settings
(CI's quickstart checks that path). The float rounding differs between levels, which is
why no test compares bits across them.
"""

import functools

import jax
import jax.numpy as jnp

from solar_jax.xla.options import physics_compiler_options

UNOPTIMISED = {"xla_backend_optimization_level": 0}
SESSION_FLAGS = "--xla_backend_optimization_level=1 --xla_cpu_use_fusion_emitters=false"
"""The test session's XLA settings for every program (``tests/conftest.py``): LLVM's -O1
where a program does not ask for -O0, and XLA's older CPU fusion emitters (the package
keeps the new ones: the module docstring)."""


def _options(base: dict) -> dict:
    """``base`` at -O0 on a CPU; as it is elsewhere (accelerators are not measured)."""
    return {**base, **UNOPTIMISED} if jax.default_backend() == "cpu" else base


def jit(fn=None, **jit_options):
    """``jax.jit(fn, **jit_options)`` at -O0 on a CPU; also a decorator, bare or with options."""
    if fn is None:
        return functools.partial(jit, **jit_options)
    return jax.jit(fn, compiler_options=_options({}), **jit_options)


def jit_physics(fn, **jit_options):
    """``xla.options.jit_physics`` (the physics' skipped XLA passes) at -O0 on a CPU."""
    return jax.jit(fn, compiler_options=_options(physics_compiler_options()), **jit_options)


def copy(tree):
    """Every leaf of ``tree`` copied, in one program (eagerly, each leaf shape compiles its
    own: 31 for the tiny run's state): for programs that donate their arguments."""
    return _copy()(tree)


@functools.cache
def _copy():  # jitted on first use: ``jit`` asks for the backend, which must wait (conftest)
    return jit(lambda tree: jax.tree.map(jnp.copy, tree))
