"""Driver benchmarks: CPU cost per control cycle of the WX250s DYNAMIXEL driver versus raw dynamixel-sdk.

The cycle (issue #3): one Sync Write of Goal Position to 7 servos (the wx250s joint ids
1, 2, 4, 6, 7, 8, 9) and one Sync Read of 12 bytes at address 126 (current/load, velocity,
position) from the 9 servos of the arm (ids 1-9, shadows included), encode + decode, values
converted to SI units, against the protocol-level fake bus.

* ours: :class:`mmexec.drivers.dynamixel.wx250s.CycleIO` (the code the arm's I/O thread runs
  every cycle) over :class:`~mmexec.drivers.dynamixel.bus.DxlBus`;
* raw: dynamixel-sdk 4.1 ``GroupSyncWrite`` / ``GroupSyncRead`` on a ``PortHandler`` /
  ``Protocol2PacketHandler`` with the same SI conversion of the read values.

Method: the fake runs in a *separate process* (``mmexec hw fake dynamixel`` equivalent, RDT
0) on a pty, so its CPU and its reply latency are not charged to the host side. The host
cost is the calling thread's CPU time (``time.thread_time()``) over a block of cycles,
divided by the number of cycles; ours and raw alternate in blocks and the median block
is reported. Wall time per cycle is printed for reference. dynamixel-sdk polls the port
with non-blocking reads until the reply arrives (its timeout is ``time.time()`` based), so
its CPU time includes the wait; ours blocks in ``select()``. The second comparison
(``dxl_codec_*``) removes that difference: both libraries run the same cycle against an
in-memory port that hands back the recorded reply bytes at once, which measures pure
framing/encode/decode CPU.

Output: other sections first, then the dxl lines; the last line is ``dxl_cycle_ratio: X``
(ours / raw thread CPU per cycle against the fake; target <= 1.3).

Usage: ``python benchmarks/drivers.py [--cycles 300] [--blocks 7]``.
"""

from __future__ import annotations

import argparse
import platform
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import dynamixel_sdk as sdk

from mmexec.drivers.dynamixel import codec
from mmexec.drivers.dynamixel.bus import BusConfig, DxlBus
from mmexec.drivers.dynamixel.control_table import (
    MODELS,
    current_to_amps,
    load_to_fraction,
    pulses_to_rad,
    velocity_to_rad_s,
)
from mmexec.drivers.dynamixel.wx250s import CycleIO

WRITE_IDS = (1, 2, 4, 6, 7, 8, 9)
READ_IDS = tuple(range(1, 10))
MODEL_OF = {i: MODELS[1060] if i in (8, 9) else MODELS[1020] for i in READ_IDS}
GOALS = (2048, 1200, 2600, 2048, 2300, 2048, 2048)


# --------------------------------------------------------------------------- the two cycles


def ours_cycle_fn(bus: DxlBus) -> Callable[[], object]:
    io = CycleIO(bus, WRITE_IDS, READ_IDS, MODEL_OF)

    def cycle() -> object:
        return io.cycle(GOALS)

    return cycle


