"""Fixtures: a fake DYNAMIXEL bus on a pty and a bus/driver on it, with a leaked-thread check."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator

import pytest

from mmexec.drivers.dynamixel.bus import BusConfig, DxlBus
from mmexec.drivers.fakes.dynamixel import FakeDxlBus, wx250s_servos

#: generous adapter latency for a loaded 2-core CI machine: reply deadlines of ~100 ms
#: (2 x latency + wire time). At 20 ms a bring-up write once missed its 42 ms deadline
#: with two copies of tests/drivers running in parallel: the fake's thread was not
#: scheduled in time, not a protocol problem.
TEST_LATENCY = 0.05


@pytest.fixture
def no_leaks() -> Iterator[None]:
    before = threading.active_count()
    yield
    deadline = time.monotonic() + 2.0
    while threading.active_count() > before and time.monotonic() < deadline:
        time.sleep(0.01)
    assert threading.active_count() == before, [t.name for t in threading.enumerate()]


@pytest.fixture
def fake(no_leaks: None) -> Iterator[FakeDxlBus]:
    dev = FakeDxlBus(wx250s_servos())
    dev.start()
    try:
        yield dev
    finally:
        dev.stop()


@pytest.fixture
def bus(fake: FakeDxlBus) -> Iterator[DxlBus]:
    b = DxlBus(BusConfig(fake.port, latency=TEST_LATENCY))
    b.open()
    try:
        yield b
    finally:
        b.close()
