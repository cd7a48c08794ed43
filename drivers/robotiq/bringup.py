"""Bring-up for the Robotiq 2F-85: ``mmexec hw ping robotiq`` and ``mmexec hw fake robotiq``.

``ping`` opens the gripper (Modbus RTU on ``--port``, or the URCap socket with ``--host``);
``--activate`` runs the activation sequence first. It then reads the status ``--reads``
more times (the driver's I/O thread polls every 20 ms) and prints one line on stdout::

    robotiq on /dev/ttyUSB0: activated, fault none, position 0.0850 m (gPO 0), at requested position; link: 21 exchanges, 0 lost, 0 corrupt (0.0 %)

Fault 0x09 "no communication" is what a gripper reports after more than a second without
traffic (e.g. between ``ping --activate`` and the next ``ping``) and clears when traffic
resumes: the ping reads until it clears or the reads are spent, then judges.

Exit status, with at most one line on stderr naming the device, the port and the reason:

* 0: ready. A line ``warning: ...`` when more than 1 % of the exchanges were lost (no
  answer before the deadline) or corrupt (bad CRC or frame).
* 1: the gripper answered but is not fit to run: a gFLT fault (a 0x09 that does not clear
  included), activation failed, the robot is emergency-stopped (URCap), the link failed
  during the ping; or it gave no useful answer (no answer within the deadline, only
  corrupt frames).
* 2: bad input, or the port or socket cannot be opened (no such port, permission denied,
  busy, connection refused).

``run_fake`` serves a fake gripper and prints its port.
"""

from __future__ import annotations

import argparse
import sys
import time

from mmexec.drivers.interfaces import GoalState
from mmexec.drivers.robotiq import codec
from mmexec.drivers.robotiq.codec import Status
from mmexec.drivers.robotiq.core import DeviceSettings, LinkState, LinkStats, RobotiqDevice
from mmexec.drivers.robotiq.device import ModbusSettings, RobotiqModbus
from mmexec.drivers.robotiq.errors import (
    RobotiqError,
    RobotiqLinkError,
    RobotiqPortUnavailable,
    fault_error,
)
from mmexec.drivers.robotiq.urcap import URCAP_PORT, RobotiqURCap, URCapSettings

__all__ = [
    "LINK_WARN_RATIO",
    "add_fake_arguments",
    "add_ping_arguments",
    "describe",
    "ping",
    "run_fake",
]

#: ping warns when more than this fraction of the exchanges were lost or corrupt
LINK_WARN_RATIO = 0.01
#: the transient fault a gripper reports after more than 1 s without traffic
NO_COMMUNICATION = 0x09
_BACKSTOP = 5.0  # s beyond a wait's own bound before the CLI gives up on the driver

_STA = {0: "reset", 1: "activating", 2: "unused state 2", 3: "activated"}
_OBJ = {0: "moving", 1: "object caught while opening", 2: "object caught while closing",
        3: "at requested position"}


def add_ping_arguments(parser: argparse.ArgumentParser) -> None:
    where = parser.add_mutually_exclusive_group(required=True)
    where.add_argument("--port", help="serial port of the RS-485 adapter, e.g. /dev/ttyUSB0")
    where.add_argument("--host", help="UR controller running the Robotiq URCap (TCP 63352)")
    parser.add_argument("--tcp-port", type=int, default=URCAP_PORT,
                        help="URCap port with --host (default %(default)s)")
    parser.add_argument("--slave", type=int, default=codec.DEFAULT_SLAVE,
                        help="Modbus slave id (default %(default)s)")
    parser.add_argument("--baud", type=int, default=115200, help="default %(default)s")
    parser.add_argument("--read-function", type=int, choices=(3, 4), default=4,
                        help="status read function: 4 (later manuals) or 3 (2016 edition)")
    parser.add_argument("--timeout", type=float, default=0.1,
                        help="reply latency allowance [s] on top of the wire time")
    parser.add_argument("--activate", action="store_true",
                        help="run the activation sequence (the fingers travel fully!)")
    parser.add_argument("--activation-timeout", type=float, default=10.0, help="seconds")
    parser.add_argument("--reads", type=int, default=20,
                        help="status reads after the first, for faults and link quality "
                             "(default %(default)s, 1..1000)")


