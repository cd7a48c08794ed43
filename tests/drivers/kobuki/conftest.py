"""Shared helpers for the Kobuki tests: a started fake, bounded waits, thread accounting."""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator

import pytest
from driverkit import wait_for as wait_until

from mmexec.drivers.fakes.kobuki import KobukiFake


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
