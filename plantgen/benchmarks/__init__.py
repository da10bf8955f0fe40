"""Benchmark scripts, run as ``python -m plantgen.benchmarks.NAME``; they print medians."""
