"""Benchmarks, runnable as scripts or modules (python -m benchmarks.<name>).

Each imports ``solar_jax`` before jax (here for modules, in its script block for
scripts): the package sets jaxlib's C++ log level (read when jaxlib loads), XLA's flags
and MuJoCo's GL backend, so a benchmark runs with the settings users' runs have and
without a ``cpu_aot_loader`` line per persistent-cache hit."""

import solar_jax  # noqa: F401