def raw_cycle_fn(port: sdk.PortHandler) -> Callable[[], object]:
    ph = sdk.PacketHandler(2.0)
    gsw = sdk.GroupSyncWrite(port, ph, 116, 4)
    gsr = sdk.GroupSyncRead(port, ph, 126, 12)
    for i in READ_IDS:
        gsr.addParam(i)
    has_current = {i: MODEL_OF[i].has_current_sensor for i in READ_IDS}

    def s16(v: int) -> int:
        return v - 0x10000 if v & 0x8000 else v

    def s32(v: int) -> int:
        return v - 0x100000000 if v & 0x80000000 else v

    def cycle() -> object:
        gsw.clearParam()
        for i, p in zip(WRITE_IDS, GOALS):
            gsw.addParam(
                i,
                [
                    sdk.DXL_LOBYTE(sdk.DXL_LOWORD(p)),
                    sdk.DXL_HIBYTE(sdk.DXL_LOWORD(p)),
                    sdk.DXL_LOBYTE(sdk.DXL_HIWORD(p)),
                    sdk.DXL_HIBYTE(sdk.DXL_HIWORD(p)),
                ],
            )
        if gsw.txPacket() != sdk.COMM_SUCCESS:
            raise RuntimeError("raw sync write failed")
        res = gsr.txRxPacket()
        if res != sdk.COMM_SUCCESS:
            raise RuntimeError(f"raw sync read failed: {ph.getTxRxResult(res)}")
        out = {}
        for i in READ_IDS:
            eff = s16(gsr.getData(i, 126, 2))
            vel = s32(gsr.getData(i, 128, 4))
            pos = s32(gsr.getData(i, 132, 4))
            out[i] = (
                pulses_to_rad(pos),
                velocity_to_rad_s(vel),
                current_to_amps(eff) if has_current[i] else load_to_fraction(eff),
            )
        return out

    return cycle


# --------------------------------------------------------------------------- in-memory ports (no I/O)


def _replies() -> bytes:
    return b"".join(codec.encode_status(i, 0, bytes(range(12))) for i in READ_IDS)


class _MemLink:
    """Duck-typed :class:`DxlSerialTransport`: answers every Sync Read at once."""

    is_open = True
    port = "mem"

    def __init__(self) -> None:
        self._pending = b""
        self._reply = _replies()

    def discard_input(self) -> int:
        return 0

    def write(self, data: bytes) -> None:
        if data[7] == codec.Instruction.SYNC_READ:
            self._pending = self._reply

    def wait_readable(self, timeout: float) -> bytes:
        data, self._pending = self._pending, b""
        return data


class _MemPort(sdk.PortHandler):
    """dynamixel-sdk port that answers every Sync Read at once (no serial port)."""

    def __init__(self) -> None:
        super().__init__("mem")
        self.is_open = True
        self.tx_time_per_byte = 0.01
        self._buf = b""
        self._reply = _replies()

    def clearPort(self) -> None:
        self._buf = b""

    def writePort(self, packet: Sequence[int]) -> int:
        if packet[7] == codec.Instruction.SYNC_READ:
            self._buf = self._reply
        return len(packet)

    def readPort(self, length: int) -> bytes:
        out, self._buf = self._buf[:length], self._buf[length:]
        return out

    def getBytesAvailable(self) -> int:
        return len(self._buf)


# --------------------------------------------------------------------------- measurement


def _block(fn: Callable[[], object], n: int) -> tuple[float, float]:
    c0, w0 = time.thread_time(), time.perf_counter()
    for _ in range(n):
        fn()
    return (time.thread_time() - c0) / n * 1e6, (time.perf_counter() - w0) / n * 1e6


