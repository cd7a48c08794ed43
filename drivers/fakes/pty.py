"""Harness for fake serial devices on a pseudo-terminal.

A :class:`PtyDevice` owns the master side of a pty pair; the driver under test opens
:attr:`PtyDevice.port` (the slave path) with pyserial exactly as it would open
``/dev/ttyUSB0``. Subclasses implement the device side of a real protocol in
:meth:`on_bytes` (called from the I/O thread with whatever arrived) and
:meth:`on_tick` (called every :attr:`tick_period` seconds, for devices that stream).

Fault switches shared by every fake:

* ``silent``: the device neither reads nor answers (power off, wrong baud);
* ``unplug()``: close the master end; the driver's next read or write fails the way a
  pulled USB cable does (EIO), and the port path disappears;
* ``inject(bytes)``: push raw bytes (garbage, truncated frames) to the driver.

Like a device on a UART, a fake never waits for the host: bytes sent while the driver side
is not reading and the pty buffer is full are dropped (counted in ``bytes_dropped``).

Everything is bounded: the I/O thread polls with a short timeout and exits on
:meth:`stop`, and :meth:`stop` joins it.
"""

from __future__ import annotations

import logging
import os
import select
import signal
import threading
import time
import tty
from collections.abc import Callable
from types import FrameType
from typing import Protocol, Self

__all__ = ["PtyDevice", "Servable", "serve_until_signal"]

log = logging.getLogger(__name__)


class PtyDevice:
    """Base class for a protocol fake on a pty. Use as a context manager."""

    #: seconds between :meth:`on_tick` calls (None: no periodic tick)
    tick_period: float | None = None

    def __init__(self, name: str = "fake") -> None:
        self.name = name
        self.silent = False
        self._master: int | None = None
        self._slave: int | None = None
        self._port = ""
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._lock = threading.RLock()
        self.bytes_in = 0
        self.bytes_out = 0
        #: bytes lost because the driver side was not reading (a full pty buffer)
        self.bytes_dropped = 0

    # -- lifecycle
    @property
    def port(self) -> str:
        """Path of the slave side for the driver to open (valid after :meth:`start`)."""
        if not self._port:
            raise RuntimeError(f"{self.name}: not started (call start() first)")
        return self._port

    def start(self) -> PtyDevice:
        master, slave = os.openpty()
        tty.setraw(master)
        tty.setraw(slave)
        # a device never waits for its host: with nobody reading the port, what it sends is
        # lost (as on a UART), instead of blocking the fake (and stop()) on a full buffer
        os.set_blocking(master, False)
        self._master, self._slave = master, slave
        self._port = os.ttyname(slave)
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name=f"{self.name}-pty", daemon=True)
        self._thread.start()
        log.debug("%s listening on %s", self.name, self._port)
        return self

    def stop(self) -> None:
        self._stop.set()
        t, self._thread = self._thread, None
        if t is not None and t is not threading.current_thread():
            t.join(timeout=2.0)
        self._close_fds()

    def unplug(self) -> None:
        """Simulate a pulled cable: the master end closes and the I/O thread exits."""
        log.info("%s: unplugged", self.name)
        self._stop.set()
        self._close_fds()

    def _close_fds(self) -> None:
        with self._lock:
            for fd in (self._master, self._slave):
                if fd is not None:
                    try:
                        os.close(fd)
                    except OSError:
                        log.debug("%s: fd %s already closed", self.name, fd)
            self._master = self._slave = None

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # -- device side I/O
    def send(self, data: bytes) -> None:
        """Send bytes to the driver (unless silent or unplugged)."""
        with self._lock:
            if self.silent or self._master is None or not data:
                return
            try:
                sent = os.write(self._master, data)
            except BlockingIOError:
                sent = 0
            except OSError as e:
                log.debug("%s: write failed: %s", self.name, e)
                return
            self.bytes_out += sent
            if sent < len(data):
                self.bytes_dropped += len(data) - sent
                log.debug("%s: driver side not reading: %d bytes dropped", self.name,
                          len(data) - sent)

    def inject(self, data: bytes) -> None:
        """Send raw bytes regardless of protocol (garbage, truncated frames)."""
        self.send(data)

    # -- to override
    def on_bytes(self, data: bytes) -> None:
        """Bytes received from the driver."""

    def on_tick(self, now: float) -> None:
        """Periodic hook (every :attr:`tick_period` s of time.monotonic())."""

    # -- thread
    def _run(self) -> None:
        next_tick = time.monotonic()
        while not self._stop.is_set():
            master = self._master
            if master is None:
                return
            timeout = 0.02
            if self.tick_period is not None:
                timeout = max(0.0, min(timeout, next_tick - time.monotonic()))
            try:
                ready, _, _ = select.select([master], [], [], timeout)
            except (OSError, ValueError):
                return
            if ready:
                try:
                    data = os.read(master, 4096)
                except OSError:
                    data = b""
                if data and not self.silent:
                    self.bytes_in += len(data)
                    try:
                        self.on_bytes(data)
                    except Exception:
                        log.exception("%s: on_bytes failed", self.name)
            if self.tick_period is not None:
                now = time.monotonic()
                if now >= next_tick:
                    next_tick = max(next_tick + self.tick_period, now)
                    if not self.silent:
                        try:
                            self.on_tick(now)
                        except Exception:
                            log.exception("%s: on_tick failed", self.name)


class Servable(Protocol):
    """What :func:`serve_until_signal` serves: a :class:`PtyDevice`, or any fake with
    ``start``, ``stop`` and a ``port`` once started (e.g. a TCP server's port number)."""

    @property
    def port(self) -> str | int: ...

    def start(self) -> object: ...

    def stop(self) -> None: ...


def serve_until_signal(device: Servable, announce: Callable[[str], None]) -> None:
    """Start ``device``, hand its port (as text) to ``announce`` and serve until SIGINT or
    SIGTERM (``mmexec hw fake``); then stop it and restore the previous handlers. Main thread
    only (Python sets signal handlers there)."""
    done = threading.Event()

    def _on_signal(signum: int, frame: FrameType | None) -> None:
        done.set()

    old = {s: signal.signal(s, _on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        device.start()
        announce(str(device.port))
        while not done.wait(0.5):
            pass
    finally:
        device.stop()
        for s, handler in old.items():
            signal.signal(s, handler)
