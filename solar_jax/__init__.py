"""solar_jax: SOLAR (low-rank modular RL via muscle synergy) on JAX and MJX.

Data flows one way: morphology -> env -> replay -> agent and synergy -> trainer.

Importing the package keeps the terminal quiet and training off OpenGL: XLA's C++ log
lines (e.g. ``cpu_aot_loader`` on every persistent-cache hit) are off unless
``TF_CPP_MIN_LOG_LEVEL`` is set, and MuJoCo is imported with its OpenGL backend disabled
(``MUJOCO_GL`` is restored afterwards), since MuJoCo opens the backend on import and a
broken one, e.g. ``osmesa`` without libOSMesa, fails that import. Only videos render;
``solar_jax.viz.gl`` opens the ``MUJOCO_GL`` backend when one asks.
"""

import os
import sys

__version__ = "0.1.0"

os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "3")  # read when jaxlib loads


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
