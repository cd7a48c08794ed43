"""Shared helpers for the RPLIDAR tests: a started fake in a known room, bounded waits."""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator

import pytest
from driverkit import wait_for

from mmexec.drivers.fakes.rplidar import RplidarFake

#: the fake lidar's pose in its 6 m x 4 m room: off-centre, so that every wall is at a
#: different range (east 4.0 m, north 2.5 m, west 2.0 m, south 1.5 m)
POSE = (2.0, 1.5, 0.0)


def _wait_until(pred: Callable[[], object], timeout: float = 3.0) -> bool:
    """Poll ``pred`` every 10 ms until it is truthy or ``timeout`` seconds passed."""
    return wait_for(pred, timeout, poll=0.01)


@pytest.fixture
def wait_until() -> Callable[..., bool]:
    """The bounded poll (test modules here are not a package, so it comes as a fixture)."""
    return _wait_until


@pytest.fixture
def fake() -> Iterator[RplidarFake]:
    """A started fake at :data:`POSE`; on teardown, no thread may be left behind."""
    before = threading.active_count()
    f = RplidarFake(pose=POSE)
    f.start()
    try:
        yield f
    finally:
        f.stop()
    assert _wait_until(lambda: threading.active_count() <= before, 2.0), [t.name for t in threading.enumerate()]
