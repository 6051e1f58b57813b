"""Benchmarks (`make bench`): long measurements. The test suite runs each one only at tiny size
(``KUBRIC_BENCH_SMOKE=1``, smoke_mode.py; tests/test_benchmarks_smoke.py)."""
