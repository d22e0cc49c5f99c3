"""JAX's persistent compilation cache for the command-line entry points.

MJX steps take 20-40 s to compile per world on a CPU host (benchmarks/README.md);
with the cache, a second run of the same suite and settings loads them from disk.
``SOLAR_JAX_CACHE`` sets the folder; ``SOLAR_JAX_CACHE=off`` disables it.
"""

import os
from pathlib import Path

import jax

DEFAULT_DIR = Path.home() / ".cache" / "solar_jax" / "xla"


def enable_compilation_cache() -> Path | None:
    """Points JAX's persistent cache at ``$SOLAR_JAX_CACHE`` (default ``DEFAULT_DIR``)."""
    setting = os.environ.get("SOLAR_JAX_CACHE", str(DEFAULT_DIR))
    if setting.lower() in ("off", "0", "none", ""):
        return None
    path = Path(setting).expanduser()
    path.mkdir(parents=True, exist_ok=True)
    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    return path
