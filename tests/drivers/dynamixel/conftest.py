"""Fixtures: a fake DYNAMIXEL bus on a pty and a bus/driver on it, with a leaked-thread check."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator

import pytest

from mmexec.drivers.dynamixel.bus import BusConfig, DxlBus
from mmexec.drivers.fakes.dynamixel import FakeDxlBus, wx250s_servos

#: generous adapter latency for a loaded 2-core CI machine: deadlines stay in tens of ms
TEST_LATENCY = 0.02


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
