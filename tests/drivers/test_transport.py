"""SerialTransport against a pty echo device: reads with deadlines, unplug, missing ports."""

from __future__ import annotations

import time

import pytest

from mmexec.drivers.fakes.pty import PtyDevice
from mmexec.drivers.transport import (
    LinkClosed,
    LinkTimeout,
    PortNotFound,
    SerialSettings,
    SerialTransport,
)


class Echo(PtyDevice):
    def on_bytes(self, data: bytes) -> None:
        self.send(data.upper())


def test_round_trip_and_deadline() -> None:
    with Echo() as dev, SerialTransport(SerialSettings(dev.port)) as link:
        link.write(b"ping")
        assert link.read(4, time.monotonic() + 1.0) == b"PING"
        t0 = time.monotonic()
        with pytest.raises(LinkTimeout):
            link.read(1, time.monotonic() + 0.1)
        assert time.monotonic() - t0 < 0.5


def test_silent_device_times_out() -> None:
    with Echo() as dev, SerialTransport(SerialSettings(dev.port)) as link:
        dev.silent = True
        link.write(b"x")
        with pytest.raises(LinkTimeout, match="no answer"):
            link.read(1, time.monotonic() + 0.1)


def test_unplug_is_link_closed() -> None:
    dev = Echo().start()
    link = SerialTransport(SerialSettings(dev.port))
    link.open()
    try:
        dev.unplug()
        with pytest.raises((LinkClosed, LinkTimeout)):
            for _ in range(20):
                link.write(b"x")
                link.read(1, time.monotonic() + 0.05)
    finally:
        link.close()
        dev.stop()


def test_missing_port() -> None:
    with pytest.raises(PortNotFound, match="/dev/nonexistent-mmexec: no such port"):
        SerialTransport(SerialSettings("/dev/nonexistent-mmexec")).open()
