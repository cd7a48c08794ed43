"""Bring-up for the Robotiq 2F-85: ``mmexec hw ping robotiq`` and ``mmexec hw fake robotiq``.

``ping`` opens the gripper (Modbus RTU on ``--port``, or the URCap socket with ``--host``),
reads its status and prints one line (state, fault, position, object); ``--activate`` runs
the activation sequence first. Any problem is one line on stderr naming device and port
(no such port, permission denied, no answer within the deadline, corrupt frames, device
fault) and a non-zero exit. ``run_fake`` serves a fake gripper and prints its port.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
import time
from types import FrameType

from mmexec.drivers.robotiq import codec
from mmexec.drivers.robotiq.codec import Status
from mmexec.drivers.robotiq.core import DeviceSettings, RobotiqDevice
from mmexec.drivers.robotiq.device import ModbusSettings, RobotiqModbus
from mmexec.drivers.robotiq.errors import RobotiqError, RobotiqLinkError, fault_error
from mmexec.drivers.robotiq.urcap import URCAP_PORT, RobotiqURCap, URCapSettings

__all__ = ["add_fake_arguments", "add_ping_arguments", "describe", "ping", "run_fake"]

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


def describe(status: Status) -> str:
    """One human line for a status: state, fault, position in m and raw, object."""
    fault = "none" if status.gFLT == 0 else (
        f"0x{status.gFLT:02X} {fault_error(status.gFLT).info.name}")
    obj = _OBJ[status.gOBJ] if status.gGTO else "no motion requested"
    return (f"{_STA[status.gSTA]}, fault {fault}, position "
            f"{codec.position_to_width(status.gPO):.4f} m (gPO {status.gPO}), {obj}")


def _device(args: argparse.Namespace) -> tuple[RobotiqDevice, str]:
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
    """Read (and with --activate, activate) the gripper; 0 when it answers without fault."""
    try:
        dev, name = _device(args)
    except ValueError as e:
        print(f"robotiq: {e}", file=sys.stderr)
        return 2
    try:
        status = dev.open()
    except RobotiqError as e:
        print(f"{name}: {_reason(e)}", file=sys.stderr)
        return 1
    try:
        if args.activate:
            goal = dev.activate()
            deadline = time.monotonic() + args.activation_timeout + 1.0
            while not goal.done() and time.monotonic() < deadline:
                time.sleep(0.02)  # a CLI waiting for its one action, not a tick
            if not goal.done():
                goal.cancel()
            if goal.state.name != "SUCCEEDED":
                print(f"{name}: activation failed: {goal.reason.split(': ', 1)[-1]}",
                      file=sys.stderr)
                return 1
            status = dev.status() or status
        if status.gFLT:
            print(f"{name}: device fault: {describe(status)}", file=sys.stderr)
            return 1
        print(f"{name}: {describe(status)}")
        return 0
    finally:
        dev.close()


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


def run_fake(args: argparse.Namespace) -> int:
    """Start a fake gripper, print its port (``/dev/pts/N`` or ``127.0.0.1:PORT``) and
    serve until SIGINT / SIGTERM."""
    from mmexec.drivers.fakes.robotiq import FakeRobotiq, FakeURCap, GripperModel

    model = GripperModel(activation_time=args.activation_time, time_scale=args.time_scale,
                         object_width=args.object_width)
    if args.fault is not None:
        try:
            model.inject_fault(args.fault)
        except ValueError as e:
            print(f"robotiq fake: --fault: {e}", file=sys.stderr)
            return 2
    stop = threading.Event()

    def on_signal(signum: int, frame: FrameType | None) -> None:
        stop.set()

    old = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        if args.urcap:
            with FakeURCap(model, port=args.tcp_port) as server:
                print(f"127.0.0.1:{server.port}", flush=True)
                while not stop.wait(0.2):
                    pass
        else:
            with FakeRobotiq(model) as fake:
                print(fake.port, flush=True)
                while not stop.wait(0.2):
                    pass
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)
    return 0
