"""Bring-up commands for a DYNAMIXEL bus: ``mmexec hw ping dynamixel`` and ``mmexec hw fake dynamixel``.

``ping`` pings each requested id (3 attempts each) and prints one line per servo that
answered (id, model name and number, firmware); it exits 0 when every requested id
answered, otherwise it prints one line to stderr naming the port and what went wrong
(no such port, permission denied, port busy, no answer within the deadline, corrupt
frames, servo fault) and exits 1 -- never a traceback.

``run_fake`` starts a :class:`~mmexec.drivers.fakes.dynamixel.FakeDxlBus` with a WX250s
(``--locobot`` adds pan/tilt; ``--missing IDS`` and ``--hardware-error ID:FAULT`` rehearse
the faults), prints its port on one line and serves until SIGINT/SIGTERM.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from types import FrameType
from typing import TYPE_CHECKING

from mmexec.drivers.dynamixel.bus import (
    BusConfig,
    CorruptReply,
    DxlBus,
    DynamixelError,
    LinkLost,
    NoReply,
    PingInfo,
    PortUnavailable,
    ServoError,
)
from mmexec.drivers.dynamixel.control_table import MODELS, decode_hardware_error

__all__ = ["add_fake_arguments", "add_ping_arguments", "make_fake", "parse_ids", "ping", "run_fake"]

if TYPE_CHECKING:
    from mmexec.drivers.fakes.dynamixel import FakeDxlBus

DEVICE = "dynamixel"


def parse_ids(text: str) -> list[int]:
    """``"1-9"``, ``"1,2,4-6"`` -> sorted unique ids; ValueError with the bad part named."""
    ids: set[int] = set()
    for part in text.split(","):
        part = part.strip()
        if not part:
            continue
        try:
            if "-" in part:
                a, b = (int(x) for x in part.split("-", 1))
                if a > b:
                    raise ValueError
                ids.update(range(a, b + 1))
            else:
                ids.add(int(part))
        except ValueError:
            raise ValueError(f"bad id range {part!r} (expected e.g. 1-9 or 1,2,4)") from None
    bad = [i for i in ids if not 0 <= i <= 252]
    if bad or not ids:
        raise ValueError(f"ids must be 0-252, got {text!r}")
    return sorted(ids)


def add_ping_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--port", required=True, help="serial port of the U2D2, e.g. /dev/ttyDXL")
    parser.add_argument("--baud", type=int, default=1_000_000, help="bit/s (default 1000000)")
    parser.add_argument("--ids", default="1-9", help="ids to ping, e.g. 1-9 or 1,2,4 (default 1-9)")
    parser.add_argument(
        "--latency-ms",
        type=float,
        default=16.0,
        help="adapter latency for reply deadlines [ms] (default 16, the FTDI factory timer)",
    )
    parser.add_argument("--attempts", type=int, default=3, help="ping attempts per id (default 3)")


def ping(args: argparse.Namespace) -> int:
    port = args.port
    try:
        ids = parse_ids(args.ids)
        cfg = BusConfig(port, int(args.baud), float(args.latency_ms) / 1000.0)
    except ValueError as e:
        print(f"{DEVICE} {port}: {e}", file=sys.stderr)
        return 2
    bus = DxlBus(cfg)
    found: dict[int, PingInfo] = {}
    missing: list[int] = []
    corrupt: list[int] = []
    faulted: list[str] = []
    try:
        bus.open()
        for dxl_id in ids:
            for _ in range(max(1, int(args.attempts))):
                try:
                    found[dxl_id] = bus.ping(dxl_id)
                    break
                except CorruptReply:
                    if dxl_id not in corrupt:
                        corrupt.append(dxl_id)
                except NoReply:
                    continue
            if dxl_id not in found:
                missing.append(dxl_id)
                continue
            info = found[dxl_id]
            model = MODELS[info.model].name if info.model in MODELS else "unknown model"
            line = f"id {dxl_id}: {model} (model {info.model}), firmware {info.firmware}"
            try:
                faults = (
                    decode_hardware_error(bus.read(dxl_id, 70, 1)[0])
                    if info.model in MODELS
                    else ()
                )
            except (NoReply, CorruptReply, ServoError):
                faults = ()
            if faults:
                line += f", HARDWARE ERROR: {', '.join(faults)}"
                faulted.append(f"id {dxl_id} {'+'.join(faults)}")
            print(line)
    except PortUnavailable as e:
        print(f"{DEVICE} {port}: {e.detail}", file=sys.stderr)
        return 1
    except LinkLost as e:
        print(f"{DEVICE} {port}: {e.detail}", file=sys.stderr)
        return 1
    except DynamixelError as e:
        print(f"{DEVICE} {port}: {e}", file=sys.stderr)
        return 1
    finally:
        bus.close()
    if not found:
        why = (
            "corrupt frames (wrong baud rate or noise?)"
            if corrupt
            else "no answer within the deadline"
        )
        print(
            f"{DEVICE} {port}: {why} from any of ids {args.ids} at {args.baud} baud",
            file=sys.stderr,
        )
        return 1
    if missing:
        extra = f" (corrupt frames from {', '.join(map(str, corrupt))})" if corrupt else ""
        print(
            f"{DEVICE} {port}: no answer within the deadline from ids {', '.join(map(str, missing))}{extra}",
            file=sys.stderr,
        )
        return 1
    if faulted:
        print(
            f"{DEVICE} {port}: servo fault: {', '.join(faulted)} (torque is off: find the cause, "
            "then reboot the servo, e.g. power-cycle or WX250s.reboot())",
            file=sys.stderr,
        )
        return 1
    return 0


def add_fake_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--locobot", action="store_true", help="LoCoBot variant: add pan (10) and tilt (11)"
    )
    parser.add_argument(
        "--configured",
        action="store_true",
        help="start with the Interbotix EEPROM settings already applied",
    )
    parser.add_argument(
        "--missing", default="", metavar="IDS",
        help="ids that never answer, e.g. 5 or 4-5 (an unplugged or dead servo)",
    )
    parser.add_argument(
        "--hardware-error", action="append", default=[], metavar="ID:FAULT[+FAULT]",
        help="start a servo in Hardware Error, e.g. 4:overload (overload, overheating, "
        "input_voltage, motor_encoder, electrical_shock); repeatable",
    )


def make_fake(args: argparse.Namespace) -> FakeDxlBus:
    """The fake ``run_fake`` serves, with the fault switches of the arguments applied
    (not started). ValueError naming the bad argument."""
    from mmexec.drivers.fakes.dynamixel import FakeDxlBus, wx250s_servos

    fake = FakeDxlBus(wx250s_servos(locobot=bool(args.locobot), configured=bool(args.configured)))
    known = {s.id for s in fake.servos}
    for dxl_id in parse_ids(args.missing) if args.missing else []:
        if dxl_id not in known:
            raise ValueError(f"--missing: no servo with id {dxl_id} (ids {min(known)}-{max(known)})")
        fake.servo(dxl_id).present = False
    for spec in args.hardware_error:
        sid, _, names = spec.partition(":")
        if not sid.strip().isdigit() or int(sid) not in known or not names:
            raise ValueError(f"--hardware-error: expected ID:FAULT with an id of the arm, got {spec!r}")
        try:
            fake.inject_hardware_error(int(sid), *names.split("+"))
        except KeyError as e:
            raise ValueError(f"--hardware-error: {e.args[0]}") from None
    return fake


def run_fake(args: argparse.Namespace) -> int:
    try:
        fake = make_fake(args)
    except ValueError as e:
        print(f"{DEVICE} fake: {e}", file=sys.stderr)
        return 2
    done = threading.Event()

    def _stop(signum: int, frame: FrameType | None) -> None:
        done.set()

    old = {s: signal.signal(s, _stop) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        fake.start()
        print(fake.port, flush=True)
        while not done.wait(0.5):
            pass
    finally:
        fake.stop()
        for s, h in old.items():
            signal.signal(s, h)
    return 0
