"""Shared helpers for the Robotiq tests: fast fakes, goal polling, thread-leak check."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator

import pytest


@pytest.fixture(autouse=True)
def no_leaked_threads() -> Iterator[None]:
    """Every test must leave the thread count where it found it."""
    baseline = threading.active_count()
    yield
    deadline = time.monotonic() + 2.0
    while threading.active_count() > baseline and time.monotonic() < deadline:
        time.sleep(0.01)
    assert threading.active_count() == baseline, [t.name for t in threading.enumerate()]
