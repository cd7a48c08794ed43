"""Bring-up commands for the UR arm: ``mmexec hw ping ur`` and ``mmexec hw fake ur``.

``ping`` reads the controller through RTDE twice, each step within ``--timeout``:

1. with our own client (:mod:`mmexec.drivers.ur.rtde_client`: pure Python, a deadline on
   every answer): ``V``, ``v``, ``O``, ``S``, then every data package for ``--duration``
   seconds at ``--frequency`` (state and link quality), ``P``;
2. on port 30004, with ur_rtde's ``RTDEReceiveInterface`` in a host process
   (:mod:`mmexec.drivers.ur.rtde_host`), which must connect and read, as the arm driver's
   will (ur_rtde's constructors hold the GIL with no deadline: in this process a silent
   controller would freeze the command and Ctrl-C).

It prints::

    ur 192.168.1.10:30004: controller 5.15.0.12345
      robot mode 7 (running), safety mode 1 (normal), runtime state 1 (stopped)
      joints [rad]: +0.0000 -1.5708 +1.5708 -1.5708 -1.5708 +0.0000
      link: 500 frames, 0 lost, 0 late over 1.0 s (0.0 %)

Link quality: *lost* frames are those the controller's timestamps show were never
received (it stamps every sample; a gap of k periods is k - 1 lost), *late* ones arrived
more than ``--late`` seconds behind the best-delivered frame (arrival time minus
controller timestamp).

Exit status, with at most one line on stderr naming host and port:

* 0: ready. A line ``warning: ...`` when more than 1 % of the frames were lost or late.
* 1: the controller answered but the arm is not fit to run: a frame during the ping showed
  it powered off or with its brakes engaged (robot mode other than 7, running), or a
  protective, emergency or safeguard stop or another safety fault (safety mode other than
  1 normal or 2 reduced); or it did not answer usefully: no answer within ``--timeout``,
  bytes that are not RTDE, ``NOT_FOUND`` variables, a refused request, the connection
  closed during the ping, ur_rtde failing to connect or read.
* 2: bad input (``--timeout``, ``--duration``, ``--late`` outside (0, 60] s,
  ``--frequency`` outside (0, 500] Hz, ``--port`` outside 1..65535) or no connection could
  be opened (refused, no route to host, unknown host, connect timeout).

Not judged: the runtime state (ur_rtde's control interface uploads and starts its own
control script, so a stopped program is the normal state before a run; once the driver
runs, anything but "playing" is a fault it reports) and remote control (PolyScope 5.6
and later refuse the control script in local mode; that is read from the dashboard
server, whose protocol docs/protocols.md does not describe, so the run's bring-up
reports it: ur_rtde's "Please enable remote control on the robot!" in one line).
"""

from __future__ import annotations

import argparse
import math
import signal
import sys
import threading
import time
from dataclasses import dataclass
from typing import Any

from mmexec.drivers.ur import states
from mmexec.drivers.ur.rtde_client import (
    LinkStats,
    RTDEClientError,
    RTDESession,
    RTDEUnreachable,
    link_quality,
)
from mmexec.drivers.ur.rtde_codec import ControllerVersion

__all__ = [
    "LINK_WARN_RATIO",
    "PING_VARIABLES",
    "PingResult",
    "add_fake_arguments",
    "add_ping_arguments",
    "ping",
    "read_controller",
    "run_fake",
]

RTDE_PORT = 30004
PING_VARIABLES: tuple[str, ...] = (
    "timestamp", "actual_q", "robot_mode", "safety_mode", "safety_status_bits", "runtime_state",
)
#: ping warns when more than this fraction of the frames were lost or late
LINK_WARN_RATIO = 0.01
_MAX_WAIT = 60.0  # s, upper bound of --timeout, --duration and --late
_MAX_FREQUENCY = 500.0  # Hz, e-series RTDE rate
_CB3_FREQUENCY = 125.0  # Hz, CB3 (controller major version below 5) RTDE rate


@dataclass(frozen=True)
class PingResult:
    """What a ping read: the controller version, every frame's values by name (in
    arrival order), the link quality and each distinct fault seen (in order)."""

    version: ControllerVersion
    frames: list[dict[str, Any]]
    link: LinkStats
    faults: list[str]


def read_controller(host: str, port: int, *, timeout: float, duration: float, frequency: float,
                    late: float) -> PingResult:
    """Stream :data:`PING_VARIABLES` for ``duration`` s with our RTDE client and judge every
    frame (:func:`~mmexec.drivers.ur.states.not_fit_reason`). Raises
    :class:`~mmexec.drivers.ur.rtde_client.RTDEClientError` (one line)."""
    with RTDESession(host, port, timeout) as session:
        version = session.open()
        rate = min(frequency, _CB3_FREQUENCY) if version.major < 5 else frequency
        session.setup_outputs(rate, PING_VARIABLES)
        session.start()
        arrivals: list[float] = []
        frames: list[dict[str, Any]] = []
        end = time.monotonic() + duration
        while not frames or time.monotonic() < end:
            arrival, values = session.read()
            arrivals.append(arrival)
            frames.append(values)
        session.pause()
    faults: list[str] = []
    for v in frames:
        fault = states.not_fit_reason(int(v["robot_mode"]), int(v["safety_mode"]), int(v["safety_status_bits"]))
        if fault and fault not in faults:
            faults.append(fault)
    stats = link_quality([float(v["timestamp"]) for v in frames], arrivals, 1.0 / rate, late)
    return PingResult(version, frames, stats, faults)


