"""Shared test fixtures."""

import pytest

from kubric.core.assets import reset_uid_counters


@pytest.fixture(autouse=True)
def _fresh_uids():
    """Every test sees uids as in a fresh process (tests must not depend on run order)."""
    reset_uid_counters()
    yield
    reset_uid_counters()
