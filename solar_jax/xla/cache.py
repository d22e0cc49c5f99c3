"""The on-disk cache of compiled work, and the keys of what is kept there.

``SOLAR_JAX_CACHE`` sets the folder (default ``~/.cache/solar_jax/xla``; ``off``
disables it). It holds XLA's executables (JAX's persistent compilation cache), the traced
programs themselves (``programs/``: ``solar_jax.xla.programs``) and how long each took
to compile here (``compile_times.json``: ``solar_jax.xla.times``). MJX steps take 20-40 s
to compile per world on a CPU, so a second run of the same suite and settings loads them.
"""

import gc
import hashlib
import json
import os
import sys
from importlib import metadata
from pathlib import Path

import jax

DEFAULT_DIR = Path.home() / ".cache" / "solar_jax" / "xla"
PROGRAMS_DIR = "programs"
PROGRAM_FORMAT = 2  # raise when what a program file holds changes
programs_dir: Path | None = None
"""The traced programs' folder once ``enable_compilation_cache`` has run; None: off."""


# Python's cyclic garbage collector while JAX traces: at its default thresholds (700, 10,
# 10) it runs a young collection every 700 new objects, and tracing makes millions (every
# tracer, equation and avals tuple). At these, humanoid++'s episodes program (paper sizes)
# traced and lowered in 21.9-23.4 s against 26.4-29.2, its update in 6.3-6.7 against
# 7.9-8.0 (two processes each, in turn); the tiny test run's in 3.7 against 4.6 and 2.4
# against 3.0 (the test suite, whose workers hold large heaps, gained nothing measurable).
# Unreachable cycles are still collected, in larger batches.
GC_THRESHOLDS = (50_000, 20, 100)


def enable_compilation_cache() -> Path | None:
    """Points JAX's persistent cache at ``$SOLAR_JAX_CACHE`` (default ``DEFAULT_DIR``) and
    keeps traced programs in its ``programs/`` (``solar_jax.xla.programs``). The commands call it
    first, so it also sets the garbage collector's thresholds for tracing
    (``GC_THRESHOLDS``), cache or not."""
    global programs_dir
    gc.set_threshold(*GC_THRESHOLDS)
    path = cache_dir()
    if path is None:
        programs_dir = None
        return None
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / f".write-test-{os.getpid()}"
        probe.touch()
        probe.unlink()
    except OSError as err:  # read-only, or a file in the way: run without it
        print(
            f"warning: SOLAR_JAX_CACHE={path}: cannot write there ({err.strerror or err}); "
            "running without the compilation cache",
            file=sys.stderr,
        )
        programs_dir = None
        return None
    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    programs_dir = path / PROGRAMS_DIR
    return path


def cache_dir() -> Path | None:
    """The cache's folder as ``SOLAR_JAX_CACHE`` sets it; None when it is off."""
    setting = os.environ.get("SOLAR_JAX_CACHE", str(DEFAULT_DIR))
    if setting.lower() in ("off", "0", "none", ""):
        return None
    return Path(setting).expanduser()


_VERSIONED = ("jax", "jaxlib", "mujoco", "mujoco-mjx", "flax", "optax", "numpy")


def _source_digest() -> str:
    """Every Python file of the ``solar_jax`` package, hashed (what traced code reads)."""
    package = Path(__file__).resolve().parents[1]
    digest = hashlib.sha256()
    for path in sorted(package.rglob("*.py")):
        digest.update(str(path.relative_to(package)).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def program_fingerprint(*parts: bytes | str) -> str:
    """A key for programs traced from ``parts`` (e.g. the config less its bookkeeping keys,
    the MuJoCo models) by this package's source, under these library versions and this
    backend. Anything a traced function reads must be in one of these."""
    digest = hashlib.sha256()
    versions = [(name, metadata.version(name)) for name in _VERSIONED]
    device = jax.devices()[0]
    tracing = [jax.config.jax_enable_x64, jax.config.jax_default_matmul_precision]
    header = [PROGRAM_FORMAT, sys.version, versions, device.platform, device.device_kind, tracing]
    for part in (json.dumps(header), _source_digest(), *parts):
        digest.update(part if isinstance(part, bytes) else part.encode())
        digest.update(b"\0")
    return digest.hexdigest()
