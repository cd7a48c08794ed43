"""Shared helpers for the Kobuki tests: a started fake, bounded waits, thread accounting."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator

import pytest

from mmexec.drivers.fakes.kobuki import KobukiFake


def wait_until(pred: Callable[[], bool], timeout: float = 2.0) -> bool:
    """Poll ``pred`` every 5 ms until true or ``timeout`` seconds passed."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():
            return True
        time.sleep(0.005)
    return pred()


@pytest.fixture(name="wait_until")
def wait_until_fixture() -> Callable[..., bool]:
    """The :func:`wait_until` helper (test modules here are not a package)."""
    return wait_until


@pytest.fixture
def no_leaked_threads() -> Iterator[None]:
    before = threading.active_count()
    yield
    assert wait_until(lambda: threading.active_count() <= before, 2.0), [t.name for t in threading.enumerate()]


@pytest.fixture
def fake(no_leaked_threads: None) -> Iterator[KobukiFake]:
    f = KobukiFake()
    f.start()
    try:
        yield f
    finally:
        f.stop()