def describe(status: Status) -> str:
    """One human line for a status: state, fault, position in m and raw, object."""
    fault = "none" if status.gFLT == 0 else (
        f"0x{status.gFLT:02X} {fault_error(status.gFLT).info.name}")
    obj = _OBJ[status.gOBJ] if status.gGTO else "no motion requested"
    return (f"{_STA[status.gSTA]}, fault {fault}, position "
            f"{codec.position_to_width(status.gPO):.4f} m (gPO {status.gPO}), {obj}")


def _device(args: argparse.Namespace) -> tuple[RobotiqDevice, str]:
    if not 1 <= args.reads <= 1000:
        raise ValueError(f"--reads must be in 1..1000, got {args.reads}")
    settings = DeviceSettings(activation_timeout=args.activation_timeout)
    if args.host:
        where = f"{args.host}:{args.tcp_port}"
        link = URCapSettings(args.host, args.tcp_port, reply_timeout=max(args.timeout, 0.05))
        return RobotiqURCap(link, settings), f"robotiq urcap on {where}"
    msettings = ModbusSettings(args.port, args.baud, args.slave, args.read_function,
                               latency=args.timeout)
    return RobotiqModbus(msettings, settings), f"robotiq on {args.port}"


def _reason(e: RobotiqError) -> str:
    if isinstance(e, RobotiqLinkError):
        return e.detail.removeprefix("robotiq urcap: ").removeprefix("robotiq: ")
    return str(e).split(": ", 1)[-1]


def ping(args: argparse.Namespace) -> int:
    """Read (and with --activate, activate) the gripper; exit status as the module says."""
    try:
        dev, name = _device(args)
    except ValueError as e:
        print(f"robotiq: {e}", file=sys.stderr)
        return 2
    try:
        status = dev.open()
    except RobotiqError as e:
        print(f"{name}: {_reason(e)}", file=sys.stderr)
        return 2 if isinstance(e, RobotiqPortUnavailable) else 1
    try:
        problem = _activate(dev) if args.activate else ""
        if not problem:
            status, problem = _sample(dev, status, args.reads)
        stats = dev.link_stats()
    finally:
        dev.close()
    print(f"{name}: {describe(status)}; link: {_link_text(stats)}")
    if not problem and status.gFLT:
        problem = f"device fault: {describe(status)}"
        if status.gFLT == NO_COMMUNICATION:
            problem += f" (did not clear over {args.reads} reads)"
    poor = stats.failure_rate > LINK_WARN_RATIO
    note = (f"link quality {100 * stats.failure_rate:.1f} % lost or corrupt (above "
            f"{100 * LINK_WARN_RATIO:g} %: check the cable, the RS-485 adapter and the baud "
            "rate)")
    if problem:
        print(f"{name}: {problem}" + (f"; also {note}" if poor else ""), file=sys.stderr)
        return 1
    if poor:
        print(f"{name}: warning: {note}", file=sys.stderr)
    return 0


def _activate(dev: RobotiqDevice) -> str:
    """Run the activation goal to its end; "" or the reason. The goal's own deadline
    (activation timeout, on the device's clock) ends it; ours is a backstop."""
    goal = dev.activate()
    backstop = dev.clock.now() + dev.settings.activation_timeout + _BACKSTOP
    while not goal.done() and dev.clock.now() < backstop:
        time.sleep(0.02)  # a CLI waiting for its one action, not a tick
    if not goal.done():
        goal.cancel()
        return (f"activation failed: no result within "
                f"{dev.settings.activation_timeout + _BACKSTOP:g} s")
    if goal.state is GoalState.SUCCEEDED:
        return ""
    return f"activation failed: {goal.reason.removeprefix(dev.where + ': ')}"