def _compare(
    ours: Callable[[], object], raw: Callable[[], object], cycles: int, blocks: int
) -> tuple[float, float, float, float]:
    for fn in (ours, raw):  # warm up
        _block(fn, max(10, cycles // 10))
    o_cpu, o_wall, r_cpu, r_wall = [], [], [], []
    for _ in range(blocks):
        c, w = _block(ours, cycles)
        o_cpu.append(c)
        o_wall.append(w)
        c, w = _block(raw, cycles)
        r_cpu.append(c)
        r_wall.append(w)
    med = statistics.median
    return med(o_cpu), med(o_wall), med(r_cpu), med(r_wall)


def _start_fake() -> tuple[subprocess.Popen[str], str]:
    code = (
        "import argparse, sys\nfrom mmexec.drivers.dynamixel import bringup as b\n"
        "p = argparse.ArgumentParser(); b.add_fake_arguments(p)\n"
        "sys.exit(b.run_fake(p.parse_args(sys.argv[1:])))\n"
    )
    proc = subprocess.Popen(
        [sys.executable, "-c", code, "--configured"], stdout=subprocess.PIPE, text=True
    )
    assert proc.stdout is not None
    port = proc.stdout.readline().strip()
    if not port:
        proc.kill()
        raise RuntimeError("the fake DYNAMIXEL bus did not start")
    return proc, port


def bench_dxl(cycles: int = 300, blocks: int = 7) -> list[str]:
    """WX250s control cycle, ours vs raw dynamixel-sdk; the ratio line comes last."""
    lines: list[str] = []
    proc, port = _start_fake()
    try:
        bus = DxlBus(BusConfig(port, latency=0.016))  # the SDK's own 16 ms latency constant
        bus.open()
        raw_port = sdk.PortHandler(port)
        try:
            if not raw_port.openPort():
                raise RuntimeError(f"dynamixel-sdk could not open {port}")
            o_cpu, o_wall, r_cpu, r_wall = _compare(
                ours_cycle_fn(bus), raw_cycle_fn(raw_port), cycles, blocks
            )
        finally:
            raw_port.closePort()
            bus.close()
    finally:
        proc.terminate()
        proc.wait(timeout=5)
    mem_bus = DxlBus(BusConfig("mem"), transport=_MemLink())  # type: ignore[arg-type]
    m_o, _, m_r, _ = _compare(ours_cycle_fn(mem_bus), raw_cycle_fn(_MemPort()), cycles, blocks)
    lines += [
        f"dxl_cycle_wall_us: {o_wall:.1f}",
        f"dxl_raw_cycle_us: {r_cpu:.1f}",
        f"dxl_raw_cycle_wall_us: {r_wall:.1f}",
        f"dxl_codec_us: {m_o:.1f}",
        f"dxl_raw_codec_us: {m_r:.1f}",
        f"dxl_codec_ratio: {m_o / m_r:.3f}",
        f"dxl_cycle_us: {o_cpu:.1f}",
        f"dxl_cycle_ratio: {o_cpu / r_cpu:.3f}",
    ]
    return lines


# --------------------------------------------------------------------------- other drivers
# Kobuki feedback parse throughput and the Robotiq status round trip (issue #3) are added
# here by their owners as functions returning output lines, listed in OTHER_SECTIONS; they
# print before the dxl section so that dxl_cycle_ratio stays the last line.
def bench_kobuki(frames: int = 20_000) -> list[str]:
    """Kobuki feedback parsing: frames/s through FrameParser + decode_feedback.

    The stream is the vendor's 50 Hz feedback frame (ids 1, 3, 4, 5, 6, 13, 16 with two
    raw-gyro samples, 77-byte payload) repeated, fed in 64-byte chunks the way an FTDI
    link with a 1 ms latency timer delivers them; CPU time of this thread.
    """
    from mmexec.drivers.kobuki import codec as kc

    payload = b"".join(
        (
            kc.encode_core_sensors(kc.CoreSensors(timestamp_ms=1234, bumper=0, wheel_drop=0, cliff=0,
                                                  left_encoder=40000, right_encoder=40010,
                                                  left_pwm=10, right_pwm=10, buttons=0, charger=0,
                                                  battery=16.1, overcurrent=0)),
            kc.encode_dock_ir(kc.DockInfrared(0, 0, 0)),
            kc.encode_inertia(0.5, 0.1),
            kc.encode_cliff(kc.CliffSensors(1000, 1000, 1000)),
            kc.encode_current(0.1, 0.1),
            kc.encode_gyro(7, [(1.0, 2.0, 3.0), (1.0, 2.0, 3.0)]),
            kc.encode_gp_input(kc.GpInput(0, (0, 0, 0, 0))),
        )
    )
    frame = kc.encode_frame(payload)
    stream = frame * frames
    chunks = [stream[i : i + 64] for i in range(0, len(stream), 64)]
    parser = kc.FrameParser()
    t0 = time.process_time()
    decoded = 0
    for chunk in chunks:
        for body in parser.feed(chunk):
            kc.decode_feedback(body)
            decoded += 1
    dt = time.process_time() - t0
    assert decoded == frames, (decoded, frames)
    return [
        f"kobuki_frame_bytes: {len(frame)}",
        f"kobuki_parse_us_per_frame: {dt / frames * 1e6:.1f}",
        f"kobuki_parse_frames_per_s: {frames / dt:.0f}",
    ]


def bench_robotiq(requests: int = 200) -> list[str]:
    """Robotiq 2F-85 status round trip: FC04 read of the 3 status registers, request
    written to the pty fake and the reply read and decoded, median wall time [ms]
    (the gripper's own 5 ms request spacing excluded by setting min_gap 0)."""
    from mmexec.drivers.fakes.robotiq import FakeRobotiq
    from mmexec.drivers.robotiq import codec as rc
    from mmexec.drivers.robotiq.device import ModbusSettings, RobotiqModbus

    with FakeRobotiq() as fake:
        dev = RobotiqModbus(ModbusSettings(fake.port, min_gap=0.0))
        dev._connect()
        try:
            req = rc.encode_read(9, 4, rc.INPUT_BASE, 3)
            n = rc.read_reply_length(3)
            times = []
            for _ in range(requests):
                t0 = time.perf_counter()
                rc.decode_read_reply(dev.exchange(req, n), 9, 4, 3)
                times.append(time.perf_counter() - t0)
        finally:
            dev._disconnect()
    return [f"robotiq_status_round_trip_ms: {statistics.median(times) * 1e3:.2f} (median of {requests})"]


def _refusing_host() -> str:
    """A loopback address on which nothing listens on port 30004 (a connect is refused)."""
    for last in range(100, 150):
        host = f"127.0.0.{last}"
        with socket.socket() as probe:
            if probe.connect_ex((host, 30004)) != 0:
                return host
    raise RuntimeError("every probed loopback address listens on port 30004")


_UR_MISSION = "mission: ur_bringup\ntree:\n  skill: report\n  params: {message: connected}\n"


def _ur_open_failure(host: str, connect_timeout: float) -> float:
    """Wall seconds from ``URArm.open()`` to its one-line URConnectionError."""
    from mmexec.drivers.ur.arm import URArm, URArmConfig, URConnectionError

    arm = URArm(URArmConfig(host=host, connect_timeout=connect_timeout))
    t0 = time.perf_counter()
    try:
        arm.open()
    except URConnectionError as e:
        took = time.perf_counter() - t0
        if "\n" in str(e):
            raise RuntimeError(f"the failure is not one line: {e!r}") from e
        return took
    finally:
        arm.close()
    raise RuntimeError(f"URArm.open() to {host} did not fail")


def _ur_run_failure(host: str, connect_timeout: float) -> float:
    """Wall seconds from starting ``mmexec run`` (a config whose arm is the silent host) to
    its exit with status 2 and one line on stderr."""
    exe = Path(sys.executable).with_name("mmexec")
    with tempfile.TemporaryDirectory() as tmp:
        mission, config = Path(tmp, "mission.yaml"), Path(tmp, "ur.yaml")
        mission.write_text(_UR_MISSION)
        config.write_text(f"backend: robot\nrate_hz: 20\nrobot:\n  arm: {{kind: ur, host: {host}, "
                          f"connect_timeout: {connect_timeout}}}\nprofile: {{}}\n")
        t0 = time.perf_counter()
        proc = subprocess.run([str(exe), "run", str(mission), "--config", str(config), "--log", str(Path(tmp, "l.jsonl"))],
                              check=False, capture_output=True, text=True, timeout=connect_timeout + 60.0)
        took = time.perf_counter() - t0
    lines = proc.stderr.strip().splitlines()
    if proc.returncode != 2 or len(lines) != 1:
        raise RuntimeError(f"mmexec run: exit {proc.returncode}, stderr {proc.stderr!r}")
    return took


def bench_ur_bringup(runs: int = 3, timeouts: Sequence[float] = (1.0, 2.0)) -> list[str]:
    """UR bring-up against a controller that never answers (issue 9: "bring-up fails in one
    line within connect_timeout + 1 s"): wall time from the start to the one-line failure,
    against ``connect_timeout`` T, median and max of ``runs`` per T.

    * ``ur_open_fail_s``: ``URArm.open()`` in this process until it raises (the driver's
      bring-up alone), against the RTDE stub: ``silent`` (it accepts TCP and never
      answers: the pre-flight check's deadline) and ``stalls`` (it answers the pre-flight,
      then never answers ur_rtde: the host process's deadline);
    * ``ur_run_fail_s``: a whole ``mmexec run`` against the silent stub (interpreter
      start, imports, config, bring-up, exit) until it exits 2 with one line on stderr;
      ``refused``: the same against a host where nothing listens (an immediate failure),
      i.e. what the command costs around the bring-up.

    The last two lines: ``ur_bringup_overshoot_s``, the worst time past T of the
    bring-up (every ``ur_open_fail_s`` run; the issue's bound, 1 s), and
    ``ur_run_overshoot_s``, the same for the whole command, start-up included.
    """
    from mmexec.drivers.ur.rtde_stub import RTDEStub, StubError

    lines: list[str] = []
    worst = {"open": 0.0, "run": 0.0}

    def report(name: str, t: float, took: list[float]) -> None:
        kind = name.split("_")[1]
        worst[kind] = max(worst[kind], max(took) - t)
        lines.append(f"{name}: T {t:.1f} s: median {statistics.median(took):.3f} s, max {max(took):.3f} s "
                     f"(+{max(took) - t:.3f} s over T, {len(took)} runs)")

    for last in range(150, 200):  # a loopback address whose port 30004 is free
        try:
            stub = RTDEStub(f"127.0.0.{last}").start()
            break
        except StubError as e:
            if "Address already in use" not in str(e):
                raise
    else:
        raise RuntimeError("no free loopback address for the RTDE stub on port 30004")
    try:
        stub.silence(0)  # every connection accepted and never answered
        for t in timeouts:
            report("ur_open_fail_s silent", t, [_ur_open_failure(stub.host, t) for _ in range(runs)])
        for t in timeouts:
            took = []
            for _ in range(runs):
                stub.silence(after=1)  # the pre-flight is served, ur_rtde's connection is not
                took.append(_ur_open_failure(stub.host, t))
            report("ur_open_fail_s stalls", t, took)
        stub.silence(0)
        for t in timeouts:
            report("ur_run_fail_s silent", t, [_ur_run_failure(stub.host, t) for _ in range(runs)])
        refused = [_ur_run_failure(_refusing_host(), 1.0) for _ in range(runs)]
        lines.append(f"ur_run_fail_s refused: median {statistics.median(refused):.3f} s, max {max(refused):.3f} s "
                     f"({runs} runs)")
    finally:
        stub.stop()
    lines.append(f"ur_bringup_overshoot_s: {worst['open']:.3f} (limit 1.0)")
    lines.append(f"ur_run_overshoot_s: {worst['run']:.3f} (command start-up included)")
    return lines


OTHER_SECTIONS: list[Callable[[], list[str]]] = [bench_kobuki, bench_robotiq, bench_ur_bringup]


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cycles", type=int, default=300, help="cycles per block (default 300)")
    ap.add_argument("--blocks", type=int, default=7, help="alternating blocks per side (default 7)")
    args = ap.parse_args(argv)
    print(
        f"# machine: {platform.machine()} {platform.processor() or ''} python {platform.python_version()}"
    )
    for section in OTHER_SECTIONS:
        for line in section():
            print(line)
    for line in bench_dxl(args.cycles, args.blocks):
        print(line, flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
