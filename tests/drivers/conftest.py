"""Shared fixtures of the driver tests."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator

import pytest


@pytest.fixture
def no_leaked_threads() -> Iterator[None]:
    """The test must leave the thread count where it found it (threads still ending are
    given 2 s). Folders whose every test should be checked use it from an autouse fixture."""
    baseline = threading.active_count()
    yield
    deadline = time.monotonic() + 2.0
    while threading.active_count() > baseline and time.monotonic() < deadline:
        time.sleep(0.01)
    assert threading.active_count() == baseline, [t.name for t in threading.enumerate()]