def _sample(dev: RobotiqDevice, first: Status, reads: int) -> tuple[Status, str]:
    """Let the I/O thread read the status ``reads`` more times (link quality; a 0x09 has
    that long to clear); the last status and "" or why the link is not fit. Ends early
    when the link fails (bounded by the link's own deadlines and failure count)."""
    target = dev.link_stats().reads + reads
    backstop = dev.clock.now() + 10 * reads * dev.settings.poll_period + _BACKSTOP
    status = first
    while True:
        status = dev.status() or status
        err = dev.link_error
        if dev.link_state is not LinkState.CONNECTED and err is not None:
            return status, f"link failed during the ping: {_reason(err)}"
        if dev.link_stats().reads >= target:
            return status, ""
        if dev.clock.now() > backstop:
            done = dev.link_stats().reads - (target - reads)
            return status, f"only {done} of {reads} status reads came back in time"
        time.sleep(dev.settings.poll_period)


def _link_text(stats: LinkStats) -> str:
    return (f"{stats.exchanges} exchanges, {stats.lost} lost, {stats.corrupt} corrupt "
            f"({100 * stats.failure_rate:.1f} %)")


def add_fake_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--urcap", action="store_true",
                        help="serve the URCap text protocol on 127.0.0.1 instead of Modbus")
    parser.add_argument("--tcp-port", type=int, default=0,
                        help="with --urcap: TCP port (default: a free one)")
    parser.add_argument("--activation-time", type=float, default=2.0,
                        help="seconds of gripper time an activation takes (default %(default)s)")
    parser.add_argument("--object-width", type=float, default=None,
                        help="an object between the fingers [m] that stops them closing")
    parser.add_argument("--time-scale", type=float, default=1.0,
                        help="run the fake's time this many times faster")
    parser.add_argument("--fault", type=lambda t: int(t, 0), default=None, metavar="CODE",
                        help="start with gFLT CODE, e.g. 0x0A (major faults 0x0A/0x0C/0x0E "
                             "stay until re-activation; 0x08 over-temperature)")
    parser.add_argument("--drop-every", type=int, default=0, metavar="N",
                        help="lose every N-th answer (a noisy link; default 0: none)")
    parser.add_argument("--corrupt-every", type=int, default=0, metavar="N",
                        help="corrupt every N-th answer (bad CRC, or a garbled URCap line)")


def run_fake(args: argparse.Namespace) -> int:
    """Start a fake gripper, print its port (``/dev/pts/N`` or ``127.0.0.1:PORT``) and
    serve until SIGINT / SIGTERM."""
    from mmexec.drivers.fakes.pty import serve_until_signal
    from mmexec.drivers.fakes.robotiq import FakeRobotiq, FakeURCap, GripperModel

    model = GripperModel(activation_time=args.activation_time, time_scale=args.time_scale,
                         object_width=args.object_width)
    if args.fault is not None:
        try:
            model.inject_fault(args.fault)
        except ValueError as e:
            print(f"robotiq fake: --fault: {e}", file=sys.stderr)
            return 2
    for flag in ("drop_every", "corrupt_every"):
        if getattr(args, flag) < 0:
            print(f"robotiq fake: --{flag.replace('_', '-')} must be >= 0", file=sys.stderr)
            return 2
    if args.urcap:
        server = FakeURCap(model, port=args.tcp_port)
        server.drop_every, server.garble_every = args.drop_every, args.corrupt_every
        serve_until_signal(server, lambda port: print(f"127.0.0.1:{port}", flush=True))
    else:
        fake = FakeRobotiq(model)
        fake.drop_every, fake.corrupt_every = args.drop_every, args.corrupt_every
        serve_until_signal(fake, lambda port: print(port, flush=True))
    return 0
