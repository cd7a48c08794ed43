"""The Modbus fake at the protocol level: raw frames over a serial port, as a slave sees them."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator

import pytest
from robotiq_helpers import wait_for

from mmexec.drivers.fakes.robotiq import FakeRobotiq, GripperModel
from mmexec.drivers.robotiq import codec
from mmexec.drivers.robotiq.codec import Command, Status
from mmexec.drivers.transport import LinkTimeout, SerialSettings, SerialTransport


@pytest.fixture
def bus() -> Iterator[tuple[FakeRobotiq, SerialTransport]]:
    with FakeRobotiq(activation_time=0.1, time_scale=10.0, object_width=0.03) as fake, \
            SerialTransport(SerialSettings(fake.port)) as link:
        yield fake, link


def xfer(link: SerialTransport, frame: bytes, n: int, timeout: float = 0.3) -> bytes:
    link.reset_input()
    link.write(frame)
    return link.read(n, time.monotonic() + timeout)


def status(link: SerialTransport, fc: int = 4) -> Status:
    reply = xfer(link, codec.encode_read(9, fc, codec.INPUT_BASE, 3), 11)
    return Status.from_registers(codec.decode_read_reply(reply, 9, fc, 3))


def write(link: SerialTransport, cmd: Command) -> None:
    reply = xfer(link, codec.encode_write_multiple(9, codec.OUTPUT_BASE, cmd.to_registers()), 8)
    codec.decode_write_multiple_reply(reply, 9, codec.OUTPUT_BASE, 3)


def activate(link: SerialTransport) -> None:
    write(link, Command())
    write(link, Command(rACT=True))
    assert wait_for(lambda: status(link).gSTA == 3, 1.0)


def test_activation_states(bus) -> None:  # type: ignore[no-untyped-def]
    _fake, link = bus
    assert status(link).status_byte == 0x00
    write(link, Command(rACT=True))
    assert status(link).status_byte == 0x11      # activating
    assert wait_for(lambda: status(link).status_byte == 0x31, 1.0)  # activated


def test_move_object_and_fc03(bus) -> None:  # type: ignore[no-untyped-def]
    fake, link = bus
    activate(link)
    write(link, Command(rACT=True, rGTO=True, rPR=255, rSP=255, rFR=128))
    s = status(link, fc=3)
    assert (s.status_byte, s.gPR) == (0x39, 255) and s.gCU > 0     # moving, echo, current
    assert wait_for(lambda: status(link).gOBJ != 0, 1.0)
    s = status(link)
    assert s.status_byte == 0xB9 and s.gPO == codec.width_to_position(0.03)
    # a gripper stopped on an object does not move again for the same request...
    write(link, Command(rACT=True, rGTO=True, rPR=255, rSP=255, rFR=128))
    assert status(link).gOBJ == 2
    # ...but does after the object is gone and the fingers reach the position
    fake.model.drop_object()
    assert wait_for(lambda: status(link).status_byte == 0xF9, 1.0)
    assert status(link).gPO == 255


def test_fc06_fc23_and_output_readback(bus) -> None:  # type: ignore[no-untyped-def]
    fake, link = bus
    req = codec.encode_write_single(9, codec.OUTPUT_BASE, 0x0100)
    assert xfer(link, req, 8) == req                          # FC06 echoes
    assert fake.model.command == Command(rACT=True)
    assert wait_for(lambda: status(link).gSTA == 3, 1.0)
    frame = codec.encode_read_write(9, codec.INPUT_BASE, 3, codec.OUTPUT_BASE,
                                    Command(rACT=True, rGTO=True, rPR=40, rSP=255).to_registers())
    s = Status.from_registers(codec.decode_read_reply(xfer(link, frame, 11), 9, 0x17, 3))
    assert s.gGTO and s.gPR == 40                              # write applied before the read
    back = xfer(link, codec.encode_read(9, 3, codec.OUTPUT_BASE, 3), 11)
    assert codec.decode_read_reply(back, 9, 3, 3) == (0x0900, 0x0028, 0xFF00)


@pytest.mark.parametrize(
    "frame",
    [
        codec.encode_read(9, 4, codec.INPUT_BASE, 3)[:-1] + b"\x00",   # bad CRC
        codec.encode_read(8, 4, codec.INPUT_BASE, 3),                   # other slave
        codec.append_crc(bytes.fromhex("09 2B 0E 01 00")),              # unknown function
        codec.encode_read(9, 4, 0x1000, 3),                             # outside the blocks
    ],
)
def test_silence_for_invalid_requests(bus, frame: bytes) -> None:  # type: ignore[no-untyped-def]
    _fake, link = bus
    link.write(frame)
    with pytest.raises(LinkTimeout):
        link.read(1, time.monotonic() + 0.1)
    assert status(link).gSTA == 0   # and the slave still answers afterwards


def test_fault_switches_no_reply_and_bad_crc(bus) -> None:  # type: ignore[no-untyped-def]
    fake, link = bus
    fake.no_reply = True
    with pytest.raises(LinkTimeout):
        xfer(link, codec.encode_read(9, 4, codec.INPUT_BASE, 3), 11, timeout=0.1)
    fake.no_reply = False
    fake.corrupt_replies = True
    reply = xfer(link, codec.encode_read(9, 4, codec.INPUT_BASE, 3), 11)
    assert not codec.check_crc(reply)


def test_priority_faults(bus) -> None:  # type: ignore[no-untyped-def]
    _fake, link = bus
    # 0x07: rGTO without rACT; cleared by activation
    write(link, Command(rGTO=True, rPR=100))
    assert status(link).gFLT == 0x07
    # 0x05: a move during activation waits, then runs
    write(link, Command(rACT=True))
    write(link, Command(rACT=True, rGTO=True, rPR=100, rSP=255))
    s = status(link)
    assert (s.gSTA, s.gFLT) == (1, 0x05)
    assert wait_for(lambda: status(link).gOBJ == 3, 1.0)
    s = status(link)
    assert (s.gFLT, s.gPO, s.gPR) == (0, 100, 100)


def test_major_fault_needs_rising_edge(bus) -> None:  # type: ignore[no-untyped-def]
    fake, link = bus
    activate(link)
    fake.model.inject_fault(0x0E)
    write(link, Command(rACT=True, rGTO=True, rPR=200, rSP=255))
    assert status(link).gFLT == 0x0E and status(link).gPO == 0   # no motion
    write(link, Command(rACT=True))                                # no edge: stays
    assert status(link).gFLT == 0x0E
    write(link, Command())
    assert status(link).gFLT == 0x0E                               # reset alone: stays
    write(link, Command(rACT=True))                                # rising edge clears
    assert status(link).gFLT == 0


def test_minor_faults(bus) -> None:  # type: ignore[no-untyped-def]
    fake, link = bus
    activate(link)
    fake.model.inject_fault(0x08)
    assert status(link).gFLT == 0x08
    fake.model.cool(79.0)
    assert status(link).gFLT == 0
    fake.model.comm_timeout = 0.5           # scaled: 50 ms of wall time
    time.sleep(0.12)
    assert status(link).gFLT == 0x09        # reported once traffic resumes...
    assert status(link).gFLT == 0           # ...then cleared


def test_auto_release(bus) -> None:  # type: ignore[no-untyped-def]
    _fake, link = bus
    activate(link)
    write(link, Command(rACT=True, rGTO=True, rPR=120, rSP=255))
    assert wait_for(lambda: status(link).gOBJ == 3, 1.0)
    write(link, Command(rACT=True, rATR=True))
    s = status(link)
    assert (s.gFLT, s.gSTA) == (0x0B, 0)
    assert wait_for(lambda: status(link).gFLT == 0x0F, 2.0)
    assert status(link).gPO == 0            # opened to the mechanical stop


def test_activation_fault(bus) -> None:  # type: ignore[no-untyped-def]
    fake, link = bus
    fake.model.activation_fault = True
    write(link, Command(rACT=True))
    assert wait_for(lambda: status(link).gFLT == 0x0D, 1.0)
    fake.model.activation_fault = False
    activate(link)
    assert status(link).gFLT == 0


# --------------------------------------------------------------- the firmware model, stepped
# explicit times (the model takes ``now``), so no wall time is involved


def activated_model(**kw: object) -> GripperModel:
    model = GripperModel(start=0.0, **kw)  # type: ignore[arg-type]
    model.write(Command(), 0.0)
    model.write(Command(rACT=True), 0.0)
    model.touch(model.activation_time)            # the request that sees it activated
    model.after_request()
    assert model.status().gSTA == 3
    return model


def test_activation_takes_seconds_and_the_fingers_travel_fully() -> None:
    model = GripperModel(start=10.0)              # vendor: seconds, fingers travel fully
    assert model.activation_time == 2.0
    model.write(Command(rACT=True), 10.0)
    seen = []
    for t in (10.5, 11.0, 11.5, 11.75):
        model.step(t)
        st = model.status()
        seen.append((st.gSTA, st.gPO))
    assert seen == [(1, 128), (1, 255), (1, 128), (1, 64)]   # closed, then back open
    model.step(12.0)
    assert (model.status().gSTA, model.status().gPO) == (3, 0)


def test_activation_that_never_completes_can_be_released() -> None:
    model = GripperModel(activation_time=math.inf, start=0.0)
    model.write(Command(rACT=True), 0.0)
    model.step(1e6)
    assert model.status().gSTA == 1
    model.activation_time = 2.0                   # already longer than that: done next step
    model.step(1e6 + 0.01)
    assert model.status().gSTA == 3


def test_no_communication_after_a_second_of_silence() -> None:
    model = activated_model()
    t = model.activation_time
    model.step(t + 0.99)
    assert model.status().gFLT == 0               # the vendor's "at least 1 s"
    model.step(t + 1.01)
    assert model.status().gFLT == 0x09           # silence: raised without any request
    model.touch(t + 1.02)                         # traffic resumes: this answer still says so
    assert model.status().gFLT == 0x09
    model.after_request()
    assert model.status().gFLT == 0               # cleared by the traffic


def test_no_communication_clears_after_the_configured_answers() -> None:
    model = activated_model(comm_fault_answers=3)
    t = model.activation_time + 1.5
    seen = []
    for k in range(4):
        model.touch(t + 0.01 * k)
        seen.append(model.status().gFLT)
        model.after_request()
    assert seen == [0x09, 0x09, 0x09, 0]
