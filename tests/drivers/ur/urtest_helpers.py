"""Shared helpers for the UR driver tests: bounded real-time waits, a stepped clock loop."""

from __future__ import annotations

import itertools
import random
import threading
import time
from collections.abc import Callable
from pathlib import Path

from mmexec.drivers.interfaces import Goal, ManualClock
from mmexec.drivers.ur.arm import URArm
from mmexec.drivers.ur.rtde_stub import RTDEStub, StubError

# a random start: two test processes (parallel runs on one machine) rarely share a sequence
_hosts = itertools.count(random.SystemRandom().randrange(250))


def loopback_host() -> str:
    """A fresh 127.0.0.X address so stubs (which must use port 30004) rarely collide."""
    return f"127.0.0.{next(_hosts) % 250 + 2}"


def start_stub(attempts: int = 20) -> RTDEStub:
    """An RTDE stub on a free loopback address: another process (a parallel test run) may
    hold 30004 on the address tried, so move on to the next one, at most ``attempts``."""
    error: StubError | None = None
    for _ in range(attempts):
        try:
            return RTDEStub(loopback_host()).start()
        except StubError as e:
            if "Address already in use" not in str(e):
                raise
            error = e
    assert error is not None
    raise error


def host_processes(parent: int) -> list[int]:
    """Pids of the ur_rtde host processes (:mod:`mmexec.drivers.ur.rtde_host`) started by
    process ``parent`` that are still running (zombies show an empty command line)."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            argv = (entry / "cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if b"mmexec.drivers.ur.rtde_host" in argv and str(parent).encode() in argv:
            found.append(int(entry.name))
    return found


def wait_for(pred: Callable[[], bool], timeout: float = 2.0) -> bool:
    """Poll ``pred`` every 2 ms of real time until true or ``timeout`` s pass."""
    ev = threading.Event()
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():
            return True
        ev.wait(0.002)
    return pred()


def sync(arm: URArm, clock: ManualClock) -> None:
    """Wait until the worker has read the controller at the clock's current time."""
    now = clock.now()
    before = arm.state()
    # a new read object means a whole worker cycle (commands, then read) ran after this call
    assert wait_for(lambda: (arm.state() is not before and arm.state().stamp >= now) or not arm.connected), (
        "worker did not cycle"
    )


def step_until(arm: URArm, clock: ManualClock, goal: Goal, dt: float = 0.02, limit: float = 10.0) -> float:
    """Advance the clock by ``dt`` per step (letting the worker cycle each time) until the
    goal is done; returns the clock time it took. Fails after ``limit`` clock seconds."""
    t0 = clock.now()
    while not goal.done():
        assert clock.now() - t0 < limit, f"{goal} not done after {limit} s of clock time"
        clock.advance(dt)
        sync(arm, clock)
        sync(arm, clock)  # one more cycle: the command sent after the read has been applied
    return clock.now() - t0


def run_for(arm: URArm, clock: ManualClock, seconds: float, dt: float = 0.02) -> None:
    """Advance the clock by ``seconds`` in steps of ``dt``, letting the worker cycle after
    each: a driver that keeps up. (One large ``clock.advance`` is, to the controller, a
    driver silent that long: its RTDE watchdog stops the program after ``1 /
    watchdog_frequency`` s.)"""
    end = clock.now() + seconds
    while clock.now() < end - 1e-9:
        clock.advance(min(dt, end - clock.now()))
        sync(arm, clock)
        sync(arm, clock)  # one more cycle: the command sent after the read has been applied
