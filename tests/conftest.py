"""Shared test fixtures."""

import pytest

from kubric.randomness import unbind_worker_rng


@pytest.fixture(autouse=True)
def _fresh_process_state():
    """Every test sees uids and the worker rng as in a fresh process (no run-order dependence)."""
    unbind_worker_rng()
    yield
    unbind_worker_rng()
