"""Bring-up for the Kobuki base: ``mmexec hw ping kobuki`` and ``mmexec hw fake kobuki``.

``ping`` opens the port (sending a stop frame), waits for a valid feedback frame, asks for
the versions and the unique id, listens for ``--duration`` seconds (1 s: 50 frames) and
prints one line on stdout::

    kobuki on /dev/kobuki: firmware 1.2.0, hardware 1.0.4, battery 16.5 V, unique id 0A0B0C0D-11223344-55667788; link: 50 frames, 0 corrupt, 0 lost, 0 late over 1.0 s (0.0 %)

Link quality counts the feedback frames over the ping: *corrupt* (bad checksum, impossible
length, malformed sub-payloads), *lost* (the base's 20 ms timestamps show a frame that never
arrived) and *late* (a valid frame more than ``link_timeout`` after the previous one).

Exit status, with at most one line on stderr naming the device, the port and the reason:

* 0: ready. A line ``warning: ...`` on stderr when more than 1 % of the frames were
  corrupt, lost or late (cable, baud rate, FTDI latency timer not 1 ms).
* 1: the device answered but is not fit to run, or did not answer usefully: a bumper
  pressed, a cliff, a wheel dropped, motor overcurrent, the link lost during the ping, no
  answer within ``--timeout``, only corrupt frames, an unsupported firmware.
* 2: bad input (``--timeout`` outside [0.02, 60] s, ``--duration`` outside (0, 60] s) or
  the port cannot be opened (no such port, permission denied, busy).

The base is never moved.
"""

from __future__ import annotations

import argparse
import math
import sys
import time

from mmexec.drivers.fakes.kobuki import SAFETY_BITS, KobukiFake
from mmexec.drivers.fakes.pty import serve_until_signal
from mmexec.drivers.kobuki.device import (
    KobukiConfig,
    KobukiDevice,
    KobukiError,
    KobukiInfo,
    KobukiPortError,
    LinkStats,
)

__all__ = ["LINK_WARN_RATIO", "add_fake_arguments", "add_ping_arguments", "ping", "run_fake"]

#: ping warns when more than this fraction of the frames were corrupt, lost or late
LINK_WARN_RATIO = 0.01
_MAX_WAIT = 60.0  # s, upper bound of --timeout and --duration
#: what each fault a ping can see means, for the one-line report
_FAULT_TEXT = {
    "bumper": "bumper pressed", "cliff": "cliff (a wheel over an edge)", "wheel_drop": "wheel dropped",
    "overcurrent": "motor overcurrent", "link_lost": "link lost during the ping",
    "driver_error": "driver error", "firmware_unsupported": "unsupported firmware",
}


def add_ping_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--port", default="/dev/kobuki", help="serial port (default: /dev/kobuki)")
    parser.add_argument(
        "--timeout", type=float, default=0.5, metavar="S",
        help="seconds to wait for the first valid frame (default: 0.5)",
    )
    parser.add_argument(
        "--duration", type=float, default=1.0, metavar="S",
        help="seconds to listen for faults and link quality once connected (default: 1.0)",
    )


def ping(args: argparse.Namespace) -> int:
    """Report versions, battery, unique id and link quality; exit status as the module doc says."""
    for name in ("timeout", "duration"):
        value = getattr(args, name)
        if not (math.isfinite(value) and 0 < value <= _MAX_WAIT):
            print(f"kobuki on {args.port}: --{name} must be a number of seconds in (0, {_MAX_WAIT:g}], got {value}",
                  file=sys.stderr)
            return 2
    try:
        dev = KobukiDevice(KobukiConfig(port=args.port, connect_timeout=args.timeout))
    except ValueError as e:  # the config's own bounds, e.g. --timeout below one frame period
        print(f"{e} (from --timeout {args.timeout:g})", file=sys.stderr)
        return 2
    faults: set[str] = set()
    try:
        dev.connect()
        start = time.monotonic()
        while True:  # bounded by --duration
            faults |= dev.faults
            elapsed = time.monotonic() - start
            if elapsed >= args.duration:
                break
            time.sleep(min(0.02, args.duration - elapsed))
        info, stats = dev.info(), dev.link_stats()
    except KobukiPortError as e:
        print(str(e), file=sys.stderr)
        return 2
    except KobukiError as e:
        print(str(e), file=sys.stderr)
        return 1
    finally:
        dev.close()
    print(f"kobuki on {args.port}: {_describe(info)}; link: {_link_text(stats)} over {elapsed:.1f} s")
    problems = [f"{name} ({_fault_text(name)})" for name in sorted(faults)]
    poor_link = stats.error_ratio > LINK_WARN_RATIO
    link_note = (f"link quality {100 * stats.error_ratio:.1f} % corrupt, lost or late (above "
                 f"{100 * LINK_WARN_RATIO:g} %: check the cable, and that the FTDI latency timer is 1 ms)")
    if problems:
        print(f"kobuki on {args.port}: not fit to run: {', '.join(problems)}"
              + (f"; also {link_note}" if poor_link else ""), file=sys.stderr)
        return 1
    if poor_link:
        print(f"kobuki on {args.port}: warning: {link_note}", file=sys.stderr)
    return 0


def _describe(info: KobukiInfo) -> str:
    battery = f"{info.battery:.1f} V" if info.battery is not None else "unknown"
    return f"firmware {info.firmware}, hardware {info.hardware}, battery {battery}, unique id {info.unique_id_text}"


def _link_text(stats: LinkStats) -> str:
    return (f"{stats.frames} frames, {stats.corrupt} corrupt, {stats.lost} lost, {stats.late} late "
            f"({100 * stats.error_ratio:.1f} %)")


def _fault_text(name: str) -> str:
    for prefix, text in _FAULT_TEXT.items():
        if name.startswith(prefix):
            return text
    return "fault"


def _version(text: str) -> tuple[int, int, int]:
    try:
        parts = tuple(int(x) for x in text.split("."))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected MAJOR.MINOR.PATCH, got {text!r}") from None
    if len(parts) != 3 or not all(0 <= p <= 255 for p in parts):
        raise argparse.ArgumentTypeError(f"expected MAJOR.MINOR.PATCH (0-255 each), got {text!r}")
    return parts  # type: ignore[return-value]


def add_fake_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--firmware", type=_version, default=(1, 2, 0), metavar="X.Y.Z",
                        help="firmware version to report (default 1.2.0; 2.0.0 rehearses a refusal)")
    parser.add_argument("--battery", type=float, default=16.5, metavar="V", help="battery voltage (default 16.5)")
    parser.add_argument("--fault", action="append", default=[], choices=sorted(SAFETY_BITS), metavar="NAME",
                        help="start with this safety condition raised (repeatable): "
                             + ", ".join(sorted(SAFETY_BITS)))


def run_fake(args: argparse.Namespace) -> int:
    """Start a fake Kobuki, print its port, serve until SIGINT / SIGTERM."""
    fake = KobukiFake(firmware=args.firmware)
    fake.set_sensors(battery=args.battery)
    for name in args.fault:
        fake.set_fault(name)
    serve_until_signal(fake, lambda port: print(port, flush=True))
    return 0
