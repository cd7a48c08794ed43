"""Helpers shared by the driver tests (importable from every folder below tests/drivers:
its conftest.py puts this folder on the path)."""

from __future__ import annotations

import os
import selectors
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager


def wait_for(pred: Callable[[], object], timeout: float = 2.0, poll: float = 0.005) -> bool:
    """Poll ``pred`` every ``poll`` s until it is truthy or ``timeout`` s of real time
    pass (bounded, never forever); whether it became true."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():
            return True
        time.sleep(poll)
    return bool(pred())


@contextmanager
def fake_process(*args: str, timeout: float = 15.0, stop: signal.Signals = signal.SIGINT,
                 exit_timeout: float = 30.0) -> Iterator[str]:
    """Run ``mmexec hw fake ARGS`` (a real process, as a user would); yield the port it prints
    (bounded wait); at exit send ``stop`` and expect exit status 0 within ``exit_timeout`` s
    and no traceback; a fake still running after a failure is killed."""
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen([sys.executable, "-m", "mmexec.drivers.hwcli", "fake", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env)
    try:
        assert proc.stdout is not None
        sel = selectors.DefaultSelector()
        sel.register(proc.stdout, selectors.EVENT_READ)
        deadline = time.monotonic() + timeout
        while not sel.select(0.1):
            assert proc.poll() is None, f"fake exited: {proc.stderr.read() if proc.stderr else ''}"
            assert time.monotonic() < deadline, f"fake {args} printed no port within {timeout} s"
        sel.close()
        yield proc.stdout.readline().strip()
        proc.send_signal(stop)
        # bounded generously: the UR fake asks its stub process to quit (up to 5 s, then kills
        # it, another 5 s), and a loaded 2-core machine is slow to schedule all of it
        assert proc.wait(timeout=exit_timeout) == 0
        assert "Traceback" not in (proc.stderr.read() if proc.stderr else "")
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=5)
