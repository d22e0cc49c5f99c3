"""JAX's persistent compilation cache for the command-line entry points.

MJX steps take 20-40 s to compile per world on a CPU host (benchmarks/README.md);
with the cache, a second run of the same suite and settings loads them from disk.
``SOLAR_JAX_CACHE`` sets the folder; ``SOLAR_JAX_CACHE=off`` disables it. The folder
also remembers how long each program took to compile here (``compile_times.json``),
so a run's progress line can say what to expect.
"""

import json
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


TIMES_FILE = "compile_times.json"  # beside the cache's entries: {program key: seconds}


def _times_path() -> Path | None:
    setting = os.environ.get("SOLAR_JAX_CACHE", str(DEFAULT_DIR))
    if setting.lower() in ("off", "0", "none", ""):
        return None
    return Path(setting).expanduser() / TIMES_FILE


def _read_times(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):  # none yet, or a torn write: no history
        return {}


def last_compile_time(key: str) -> float | None:
    """Seconds the last compilation of ``key`` took on this machine (None: never seen, or
    the cache is off)."""
    path = _times_path()
    return None if path is None else _read_times(path).get(key)


def save_compile_time(key: str, seconds: float) -> None:
    """Remembers how long compiling ``key`` took, for the next run's progress line."""
    path = _times_path()
    if path is None:
        return
    times = _read_times(path) | {key: round(seconds, 1)}
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(times, indent=1, sort_keys=True))
    tmp.replace(path)