def _vendor_read(host: str, timeout: float) -> str:
    """Connect ur_rtde's ``RTDEReceiveInterface`` in a host process and read one sample
    within ``timeout`` s per step; returns "" or the one-line reason it failed."""
    from mmexec.drivers.ur.rtde_host import RTDEHost, RTDEHostError

    rtde_host = RTDEHost(host)
    try:
        rtde_host.start(timeout)
        r = rtde_host.construct("rtde_receive", "RTDEReceiveInterface", (host, 10.0, list(PING_VARIABLES)),
                                timeout=timeout, call_timeout=timeout, method_timeouts={"disconnect": timeout + 1.0})
        deadline = time.monotonic() + timeout
        pause = threading.Event()
        while r.getTimestamp() == 0.0:
            if time.monotonic() > deadline:
                return f"ur_rtde connected but read no data within {timeout:.1f} s"
            pause.wait(0.01)
        r.getActualQ()
        r.disconnect()
    except RTDEHostError as e:  # already names ur_rtde and the call
        return str(e)
    except RuntimeError as e:  # ur_rtde's own error
        return "ur_rtde: " + " ".join(str(e).split())
    finally:
        rtde_host.close()
    return ""


def add_ping_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``mmexec hw ping ur``."""
    parser.add_argument("--host", required=True, help="controller IP address or name")
    parser.add_argument("--port", type=int, default=RTDE_PORT, help="RTDE port (default 30004)")
    parser.add_argument("--timeout", type=float, default=2.0, metavar="S",
                        help="deadline for each answer in seconds (default 2)")
    parser.add_argument("--duration", type=float, default=1.0, metavar="S",
                        help="seconds to stream state for faults and link quality (default 1)")
    parser.add_argument("--frequency", type=float, default=_MAX_FREQUENCY, metavar="HZ",
                        help="RTDE rate for the link check (default 500, the driver's; CB3: 125 at most)")
    parser.add_argument("--late", type=float, default=0.02, metavar="S",
                        help="a frame this much behind the best-delivered one counts as late (default 0.02)")


def _bad_input(args: argparse.Namespace) -> str:
    for name in ("timeout", "duration", "late"):
        value = getattr(args, name)
        if not (math.isfinite(value) and 0 < value <= _MAX_WAIT):
            return f"--{name} must be a number of seconds in (0, {_MAX_WAIT:g}], got {value}"
    if not (math.isfinite(args.frequency) and 0 < args.frequency <= _MAX_FREQUENCY):
        return f"--frequency must be in (0, {_MAX_FREQUENCY:g}] Hz, got {args.frequency}"
    if not 1 <= args.port <= 65535:
        return f"--port must be in 1..65535, got {args.port}"
    return ""


def ping(args: argparse.Namespace) -> int:
    """``mmexec hw ping ur``: exit status and output as the module doc says."""
    where = f"ur {args.host}:{args.port}"
    problem = _bad_input(args)
    if problem:
        print(f"{where}: {problem}", file=sys.stderr)
        return 2
    try:
        res = read_controller(args.host, args.port, timeout=args.timeout, duration=args.duration,
                              frequency=args.frequency, late=args.late)
    except RTDEUnreachable as e:
        print(f"ur {e}", file=sys.stderr)
        return 2
    except RTDEClientError as e:
        print(f"ur {e}", file=sys.stderr)
        return 1
    if args.port == RTDE_PORT:
        failure = _vendor_read(args.host, args.timeout)
        if failure:
            print(f"{where}: {failure}", file=sys.stderr)
            return 1
    last = res.frames[-1]
    rm, sm, rt = int(last["robot_mode"]), int(last["safety_mode"]), int(last["runtime_state"])
    print(f"{where}: controller {res.version}")
    print(f"  robot mode {rm} ({states.ROBOT_MODES.get(rm, '?')}), "
          f"safety mode {sm} ({states.SAFETY_MODES.get(sm, '?')}), "
          f"runtime state {rt} ({states.RUNTIME_STATES.get(rt, '?')})")
    print("  joints [rad]: " + " ".join(f"{x:+.4f}" for x in last["actual_q"]))
    print(f"  link: {res.link}")
    poor_link = res.link.ratio > LINK_WARN_RATIO
    link_note = (f"link quality {100 * res.link.ratio:.1f} % lost or late (above {100 * LINK_WARN_RATIO:g} %: "
                 "check the cable and switch, and that nothing else loads the network or this computer)")
    if res.faults:
        print(f"{where}: not fit to run: {'; '.join(res.faults)}" + (f"; also {link_note}" if poor_link else ""),
              file=sys.stderr)
        return 1
    if poor_link:
        print(f"{where}: warning: {link_note}", file=sys.stderr)
    return 0


def add_fake_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``mmexec hw fake ur``."""
    parser.add_argument("--host", default="127.0.0.1", help="loopback address to listen on (default 127.0.0.1)")
    parser.add_argument("--port", type=int, default=30004,
                        help="port (default 30004, the only one ur_rtde can use; 0 = ephemeral)")


def run_fake(args: argparse.Namespace) -> int:
    """``mmexec hw fake ur``: start the RTDE stub process, print HOST:PORT, run until Ctrl-C."""
    from mmexec.drivers.ur.rtde_stub import RTDEStub, StubError

    stub = RTDEStub(args.host, args.port)
    stop = threading.Event()
    # handlers first: a Ctrl-C right after the port is printed still stops the stub process
    previous = {s: signal.signal(s, lambda *_: stop.set()) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        try:
            stub.start()
        except StubError as e:
            print(f"ur fake: {e}", file=sys.stderr)
            return 1
        print(f"{stub.host}:{stub.port}", flush=True)
        while not stop.is_set() and stub.running():
            stop.wait(0.5)
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        stub.stop()
    return 0
