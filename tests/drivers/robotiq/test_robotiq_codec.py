"""Codec: CRC, frames byte for byte, register packing, command/status bits, SI, faults."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from mmexec.drivers.robotiq import codec
from mmexec.drivers.robotiq.codec import Command, Status
from mmexec.drivers.robotiq.errors import (
    FAULTS,
    ActivationFault,
    FrameError,
    Overcurrent,
    RobotiqFault,
    fault_error,
)


def h(s: str) -> bytes:
    return bytes.fromhex(s)


def test_crc_check_value() -> None:
    assert codec.crc16_modbus(b"123456789") == 0x4B37


def test_doc_example_read_frame() -> None:
    # docs/protocols.md 3.1: FC03, slave 1, 3 registers at 0x07D0
    assert codec.encode_read(1, 3, 0x07D0, 3) == h("01 03 07 D0 00 03 05 46")
    assert codec.check_crc(h("01 03 07 D0 00 03 05 46"))
    assert not codec.check_crc(h("01 03 07 D0 00 03 05 47"))


# Hand-built frames for slave 9 (CRC low byte first), per docs/protocols.md 3.2/3.3.
RESET = "09 10 03 E8 00 03 06 00 00 00 00 00 00 73 30"
ACTIVATE = "09 10 03 E8 00 03 06 01 00 00 00 00 00 72 E1"
CLOSE_FULL = "09 10 03 E8 00 03 06 09 00 00 FF FF FF 42 29"
READ_STATUS_FC03 = "09 03 07 D0 00 03 04 0E"
READ_STATUS_FC04 = "09 04 07 D0 00 03 B1 CE"


def test_activation_and_move_writes() -> None:
    assert codec.encode_write_multiple(9, 0x03E8, Command().to_registers()) == h(RESET)
    assert codec.encode_write_multiple(9, 0x03E8, Command(rACT=True).to_registers()) == h(ACTIVATE)
    move = Command(rACT=True, rGTO=True, rPR=0xFF, rSP=0xFF, rFR=0xFF)
    assert move.action_request == 0x09
    assert codec.encode_write_multiple(9, 0x03E8, move.to_registers()) == h(CLOSE_FULL)


def test_status_reads() -> None:
    assert codec.encode_read(9, 3, 0x07D0, 3) == h(READ_STATUS_FC03)
    assert codec.encode_read(9, 4, 0x07D0, 3) == h(READ_STATUS_FC04)


def test_status_reply_decode() -> None:
    # activated, at requested position (0xF9), no fault, gPR 0xFF, gPO 0xBD, gCU 0x00
    reply = codec.encode_read_reply(9, 4, (0xF900, 0x00FF, 0xBD00))
    assert reply[:9] == h("09 04 06 F9 00 00 FF BD 00")
    regs = codec.decode_read_reply(reply, 9, 4, 3)
    s = Status.from_registers(regs)
    assert (s.gACT, s.gGTO, s.gSTA, s.gOBJ) == (True, True, 3, 3)
    assert (s.gFLT, s.kFLT, s.gPR, s.gPO, s.gCU) == (0, 0, 0xFF, 0xBD, 0)
    assert s.to_registers() == (0xF900, 0x00FF, 0xBD00)


@pytest.mark.parametrize(
    ("byte", "sta", "obj", "gto"),
    [(0x11, 1, 0, False), (0x31, 3, 0, False), (0x39, 3, 0, True), (0xB9, 3, 2, True),
     (0xF9, 3, 3, True), (0x79, 3, 1, True)],
)
def test_status_byte_bits(byte: int, sta: int, obj: int, gto: bool) -> None:
    s = Status.from_bytes(bytes((byte, 0, 0, 0, 0, 0)))
    assert (s.gSTA, s.gOBJ, s.gGTO, s.gACT) == (sta, obj, gto, True)
    assert s.status_byte == byte


def test_fault_nibbles() -> None:
    s = Status.from_bytes(h("31 00 3E 00 00 00"))
    assert (s.gFLT, s.kFLT) == (0x0E, 0x3)


def test_register_packing_high_byte_first() -> None:
    assert codec.registers_to_bytes((0x0900, 0x00FF)) == h("09 00 00 FF")
    assert codec.bytes_to_registers(h("09 00 00 FF 80 40")) == (0x0900, 0x00FF, 0x8040)
    cmd = Command(rACT=True, rGTO=True, rPR=0x80, rSP=0x40, rFR=0x20)
    assert cmd.to_registers() == (0x0900, 0x0080, 0x4020)
    assert Command.from_bytes(cmd.to_bytes()) == cmd


def test_action_request_bits() -> None:
    assert Command(rACT=True, rATR=True).action_request == 0x11
    assert Command(rACT=True, rATR=True, rARD=True).action_request == 0x31
    with pytest.raises(ValueError, match="rPR=256"):
        Command(rPR=256)


def test_fc06_fc23_and_replies() -> None:
    assert codec.encode_write_single(9, 0x03E8, 0x0100) == codec.append_crc(h("09 06 03 E8 01 00"))
    frame = codec.encode_read_write(9, 0x07D0, 3, 0x03E8, (0x0900, 0x00FF, 0xFFFF))
    assert frame[:-2] == h("09 17 07 D0 00 03 03 E8 00 03 06 09 00 00 FF FF FF")
    req = codec.decode_request(frame)
    assert (req.function, req.read_address, req.read_count) == (0x17, 0x07D0, 3)
    assert req.write_values == (0x0900, 0x00FF, 0xFFFF)
    ack = codec.encode_write_multiple_reply(9, 0x03E8, 3)
    assert ack[:-2] == h("09 10 03 E8 00 03")
    codec.decode_write_multiple_reply(ack, 9, 0x03E8, 3)
    echo = codec.encode_write_single(9, 0x03E8, 0x0100)
    codec.decode_write_single_reply(echo, 9, 0x03E8, 0x0100)


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda f: f[:-1] + bytes((f[-1] ^ 1,)), "bad CRC"),
        (lambda f: codec.append_crc(b"\x08" + f[1:-2]), "slave 8"),
        (lambda f: codec.append_crc(f[:1] + b"\x03" + f[2:-2]), "function 0x03"),
        (lambda f: f[:-3], "expected 11"),
        (lambda f: codec.append_crc(f[:1] + b"\x84\x02"), "expected 11"),
    ],
)
def test_reply_validation(mutate, message: str) -> None:  # type: ignore[no-untyped-def]
    good = codec.encode_read_reply(9, 4, (0x3100, 0, 0))
    with pytest.raises(FrameError, match=message):
        codec.decode_read_reply(mutate(good), 9, 4, 3)


def test_exception_reply_named() -> None:
    frame = codec.append_crc(h("09 84 02 00 00 00 00 00 00"))
    with pytest.raises(FrameError, match="exception reply, code 0x02"):
        codec.decode_read_reply(frame, 9, 4, 3)


def test_request_length_and_unknown_function() -> None:
    assert codec.request_length(h("09")) is None
    assert codec.request_length(h("09 03")) == 8
    assert codec.request_length(h(CLOSE_FULL)) == 15
    with pytest.raises(FrameError, match="unsupported function 0x2B"):
        codec.request_length(h("09 2B"))


def test_si_conversions() -> None:
    assert codec.width_to_position(0.085) == 0
    assert codec.width_to_position(0.0) == 255
    assert codec.width_to_position(0.2) == 0          # clamped to the stroke
    assert codec.position_to_width(255) == 0.0
    assert codec.position_to_width(0) == pytest.approx(0.085)
    assert codec.speed_to_raw(0.02) == 0 and codec.speed_to_raw(0.15) == 255
    assert codec.speed_to_raw(1.0) == 255
    assert codec.raw_to_speed(255) == pytest.approx(0.15)
    assert codec.force_to_raw(20) == 0 and codec.force_to_raw(235) == 255
    assert codec.force_to_raw(1000) == 255
    assert codec.raw_to_force(0) == pytest.approx(20.0)
    with pytest.raises(ValueError, match="finite"):
        codec.width_to_position(float("nan"))


@given(st.integers(0, 255))
def test_position_round_trip(p: int) -> None:
    assert codec.width_to_position(codec.position_to_width(p)) == p


@given(st.binary(min_size=2, max_size=40))
def test_crc_appended_always_checks(body: bytes) -> None:
    framed = codec.append_crc(body)
    assert codec.check_crc(framed)
    assert not codec.check_crc(framed[:-1] + bytes((framed[-1] ^ 0x10,)))


def test_fault_table_and_named_errors() -> None:
    assert sorted(FAULTS) == [0x05, 0x07, 0x08, 0x09, 0x0A, 0x0B, 0x0C, 0x0D, 0x0E, 0x0F]
    classes = {c: info.fault_class for c, (info, _) in FAULTS.items()}
    assert classes[0x05] == classes[0x07] == "priority"
    assert classes[0x08] == classes[0x09] == "minor"
    assert all(classes[c] == "major" for c in range(0x0A, 0x10))
    e = fault_error(0x0E, "robotiq /dev/ttyUSB0")
    assert isinstance(e, Overcurrent) and e.code == 0x0E and e.fault_class == "major"
    assert str(e).startswith("robotiq /dev/ttyUSB0: gripper fault 0x0E overcurrent (major)")
    assert "rising edge on rACT" in str(e)
    assert isinstance(fault_error(0x0D), ActivationFault)
    unknown = fault_error(0x03)
    assert type(unknown) is RobotiqFault and "0x03" in str(unknown)
