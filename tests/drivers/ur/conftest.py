"""Fixtures shared by the UR driver tests."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from mmexec.drivers.ur.rtde_stub import RTDEStub


@pytest.fixture(scope="module")
def _module_stub() -> Iterator[RTDEStub]:
    with RTDEStub("127.0.0.1", 0) as s:
        yield s


@pytest.fixture
def local_stub(_module_stub: RTDEStub) -> Iterator[RTDEStub]:
    """The module's RTDE stub process on 127.0.0.1 and an ephemeral port (so only our own
    RTDE client can use it, not ur_rtde), with every switch back to normal after the test."""
    yield _module_stub
    _module_stub.clear_faults()
    _module_stub.set_link()
    _module_stub.silence(None)
    _module_stub.garbage(False)
    _module_stub.set_not_found([])
