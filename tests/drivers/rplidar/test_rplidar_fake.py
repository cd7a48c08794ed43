"""The fake lidar against the protocol document, with raw bytes on its port (no driver,
no codec): what a host would see on the wire."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator

import pytest

from mmexec.drivers.fakes.rplidar import BANNER, RplidarFake
from mmexec.drivers.transport import SerialSettings, SerialTransport

Waiter = Callable[..., bool]


@pytest.fixture
def port(fake: RplidarFake) -> Iterator[SerialTransport]:
    t = SerialTransport(SerialSettings(fake.port))
    t.open()
    try:
        yield t
    finally:
        t.close()


def _read(t: SerialTransport, n: int) -> bytes:
    return t.read(n, time.monotonic() + 1.0)


def _drain(t: SerialTransport, quiet: float = 0.1) -> bytes:
    """Everything until the line has been quiet for ``quiet`` s (bounded to 2 s)."""
    out = b""
    end = time.monotonic() + 2.0
    while time.monotonic() < end:
        chunk = t.wait_readable(quiet)
        if not chunk:
            break
        out += chunk
    return out


def test_get_health_and_get_info_as_documented(port: SerialTransport) -> None:
    port.write(bytes([0xA5, 0x52]))                                   # GET_HEALTH
    assert _read(port, 10) == bytes([0xA5, 0x5A, 0x03, 0x00, 0x00, 0x00, 0x06,   # descriptor
                                     0x00, 0x00, 0x00])               # good, error code 0
    port.write(bytes([0xA5, 0x50]))                                   # GET_INFO
    answer = _read(port, 27)
    assert answer[:7] == bytes([0xA5, 0x5A, 0x14, 0x00, 0x00, 0x00, 0x04])
    assert answer[7:11] == bytes([0x28, 29, 1, 7])                    # A2M8, fw minor 29, major 1, hw 7
    port.write(bytes([0xA5, 0x59]))                                   # GET_SAMPLERATE
    assert _read(port, 11) == bytes([0xA5, 0x5A, 0x04, 0x00, 0x00, 0x00, 0x15, 0xF4, 0x01, 0xFA, 0x00])


def test_nodes_only_while_the_motor_runs_and_until_stop(fake: RplidarFake, port: SerialTransport) -> None:
    port.write(bytes([0xA5, 0x20]))                                   # SCAN, motor off (DTR asserted)
    assert _read(port, 7) == bytes([0xA5, 0x5A, 0x05, 0x00, 0x00, 0x40, 0x81])
    assert _drain(port, 0.3) == b""                                   # motor stopped: no data
    port.write(bytes([0xA5, 0xF0, 0x02, 0x94, 0x02, 0xC1]))           # SET_MOTOR_PWM 660
    stream = port.read(1000, time.monotonic() + 3.0)                  # spin-up, then 200 nodes
    for i in range(0, len(stream), 5):
        b0, b1 = stream[i], stream[i + 1]
        assert (b0 & 1) != (b0 >> 1) & 1 and b1 & 1, stream[i:i + 5].hex()   # S != not-S, C = 1
    starts = [i for i in range(0, len(stream), 5) if stream[i] & 1]
    assert starts, "no start flag in 200 nodes (one turn)"
    port.write(bytes([0xA5, 0x25]))                                   # STOP
    _drain(port)                                                      # what was in flight
    assert _drain(port, 0.2) == b""
    snap = fake.snapshot()
    assert not snap.scanning and snap.stops == 1 and snap.pwm == 660


def test_motor_runs_on_a_cleared_dtr_line(fake: RplidarFake, port: SerialTransport, wait_until: Waiter) -> None:
    port.write(bytes([0xA5, 0x21]))                                   # FORCE_SCAN: no wait for the speed
    assert _read(port, 7) == bytes([0xA5, 0x5A, 0x05, 0x00, 0x00, 0x40, 0x81])
    fake.set_dtr(False)                                               # the adapter clears DTR: motor on
    assert len(port.read(50, time.monotonic() + 1.0)) == 50
    fake.set_dtr(True)
    assert wait_until(lambda: not fake.motor_running)


def test_reset_prints_a_banner_and_bad_checksums_are_ignored(fake: RplidarFake, port: SerialTransport) -> None:
    port.write(bytes([0xA5, 0xF0, 0x02, 0x94, 0x02, 0xC0]))           # PWM 660, checksum wrong
    port.write(bytes([0xA5, 0x40]))                                   # RESET
    assert _read(port, len(BANNER)).startswith(b"RP LIDAR")
    snap = fake.snapshot()
    assert snap.bad_requests == 1 and snap.pwm == 0 and snap.resets == 1


def test_health_error_refuses_to_scan(fake: RplidarFake, port: SerialTransport) -> None:
    fake.set_health(2, 0x1234)
    port.write(bytes([0xA5, 0x52]))
    assert _read(port, 10)[7:] == bytes([0x02, 0x34, 0x12])           # error, code 0x1234 LE
    port.write(bytes([0xA5, 0x20]))
    assert _drain(port, 0.2) == b""                                   # protection stop: no answer
