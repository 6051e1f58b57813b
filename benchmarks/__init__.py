"""Benchmarks (`make bench`): long measurements that never run in the test suite."""
