"""How long each program took to compile on this machine, for the next run's progress line
(``compile_times.json`` in the cache's folder)."""

import json
from pathlib import Path

from solar_jax.files import write_atomic
from solar_jax.xla.cache import cache_dir

TIMES_FILE = "compile_times.json"  # beside the cache's entries: {program key: seconds}


def _times_path() -> Path | None:
    folder = cache_dir()
    return None if folder is None else folder / TIMES_FILE


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
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(path, json.dumps(times, indent=1, sort_keys=True).encode())
    except OSError:  # a read-only or full cache: the next run just does not know
        pass
