"""Shared test fixtures.

The session runs with two fake CPU devices (sweeps shard across them), XLA settings
that compile faster (``tests/unoptimised.py``) and a persistent XLA compilation cache
in a fresh temporary folder (``SOLAR_JAX_CACHE``; all inherited by subprocesses): the
command-line smoke runs load the programs the in-process tests compiled instead of
compiling them again.
"""

import os
import tempfile
from pathlib import Path

import chex
import pytest

from solar_jax.xla.cache import enable_compilation_cache
from tests import unoptimised

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
REFERENCE_CONVERTED = SHARED / "reference" / "modular_rl" / "converted"

# XLA's settings for the session (``unoptimised.SESSION_FLAGS``: LLVM's -O1, the older
# CPU fusion emitters; programs a test only checks ask for -O0), set before JAX starts
# its backend and inherited by the command-line runs, so they load what it compiled.
os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {unoptimised.SESSION_FLAGS}".strip()
# Two CPU devices for the whole session (before any JAX operation), so sweeps shard
# their lanes as on a multi-device host; single-device programs run on the first.
chex.set_n_cpu_devices(2)
os.environ.setdefault("SOLAR_JAX_CACHE", tempfile.mkdtemp(prefix="solar_jax_test_cache_"))
enable_compilation_cache()


GROUPS = {
    "tests/training/test_runner.py": "tiny",
    "tests/training/test_round.py": "tiny",
    "tests/training/test_bounded_round.py": "tiny",
    "tests/test_faults.py": "tiny",
    "tests/training/test_sweep.py": "sweep",
    "tests/viz/test_real_runs.py": "sweep",
}
"""Modules that share compiled programs run on one worker (under pytest-xdist): the
single runs of ``tests.tiny`` (``tiny_run``), and its sweeps (``tiny_lanes``; their
single runs load ``tiny_run``'s programs from the persistent cache when the tiny group
has compiled them already, else compile their own)."""
LONGEST = (
    "tests/env/test_batch.py",  # 95 s (CPU-s in one profiled run of the suite, 2026-12-04)
    "sweep",  # 91 s
    "tiny",  # 75 s
    "tests/training/test_trainer.py",  # 37 s
    "tests/networks/test_registry.py",  # 30 s
    "tests/networks/test_solar.py",  # 30 s
    "tests/synergy/test_affinity_propagation.py",  # 24 s
    "tests/agent/test_update.py",  # 22 s
    "tests/env/test_single.py",  # 21 s
    "tests/agent/test_probe.py",  # 20 s
    "tests/networks/test_reference_forward.py",  # 14 s
)
"""Scopes of 14 s or more, sent first, longest first (the two workers start with the env
batch and the sweeps; the tiny group goes to the first free, and whichever of the sweep
and the tiny group comes second loads the single runs' programs the first compiled, in
process or from the persistent cache); the rest (each under 12 s) follow in collection
order, so that the two workers end close together."""
FIRST = {scope: rank for rank, scope in enumerate(LONGEST)}


def _scope(nodeid: str) -> str:
    module = nodeid.split("::")[0]
    return GROUPS.get(module, module)


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """Whole groups and modules to a worker (their fixtures and compiled programs are
    shared; ``-n 2`` in pyproject.toml: compiles are mostly single-threaded), in the
    collection's order (``pytest_collection_modifyitems``)."""
    from xdist.scheduler import LoadScopeScheduling

    config.option.loadscopereorder = False  # the collection's order (below)

    class GroupScheduling(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return _scope(nodeid)

    return GroupScheduling(config, log)


def pytest_collection_modifyitems(config, items):
    items.sort(key=lambda item: FIRST.get(_scope(item.nodeid), len(FIRST)))  # stable


@pytest.fixture(scope="session")
def tiny_trainer():
    """One ``Trainer`` of ``tests.tiny.CONFIG`` for the session."""
    from solar_jax.training.trainer import Trainer
    from tests.tiny import CONFIG

    return Trainer(CONFIG)


@pytest.fixture(scope="session")
def tiny_run(tiny_trainer):
    """Its round for single runs (``RoundPrograms`` of one lane), compiled once."""
    from solar_jax.training.lanes import SingleLane
    from solar_jax.training.programs import RoundPrograms

    return RoundPrograms(SingleLane(tiny_trainer))


@pytest.fixture(scope="session")
def tiny_bounded():
    """The round of ``tests.tiny.BOUNDED`` (rounds of bounded length) for single runs."""
    from solar_jax.training.lanes import SingleLane
    from solar_jax.training.programs import RoundPrograms
    from solar_jax.training.trainer import Trainer
    from tests.tiny import BOUNDED

    return RoundPrograms(SingleLane(Trainer(BOUNDED)))


@pytest.fixture(scope="session")
def tiny_lanes(tiny_trainer):
    """Its round vmapped over two lanes, sharded over the session's two devices."""
    from solar_jax.training.lanes import Lanes
    from solar_jax.training.programs import RoundPrograms

    return RoundPrograms(Lanes(tiny_trainer, 2))


@pytest.fixture(scope="session")
def tiny_sweep(tmp_path_factory, tiny_lanes):
    """A two-seed sweep of ``tests.tiny.CONFIG``: (its directory, its final lane-stacked
    state). Sweep tests check it against single runs; plot tests draw from it."""
    from solar_jax.sweep import parse_sweep
    from solar_jax.training.sweep import SweepRunner
    from tests.tiny import ARGS

    out = tmp_path_factory.mktemp("tiny_sweep") / "seeds"
    state = SweepRunner(parse_sweep([*ARGS, "seeds=2", f"out={out}"]), tiny_lanes).run()
    return out, state


@pytest.fixture
def reference_dir() -> Path:
    """The reference morphology files (MuJoCo-2.3.3 re-saves); skips without ../shared."""
    if not REFERENCE_CONVERTED.is_dir():
        pytest.skip("../shared/reference/modular_rl/converted is not present")
    return REFERENCE_CONVERTED
