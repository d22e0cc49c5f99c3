"""solar_jax: SOLAR (low-rank modular RL via muscle synergy) on JAX and MJX.

Data flows one way: config (a leaf) -> morphology -> env -> replay -> synergy and
networks -> agent -> training -> viz -> the commands; no module imports one above
it (``tests/test_layers.py``).

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
"""

import os
import sys

__version__ = "0.1.0"

os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "3")  # read when jaxlib loads
XLA_DISABLED_PASSES = "--xla_disable_hlo_passes=tree_reduction_rewriter"
if "xla_disable_hlo_passes" not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {XLA_DISABLED_PASSES}".strip()


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
