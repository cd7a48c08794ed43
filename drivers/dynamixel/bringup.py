"""Bring-up commands for a DYNAMIXEL bus: ``mmexec hw ping dynamixel`` and ``mmexec hw fake dynamixel``.

``ping`` pings each requested id (up to ``--attempts`` times until it answers), then
``--count`` more times, and reads its Hardware Error Status (address 70). It prints one line
per servo that answered (id, model name and number, firmware, any hardware error or alert)
and a last line with the link quality of the pings to the servos that answered::

    id 1: XM430-W350 (model 1020), firmware 46
    ...
    dynamixel /dev/ttyDXL: link: 99 exchanges with 9 servos, 0 lost, 0 corrupt (0.0 %)

*lost*: no status packet within the reply deadline; *corrupt*: a status packet with a bad
CRC, cut short, or a servo answering CRC error (the instruction was garbled on the way).
Exchanges with ids that never answered are not counted: those servos are missing.

Exit status, with at most one line on stderr naming the device, the port and the reason:

* 0: ready; a line ``warning: ...`` when more than 1 % of the exchanges were lost or corrupt.
* 1: the bus answered but is not fit to run: a requested id missing, a servo in hardware
  error (Hardware Error Status non-zero, or the alert bit in its status packets: torque is
  off until a reboot), its Hardware Error Status unreadable, the port lost during the ping;
  or no useful answer at all (no answer within the deadline, only corrupt frames).
* 2: bad input (``--ids``, ``--baud``, ``--count`` ...) or the port cannot be opened (no
  such port, permission denied, busy).

``run_fake`` starts a :class:`~mmexec.drivers.fakes.dynamixel.FakeDxlBus` with a WX250s
(``--locobot`` adds pan/tilt; ``--missing IDS``, ``--hardware-error ID:FAULT`` and
``--drop-every`` / ``--corrupt-every`` rehearse the faults), prints its port on one line and
serves until SIGINT/SIGTERM.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, TypeVar

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
from mmexec.drivers.dynamixel.codec import StatusResult
from mmexec.drivers.dynamixel.control_table import (
    MODELS,
    baud_rate_problem,
    decode_hardware_error,
)

__all__ = [
    "LINK_WARN_RATIO",
    "add_fake_arguments",
    "add_ping_arguments",
    "make_fake",
    "parse_ids",
    "ping",
    "run_fake",
]

if TYPE_CHECKING:
    from mmexec.drivers.fakes.dynamixel import FakeDxlBus

_T = TypeVar("_T")

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


#: ping warns when more than this fraction of the exchanges were lost or corrupt
LINK_WARN_RATIO = 0.01
_MAX_COUNT = 1000


def add_ping_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--port", required=True, help="serial port of the U2D2, e.g. /dev/ttyDXL")
    parser.add_argument(
        "--baud",
        type=int,
        default=1_000_000,
        help="bit/s: 9600, 57600, 115200, 1000000, 2000000, 3000000, 4000000 or 4500000 "
        "(default 1000000)",
    )
    parser.add_argument("--ids", default="1-9", help="ids to ping, e.g. 1-9 or 1,2,4 (default 1-9)")
    parser.add_argument(
        "--latency-ms",
        type=float,
        default=16.0,
        help="adapter latency for reply deadlines [ms] (default 16, the FTDI factory timer)",
    )
    parser.add_argument(
        "--attempts", type=int, default=3, help="ping attempts per id until it answers (default 3)"
    )
    parser.add_argument(
        "--count",
        type=int,
        default=10,
        help="further pings per servo that answered, for link quality (default 10)",
    )


@dataclass
class _Servo:
    """What the ping learned about one id: its answer, the exchanges with it and how they
    failed, its alert bit and hardware faults."""

    id: int
    info: PingInfo | None = None
    exchanges: int = 0
    lost: int = 0
    corrupt: int = 0
    alert: bool = False
    faults: tuple[str, ...] = ()
    unreadable: str = ""  # why Hardware Error Status could not be read


def _exchange(
    servo: _Servo, call: Callable[..., _T], *args: object, counted: bool = True
) -> _T | None:
    """One exchange with ``servo``; None when its reply was lost or corrupt (a servo
    answering CRC error got a corrupt instruction: also corrupt). ``counted`` exchanges
    make the link quality."""
    n = int(counted)
    servo.exchanges += n
    try:
        return call(*args)
    except NoReply:
        servo.lost += n
    except CorruptReply:  # TruncatedReply included
        servo.corrupt += n
    except ServoError as e:
        if e.result is not StatusResult.CRC_ERROR:
            raise
        servo.corrupt += n
    return None


def _probe(bus: DxlBus, servo: _Servo, attempts: int, count: int) -> None:
    """Ping until it answers, ``count`` more pings (the link quality), then read Hardware
    Error Status."""
    for _ in range(attempts):
        servo.info = _exchange(servo, bus.ping, servo.id)
        if servo.info is not None:
            break
    if servo.info is None:
        return
    servo.alert = servo.info.alert
    for _ in range(count):
        info = _exchange(servo, bus.ping, servo.id)
        servo.alert |= info is not None and info.alert
    if servo.info.model not in MODELS:
        return  # no control table known: address 70 may mean something else
    reg = MODELS[servo.info.model].reg("hardware_error_status")
    for _ in range(attempts):  # not link quality: a servo may answer pings only (SRL 0)
        st = _exchange(servo, bus.read_status, servo.id, reg.address, reg.size, counted=False)
        if st is None:
            continue
        servo.alert |= st.alert
        if st.result is StatusResult.CRC_ERROR:
            continue
        if not st.ok or len(st.data) != reg.size:
            servo.unreadable = st.result.text if not st.ok else "wrong length"
            return
        servo.faults = decode_hardware_error(st.data[0])
        servo.unreadable = ""
        return
    servo.unreadable = (
        f"no valid reply to a read in {attempts} attempts (Status Return Level 0, or noise?)"
    )


def _servo_line(servo: _Servo) -> str:
    assert servo.info is not None
    info = servo.info
    model = MODELS[info.model].name if info.model in MODELS else "unknown model"
    line = f"id {servo.id}: {model} (model {info.model}), firmware {info.firmware}"
    if servo.faults:
        line += f", HARDWARE ERROR: {', '.join(servo.faults)}"
    elif servo.alert:
        line += ", HARDWARE ALERT (alert bit set in its status packets)"
    if servo.unreadable:
        line += f", Hardware Error Status unreadable: {servo.unreadable}"
    return line


def ping(args: argparse.Namespace) -> int:
    """Ping, check fitness and link quality; the exit status of the module docstring."""
    port = args.port
    try:
        ids = parse_ids(args.ids)
        problem = baud_rate_problem(args.baud)
        if problem:
            raise ValueError(f"--baud: {problem}")
        cfg = BusConfig(port, int(args.baud), float(args.latency_ms) / 1000.0)
        if not 1 <= args.attempts <= _MAX_COUNT:
            raise ValueError(f"--attempts must be in 1..{_MAX_COUNT}, got {args.attempts}")
        if not 0 <= args.count <= _MAX_COUNT:
            raise ValueError(f"--count must be in 0..{_MAX_COUNT}, got {args.count}")
    except ValueError as e:
        print(f"{DEVICE} {port}: {e}", file=sys.stderr)
        return 2
    bus = DxlBus(cfg)
    servos = [_Servo(i) for i in ids]
    try:
        bus.open()
        for servo in servos:
            _probe(bus, servo, args.attempts, args.count)
            if servo.info is not None:
                print(_servo_line(servo))
    except PortUnavailable as e:
        print(f"{DEVICE} {port}: {e.detail}", file=sys.stderr)
        return 2
    except LinkLost as e:
        print(f"{DEVICE} {port}: {e.detail} during the ping", file=sys.stderr)
        return 1
    except DynamixelError as e:
        print(f"{DEVICE} {port}: {e}", file=sys.stderr)
        return 1
    finally:
        bus.close()
    return _judge(args, servos)


def _judge(args: argparse.Namespace, servos: list[_Servo]) -> int:
    """Print the link line and at most one line on stderr; the exit status."""
    where = f"{DEVICE} {args.port}"
    found = [s for s in servos if s.info is not None]
    corrupt_ids = [s.id for s in servos if s.corrupt]
    if not found:
        why = (
            "corrupt frames (wrong baud rate or noise?)"
            if corrupt_ids
            else "no answer within the deadline"
        )
        print(f"{where}: {why} from any of ids {args.ids} at {args.baud} baud", file=sys.stderr)
        return 1
    exchanges = sum(s.exchanges for s in found)
    lost, corrupt = sum(s.lost for s in found), sum(s.corrupt for s in found)
    ratio = (lost + corrupt) / exchanges
    print(
        f"{where}: link: {exchanges} exchanges with {len(found)} servos, {lost} lost, "
        f"{corrupt} corrupt ({100 * ratio:.1f} %)"
    )
    note = (
        f"link quality {100 * ratio:.1f} % lost or corrupt (above {100 * LINK_WARN_RATIO:g} %: "
        "check the cables and connectors, the adapter's latency timer and the baud rate)"
    )
    also = f"; also {note}" if ratio > LINK_WARN_RATIO else ""
    missing = [s.id for s in servos if s.info is None]
    faulted = [f"id {s.id} {'+'.join(s.faults) or 'alert'}" for s in found if s.faults or s.alert]
    unreadable = [f"id {s.id} ({s.unreadable})" for s in found if s.unreadable]
    if missing:
        extra = f" (corrupt frames from {', '.join(map(str, corrupt_ids))})" if corrupt_ids else ""
        problem = f"no answer within the deadline from ids {', '.join(map(str, missing))}{extra}"
    elif faulted:
        problem = (
            f"servo fault: {', '.join(faulted)} (torque is off: find the cause, then reboot "
            "the servo, e.g. power-cycle or WX250s.reboot())"
        )
    elif unreadable:
        problem = f"Hardware Error Status unreadable from {', '.join(unreadable)}"
    else:
        if also:
            print(f"{where}: warning: {note}", file=sys.stderr)
        return 0
    print(f"{where}: {problem}{also}", file=sys.stderr)
    return 1


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
    parser.add_argument(
        "--drop-every", type=int, default=0, metavar="N",
        help="lose every N-th status packet (a noisy bus; default 0: none)",
    )
    parser.add_argument(
        "--corrupt-every", type=int, default=0, metavar="N",
        help="send every N-th status packet with a bad CRC (default 0: none)",
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
    for flag in ("drop_every", "corrupt_every"):
        n = getattr(args, flag)
        if n < 0:
            raise ValueError(f"--{flag.replace('_', '-')} must be >= 0, got {n}")
        setattr(fake, flag, n)
    return fake


def run_fake(args: argparse.Namespace) -> int:
    try:
        fake = make_fake(args)
    except ValueError as e:
        print(f"{DEVICE} fake: {e}", file=sys.stderr)
        return 2
    from mmexec.drivers.fakes.pty import serve_until_signal

    serve_until_signal(fake, lambda port: print(port, flush=True))
    return 0
