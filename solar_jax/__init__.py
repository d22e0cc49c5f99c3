"""solar_jax: SOLAR (low-rank modular RL via muscle synergy) on JAX and MJX.

Data flows one way: config (a leaf) -> morphology -> env -> replay -> synergy and
networks -> agent -> training -> viz -> the command line -> benchmarks -> the commands;
no module imports one above it (``tests/test_layers.py``).

Importing the package keeps the terminal quiet and training off OpenGL: XLA's C++ log
lines (e.g. ``cpu_aot_loader`` on every persistent-cache hit) are off unless
``TF_CPP_MIN_LOG_LEVEL`` is set, and MuJoCo is imported with its OpenGL backend disabled
(``MUJOCO_GL`` is restored afterwards), since MuJoCo opens the backend on import and a
broken one, e.g. ``osmesa`` without libOSMesa, fails that import. Only videos render;
``solar_jax.viz.gl`` opens the ``MUJOCO_GL`` backend when one asks.

It also turns off one XLA pass, unless ``XLA_FLAGS`` already names passes to disable
(flags are read when the backend starts, so this holds if solar_jax is imported before
JAX first computes): XLA:CPU's ``tree_reduction_rewriter`` splits long sums (the backward
pass's bias gradients, the attention's sums over keys) into windowed reductions that ran
several times slower than the plain fused loop on this project's CPUs; without it a TD3
iteration at the paper's sizes is about 10% faster (benchmarks/README.md, learner). Only
the order of float additions changes.

On jaxlib 0.10 and later it also keeps XLA:CPU from handing fusions to YNNPACK (unless
``XLA_FLAGS`` already sets ``xla_cpu_experimental_ynn_fusion_type``): with them jaxlib
0.10.2 ran a batched MJX step 3.6-4.1x slower on this project's CPUs, without them as fast
as jaxlib 0.9.2 (benchmarks/README.md, the learner). jaxlib 0.9.2 is left as it is: as
fast, and the same bits with the flag or without.
"""

import os
import sys
from importlib import metadata

__version__ = "0.1.0"

os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "3")  # read when jaxlib loads
XLA_DISABLED_PASSES = "--xla_disable_hlo_passes=tree_reduction_rewriter"
YNN_FUSIONS = "--xla_cpu_experimental_ynn_fusion_type="  # none


def xla_flags(flags: str, jaxlib_version: str) -> str:
    """``flags`` (``XLA_FLAGS``) with the package's settings (module docstring) added where
    they name an option ``flags`` leaves unset."""
    try:
        release = tuple(int(part) for part in jaxlib_version.split(".")[:2])
    except ValueError:  # not numbered as releases are: taken as a new one
        release = (0, 10)
    for flag in (XLA_DISABLED_PASSES, *([YNN_FUSIONS] if release >= (0, 10) else [])):
        if flag.split("=")[0] not in flags:
            flags = f"{flags} {flag}".strip()
    return flags


try:  # the version read without importing jaxlib, whose backend reads XLA_FLAGS once
    _jaxlib = metadata.version("jaxlib")
except metadata.PackageNotFoundError:
    _jaxlib = "0"
os.environ["XLA_FLAGS"] = xla_flags(os.environ.get("XLA_FLAGS", ""), _jaxlib)


def _import_mujoco_without_opengl() -> None:
    if "mujoco" in sys.modules:  # imported before us: its backend is already chosen
        return
    requested = os.environ.get("MUJOCO_GL")
    os.environ["MUJOCO_GL"] = "disable"
    try:
        import mujoco  # noqa: F401
    finally:
        if requested is None:
            del os.environ["MUJOCO_GL"]
        else:
            os.environ["MUJOCO_GL"] = requested


_import_mujoco_without_opengl()
