"""Shared test fixtures."""

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
REFERENCE_CONVERTED = SHARED / "reference" / "modular_rl" / "converted"


@pytest.fixture
def reference_dir() -> Path:
    """The reference morphology files (MuJoCo-2.3.3 re-saves); skips without ../shared."""
    if not REFERENCE_CONVERTED.is_dir():
        pytest.skip("../shared/reference/modular_rl/converted is not present")
    return REFERENCE_CONVERTED
