"""The pty fake harness: a fake never blocks on a host that is not reading (bytes are
dropped, as on a UART), so stop() and Ctrl-C of `mmexec hw fake` always return."""

from __future__ import annotations

import threading
import time

from mmexec.drivers.fakes.kobuki import KobukiFake
from mmexec.drivers.fakes.pty import PtyDevice
from mmexec.drivers.kobuki.device import KobukiConfig, KobukiDevice


def test_send_to_a_port_nobody_reads_drops_instead_of_blocking() -> None:
    dev = PtyDevice("unread").start()
    size = 4 * 1024 * 1024  # far more than any pty buffer
    sender = threading.Thread(target=dev.inject, args=(b"\x55" * size,), daemon=True)
    sender.start()
    sender.join(2.0)
    assert not sender.is_alive(), "send blocked on a full pty buffer"
    assert dev.bytes_dropped > 0 and dev.bytes_out + dev.bytes_dropped == size
    t0 = time.monotonic()
    dev.stop()
    assert time.monotonic() - t0 < 1.0


def test_driver_connects_through_a_full_buffer_of_stale_bytes() -> None:
    with KobukiFake() as fake:
        fake.inject(b"\x00\xaa" * 200_000)  # the port filled up before anyone opened it
        assert fake.bytes_dropped > 0
        dev = KobukiDevice(KobukiConfig(port=fake.port))
        try:
            info = dev.connect()  # resynchronises on the frame header after the garbage
            assert info.firmware is not None and info.firmware.major == 1
        finally:
            dev.close()
