"""Bring-up for the RPLIDAR A2: ``mmexec hw ping rplidar`` and ``mmexec hw fake rplidar``.

``ping`` opens the port, reads model, firmware, hardware, serial number and health,
then scans for ``--duration`` seconds and measures the revolution rate and the points
per revolution::

    rplidar on /dev/rplidar: A2M8 (model 0x28), firmware 1.29, hardware 7, serial 101112..., health good, 10.0 Hz, 200 points/rev, motor DTR+PWM 660

Exit status: 0 ready; 1 fault (no answer, corrupt stream, health ERROR, no complete
scan: motor stopped, no start flag, corrupt nodes, link lost); 2 the port cannot be
opened (no such port, permission denied, busy) or a bad option. Every failure is one
line on stderr naming the device and the port. The motor is stopped again on exit.
``run_fake`` serves a fake lidar on a pty and prints its port.
"""

from __future__ import annotations

import argparse
import sys
import time

from mmexec.drivers.fakes.pty import serve_until_signal
from mmexec.drivers.fakes.rplidar import RplidarFake
from mmexec.drivers.rplidar import codec as c
from mmexec.drivers.rplidar.device import (
    RplidarConfig,
    RplidarDevice,
    RplidarError,
    RplidarPortError,
    RplidarStats,
    RplidarTimeout,
)

__all__ = ["add_fake_arguments", "add_ping_arguments", "ping", "run_fake"]

#: poll period of the CLI while it waits for scans [s] (a CLI waiting, not a tick)
_POLL = 0.02


def add_ping_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--port", default="/dev/rplidar", help="serial port (default: /dev/rplidar)")
    parser.add_argument("--timeout", type=float, default=0.5, metavar="S",
                        help="seconds to wait for each answer (default: 0.5)")
    parser.add_argument("--duration", type=float, default=2.0, metavar="S",
                        help="seconds of scanning to measure rate and points (default: 2)")
    parser.add_argument("--pwm", type=int, default=c.DEFAULT_MOTOR_PWM,
                        help=f"motor PWM 1-{c.MAX_MOTOR_PWM} when the firmware takes it (default: 660)")


def ping(args: argparse.Namespace) -> int:
    """Identify the lidar and measure its scans; 0 ready, 1 fault, 2 cannot open."""
    where = f"rplidar on {args.port}"
    if not (args.timeout > 0 and args.duration > 0):
        print(f"{where}: --timeout and --duration must be > 0 s", file=sys.stderr)
        return 2
    try:
        dev = RplidarDevice(RplidarConfig(port=args.port, response_timeout=args.timeout, motor_pwm=args.pwm))
    except ValueError as e:
        print(str(e), file=sys.stderr)
        return 2
    try:
        info = dev.connect()
        dev.start()
        stats = _measure(dev, args.duration)
    except RplidarPortError as e:
        print(str(e), file=sys.stderr)
        return 2
    except RplidarError as e:
        print(str(e), file=sys.stderr)
        return 1
    finally:
        dev.close()
    d, h = info.device, info.health
    health = "good" if h.status is c.HealthStatus.GOOD else f"WARNING (code 0x{h.error_code:04X})"
    rate = f"{stats.scan_rate:.1f} Hz" if stats.scan_rate is not None else "rate unknown"
    points = f"{stats.points_per_scan:.0f} points/rev" if stats.points_per_scan is not None else "points unknown"
    motor = info.motor_control + (f" {args.pwm}" if info.motor_pwm_supported else "")
    print(f"{where}: {d.model_name} (model 0x{d.model:02X}), firmware {d.firmware}, hardware {d.hardware}, "
          f"serial {d.serial_text}, health {health}, {rate}, {points}, motor {motor}")
    return 0


def _measure(dev: RplidarDevice, duration: float) -> RplidarStats:
    """Wait for the first complete scan, then scan ``duration`` s; raises the device's
    fault (watchdog, link lost) as soon as it appears."""
    cfg = dev.config
    budget = cfg.spinup_timeout + cfg.watchdog_timeout + 0.5  # the watchdog fires before this
    deadline = time.monotonic() + budget
    while dev.latest_scan() is None:
        fault = dev.fault
        if fault is not None:
            raise fault
        if time.monotonic() > deadline:
            raise RplidarTimeout(dev.port, f"no complete scan within {budget:.1f} s")
        time.sleep(_POLL)
    end = time.monotonic() + duration
    while time.monotonic() < end:
        fault = dev.fault
        if fault is not None:
            raise fault
        time.sleep(_POLL)
    return dev.stats(window=duration)


def add_fake_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--scan-rate", type=float, default=10.0, metavar="HZ",
                        help="revolutions per second at PWM 660 (default: 10)")
    parser.add_argument("--sample-rate", type=float, default=2000.0, metavar="HZ",
                        help="samples per second (default: 2000, the A2's standard scan)")
    parser.add_argument("--health", choices=("good", "warning", "error"), default="good",
                        help="what GET_HEALTH reports (error rehearses the protection stop)")
    parser.add_argument("--no-pwm", action="store_true",
                        help="report no motor control (GET_ACC_BOARD_FLAG 0): on a pty the motor then cannot start")
    parser.add_argument("--seed", type=int, default=0, help="noise seed (default: 0)")


def run_fake(args: argparse.Namespace) -> int:
    """Start a fake RPLIDAR in a 6 m x 4 m room, print its port, serve until SIGINT / SIGTERM."""
    if not (0 < args.scan_rate <= 20 and 100 <= args.sample_rate <= 10000):
        print("rplidar fake: --scan-rate must be in (0, 20] Hz and --sample-rate in 100..10000",
              file=sys.stderr)
        return 2
    fake = RplidarFake(scan_rate=args.scan_rate, sample_rate=args.sample_rate,
                       motor_control=not args.no_pwm, seed=args.seed)
    fake.set_health({"good": 0, "warning": 1, "error": 2}[args.health], 0 if args.health == "good" else 0x8001)
    serve_until_signal(fake, lambda port: print(port, flush=True))
    return 0
