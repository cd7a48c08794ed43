"""Bring-up for the Kobuki base: ``mmexec hw ping kobuki`` and ``mmexec hw fake kobuki``.

``ping`` opens the port, waits for a valid feedback frame, asks for the versions and
the unique id, and prints what it found::

    kobuki on /dev/kobuki: firmware 1.2.0, hardware 1.0.4, battery 16.5 V, unique id 0A0B0C0D-11223344-55667788

It exits 0 when the base answers; otherwise it prints one line on stderr naming the
device, the port and the reason (no such port, permission denied, no answer within the
deadline, corrupt frames, unsupported firmware) and exits 1. The base is not moved.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading

from mmexec.drivers.fakes.kobuki import KobukiFake
from mmexec.drivers.kobuki.device import KobukiConfig, KobukiDevice, KobukiError

__all__ = ["add_fake_arguments", "add_ping_arguments", "ping", "run_fake"]


def add_ping_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--port", default="/dev/kobuki", help="serial port (default: /dev/kobuki)")
    parser.add_argument(
        "--timeout", type=float, default=0.5, metavar="S",
        help="seconds to wait for the first valid frame (default: 0.5)",
    )


def ping(args: argparse.Namespace) -> int:
    """Print firmware / hardware version, battery voltage and unique id; 0 if it answers."""
    if not args.timeout > 0:
        print(f"kobuki on {args.port}: --timeout must be > 0, got {args.timeout}", file=sys.stderr)
        return 2
    dev = KobukiDevice(KobukiConfig(port=args.port, connect_timeout=args.timeout))
    try:
        info = dev.connect()
    except KobukiError as e:
        print(str(e), file=sys.stderr)
        return 1
    finally:
        dev.close()
    battery = f"{info.battery:.1f} V" if info.battery is not None else "unknown"
    print(
        f"kobuki on {args.port}: firmware {info.firmware}, hardware {info.hardware}, "
        f"battery {battery}, unique id {info.unique_id_text}"
    )
    return 0


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


def run_fake(args: argparse.Namespace) -> int:
    """Start a fake Kobuki, print its port, serve until SIGINT / SIGTERM."""
    fake = KobukiFake(firmware=args.firmware)
    fake.set_sensors(battery=args.battery)
    done = threading.Event()

    def _on_signal(signum: int, frame: object) -> None:
        done.set()

    old = {s: signal.signal(s, _on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    fake.start()
    try:
        print(fake.port, flush=True)
        while not done.wait(0.5):
            pass
    finally:
        fake.stop()
        for s, h in old.items():
            signal.signal(s, h)
    return 0
