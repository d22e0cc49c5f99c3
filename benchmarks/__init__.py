"""Benchmarks, runnable as scripts or modules (python -m benchmarks.<name>)."""
