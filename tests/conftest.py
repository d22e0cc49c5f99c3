"""Shared test fixtures.

The session uses a persistent XLA compilation cache in a fresh temporary folder
(``SOLAR_JAX_CACHE``, inherited by subprocesses): the command-line smoke runs load
the programs the in-process tests compiled instead of compiling them again.
"""

import os
import tempfile
from pathlib import Path

import pytest

from solar_jax.compilation_cache import enable_compilation_cache

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
REFERENCE_CONVERTED = SHARED / "reference" / "modular_rl" / "converted"

os.environ.setdefault("SOLAR_JAX_CACHE", tempfile.mkdtemp(prefix="solar_jax_test_cache_"))
enable_compilation_cache()


@pytest.fixture
def reference_dir() -> Path:
    """The reference morphology files (MuJoCo-2.3.3 re-saves); skips without ../shared."""
    if not REFERENCE_CONVERTED.is_dir():
        pytest.skip("../shared/reference/modular_rl/converted is not present")
    return REFERENCE_CONVERTED
