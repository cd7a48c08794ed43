"""``mmexec hw``: hardware bring-up, the way engineers check wiring before a mission.

::

    mmexec hw ping kobuki --port PORT
    mmexec hw ping dynamixel --port PORT [--baud B] [--ids 1-9]
    mmexec hw ping robotiq --port PORT [--activate]
    mmexec hw ping ur --host HOST
    mmexec hw ping rplidar --port PORT [--duration 2]
    mmexec hw fake DEVICE [options]      # start a protocol fake, print its port

Each device package provides ``mmexec.drivers.<device>.bringup`` with
``add_ping_arguments(parser)``, ``ping(args) -> int``, ``add_fake_arguments(parser)``
and ``run_fake(args) -> int``; this module only dispatches to them, importing the
one it needs lazily so a missing driver is a one-line error, not a traceback.
Exit status: 0 ready; 1 the device answered but is not fit to run, or gave no useful
answer; 2 bad input or the port cannot be opened; each failure one line on stderr.
Driver log records are held back below CRITICAL while a command runs (they would repeat
that line); set ``MMEXEC_DEBUG=1`` to see them. Also runnable as
``python -m mmexec.drivers.hwcli``.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import sys
from types import ModuleType

from mmexec.config.brokenpipe import detach_stdout

__all__ = ["DEVICES", "main"]

log = logging.getLogger(__name__)

#: device name -> one-line description
DEVICES: dict[str, str] = {
    "kobuki": "Kobuki mobile base (LoCoBot) on a serial port",
    "dynamixel": "Dynamixel 2.0 bus (Interbotix WX250s arm)",
    "robotiq": "Robotiq 2F-85 gripper over Modbus RTU",
    "ur": "Universal Robots e-series arm over RTDE",
    "rplidar": "Slamtec RPLIDAR A2 360 degree lidar (LoCoBot) on a serial port",
}

_USAGE = (
    "usage: mmexec hw ping DEVICE [options] | mmexec hw fake DEVICE [options]\n"
    "devices: " + ", ".join(DEVICES) + "\n"
    "'mmexec hw ping DEVICE --help' lists a device's options"
)


def _load(device: str) -> ModuleType:
    name = f"mmexec.drivers.{device}.bringup"
    try:
        return importlib.import_module(name)
    except ModuleNotFoundError as e:
        if e.name is not None and name.startswith(e.name):
            raise LookupError(f"the {device} driver has no bring-up module ({name} is not installed)") from e
        raise LookupError(f"the {device} driver cannot be loaded: {e}") from e
    except ImportError as e:
        raise LookupError(f"the {device} driver cannot be loaded: {e}") from e


def main(argv: list[str] | None = None) -> int:
    """Run ``mmexec hw`` with ``argv`` (the words after ``hw``); returns the exit status."""
    args = list(sys.argv[1:] if argv is None else argv)
    if not args or args[0] in ("-h", "--help"):
        print(_USAGE, file=sys.stdout if args else sys.stderr)
        return 0 if args else 2
    action = args[0]
    if action not in ("ping", "fake"):
        print(f"mmexec hw: unknown action {action!r} (expected 'ping' or 'fake')\n{_USAGE}", file=sys.stderr)
        return 2
    if len(args) < 2 or args[1].startswith("-"):
        if len(args) >= 2 and args[1] in ("-h", "--help"):
            print(_USAGE)
            return 0
        print(f"mmexec hw {action}: name a device: {', '.join(DEVICES)}", file=sys.stderr)
        return 2
    device = args[1]
    if device not in DEVICES:
        import difflib

        hint = difflib.get_close_matches(device, DEVICES, n=1)
        print(
            f"mmexec hw {action}: unknown device {device!r}"
            + (f"; did you mean {hint[0]!r}?" if hint else f" (known: {', '.join(DEVICES)})"),
            file=sys.stderr,
        )
        return 2
    try:
        mod = _load(device)
    except LookupError as e:
        print(f"mmexec hw {action} {device}: {e}", file=sys.stderr)
        return 2
    parser = argparse.ArgumentParser(prog=f"mmexec hw {action} {device}", description=DEVICES[device])
    try:
        adder = getattr(mod, "add_ping_arguments" if action == "ping" else "add_fake_arguments")
        runner = getattr(mod, "ping" if action == "ping" else "run_fake")
    except AttributeError as e:
        print(f"mmexec hw {action} {device}: bring-up module is incomplete: {e}", file=sys.stderr)
        return 2
    adder(parser)
    try:
        ns = parser.parse_args(args[2:])
    except SystemExit as e:  # argparse printed its one-line error (or --help)
        return int(e.code or 0)
    # The contract is one line per outcome: driver log records (a refusal logged by an I/O
    # thread and then raised to the caller) would repeat it. MMEXEC_DEBUG shows them.
    drivers_log = logging.getLogger("mmexec.drivers")
    level = drivers_log.level
    if not os.environ.get("MMEXEC_DEBUG"):
        drivers_log.setLevel(logging.CRITICAL)
    try:
        return int(runner(ns))
    except KeyboardInterrupt:
        print(f"mmexec hw {action} {device}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # stdout's reader went away (`| head`): the device is closed, exit quietly
        return detach_stdout()
    except Exception as e:
        log.debug("mmexec hw %s %s failed", action, device, exc_info=True)
        print(f"mmexec hw {action} {device}: {type(e).__name__}: {e}", file=sys.stderr)
        return 1
    finally:
        drivers_log.setLevel(level)


if __name__ == "__main__":
    raise SystemExit(main())
