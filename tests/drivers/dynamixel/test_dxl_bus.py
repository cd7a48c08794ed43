"""DxlBus against the protocol-level fake: instructions, error codes, link failures, deadlines."""

from __future__ import annotations

import time

import pytest

from mmexec.drivers.dynamixel import codec
from mmexec.drivers.dynamixel.bus import (
    BusConfig,
    CorruptReply,
    DxlBus,
    NoReply,
    NotConnected,
    PortUnavailable,
    ServoError,
    TruncatedReply,
)
from mmexec.drivers.dynamixel.codec import StatusResult
from mmexec.drivers.fakes.dynamixel import FakeDxlBus

le = codec.int_to_le


def test_ping_read_write(bus: DxlBus, fake: FakeDxlBus) -> None:
    assert bus.ping(1).model == 1020 and bus.ping(9).model == 1060
    assert bus.read(2, 0, 2) == le(1020, 2)
    bus.write(1, 65, b"\x01")
    assert fake.servo(1).get("led") == 1
    found = bus.broadcast_ping(12)
    assert [p.id for p in found] == list(range(1, 10))


def test_deadline_from_link() -> None:
    b = DxlBus(BusConfig("/dev/null-port", baudrate=1_000_000, latency=0.001))
    # 10 bits per byte at 1 Mbps: 10 us per byte; (10 out + 23 back) bytes + 2 ms + 2 ms
    assert b.reply_timeout(10, 23) == pytest.approx(33e-5 + 0.004)


def test_missing_servo_names_id_and_port(bus: DxlBus, fake: FakeDxlBus) -> None:
    fake.servo(4).present = False
    # the deadline is the link's: (bytes out + 4 x 23 expected) x byte time + 2 x latency + 2 ms
    ms = bus.reply_timeout(len(codec.sync_read(126, 12, [1, 2, 4, 6])), 4 * 23) * 1e3
    with pytest.raises(NoReply, match=rf"{fake.port}: no reply from servo id 4 within {ms:.1f} ms") as ei:
        bus.sync_read(126, 12, [1, 2, 4, 6])
    assert ei.value.id == 4 and set(ei.value.received) == {1, 2, 6}  # type: ignore[attr-defined]


def test_corrupt_and_truncated_replies(bus: DxlBus, fake: FakeDxlBus) -> None:
    fake.corrupt_replies = 1
    with pytest.raises(CorruptReply, match="CRC mismatch") as ei:
        bus.ping(2)
    assert not isinstance(ei.value, TruncatedReply)
    fake.truncate_replies = 1
    with pytest.raises(TruncatedReply, match="truncated reply from servo id 2"):
        bus.ping(2)
    assert bus.ping(2).id == 2  # the bus recovers at once


@pytest.mark.parametrize("answers", [True, False])
def test_corrupted_instruction_switch(bus: DxlBus, fake: FakeDxlBus, answers: bool) -> None:
    fake.crc_error_reply = answers
    fake.corrupt_instructions = 1
    if answers:
        with pytest.raises(ServoError, match="CRC error") as ei:
            bus.write(1, 65, b"\x01")
        assert ei.value.result is StatusResult.CRC_ERROR
    else:
        with pytest.raises(NoReply, match="no reply from servo id 1"):
            bus.write(1, 65, b"\x01")
    assert fake.servo(1).get("led") == 0  # the corrupted write was not executed
    bus.write(1, 65, b"\x01")
    assert fake.servo(1).get("led") == 1


def test_servo_error_codes(bus: DxlBus, fake: FakeDxlBus) -> None:
    bus.write(1, 64, b"\x01")  # torque on locks the EEPROM
    with pytest.raises(ServoError, match="servo id 1 .* access error") as ei:
        bus.write(1, 11, b"\x03")
    assert ei.value.result is StatusResult.ACCESS_ERROR
    with pytest.raises(ServoError) as ei:
        bus.write(1, 132, le(5, 4))  # read-only
    assert ei.value.result is StatusResult.ACCESS_ERROR
    with pytest.raises(ServoError) as ei:
        bus.write(1, 116, b"\x00\x08")  # 2 bytes of a 4-byte item
    assert ei.value.result is StatusResult.DATA_LENGTH_ERROR
    bus.write(2, 52, le(819, 4))
    bus.write(2, 64, b"\x01")
    with pytest.raises(ServoError) as ei:
        bus.write(2, 116, le(100, 4))  # below Min Position Limit
    assert ei.value.result is StatusResult.DATA_LIMIT_ERROR
    with pytest.raises(ServoError) as ei:
        bus.write(8, 11, b"\x00")  # XL430 has no current mode
    assert ei.value.result is StatusResult.DATA_RANGE_ERROR
    with pytest.raises(ServoError) as ei:
        bus.action(3)  # Action without Reg Write
    assert ei.value.result is StatusResult.INSTRUCTION_ERROR


def test_reg_write_action_and_bulk(bus: DxlBus, fake: FakeDxlBus) -> None:
    bus.reg_write(6, 65, b"\x01")
    assert fake.servo(6).get("led") == 0 and fake.servo(6).get("registered_instruction") == 1
    bus.action(6)
    assert fake.servo(6).get("led") == 1
    bus.bulk_write([(1, 65, b"\x01"), (8, 104, le(-5, 4))])
    bus.ping(1)  # no status for a bulk write: a round trip orders the check after it
    assert fake.servo(1).get("led") == 1 and fake.servo(8).get("goal_velocity") == -5
    got = bus.bulk_read([(8, 0, 2), (1, 65, 1)])
    assert got[8].data == le(1060, 2) and got[1].data == b"\x01"


def test_sync_read_order_and_status_return_level(bus: DxlBus, fake: FakeDxlBus) -> None:
    got = bus.sync_read(132, 4, [9, 1, 4])
    assert list(got) == [9, 1, 4]
    bus.write(4, 68, b"\x01", expect_reply=False)  # answer reads only (this write is not answered)
    bus.write(4, 65, b"\x01", expect_reply=False)
    assert bus.read(4, 65, 1) == b"\x01"
    bus.write(4, 68, b"\x00", expect_reply=False)  # ping only
    with pytest.raises(NoReply):
        bus.read(4, 65, 1)
    assert bus.ping(4).id == 4


def test_shadow_follows_master_silently(bus: DxlBus, fake: FakeDxlBus) -> None:
    bus.write(3, 12, b"\x02")  # secondary id of servo 3 = 2
    bus.write(2, 65, b"\x01")  # one status (from 2) expected; 3 executes silently
    assert fake.servo(3).get("led") == 1
    bus.sync_write(116, 4, {2: le(2100, 4)})
    bus.ping(2)
    assert fake.servo(3).get("goal_position") == 2100


def test_hardware_error_alert_and_reboot(bus: DxlBus, fake: FakeDxlBus) -> None:
    bus.write(2, 64, b"\x01")
    fake.inject_hardware_error(2, "overload")
    st = bus.read_status(2, 64, 1)
    assert st.alert and st.data == b"\x00"  # torque dropped
    assert bus.hardware_error(2) == ("overload",)
    bus.reboot(2)
    assert not bus.read_status(2, 64, 1).alert and bus.hardware_error(2) == ()


def test_bus_watchdog(bus: DxlBus, fake: FakeDxlBus) -> None:
    bus.write(1, 64, b"\x01")
    bus.write(1, 98, b"\x01")  # 20 ms
    fake.expire_watchdog(1)
    assert codec.int_from_le(bus.read(1, 98, 1), signed=True) == -1
    with pytest.raises(ServoError) as ei:
        bus.write(1, 116, le(2048, 4))
    assert ei.value.result is StatusResult.DATA_RANGE_ERROR
    bus.write(1, 98, b"\x00")
    bus.write(1, 64, b"\x01")
    bus.write(1, 116, le(2048, 4))


def test_factory_reset_and_clear(bus: DxlBus, fake: FakeDxlBus) -> None:
    bus.write(7, 9, b"\x00")
    bus.factory_reset(7, 0x02)
    assert fake.servo(7).get("return_delay_time") == 250 and fake.servo(7).id == 7
    bus.clear_multi_turn(7)


def test_open_errors_and_closed_bus() -> None:
    b = DxlBus(BusConfig("/dev/no-such-dxl"))
    with pytest.raises(PortUnavailable, match="/dev/no-such-dxl: no such port"):
        b.open()
    with pytest.raises(NotConnected, match="call open"):
        b.ping(1)


def test_garbage_before_reply_is_dropped(bus: DxlBus, fake: FakeDxlBus) -> None:
    # stale bytes waiting in the input buffer are discarded before transmitting
    fake.inject(b"\xff\xff\xfd\x00\x01\x07junk")
    time.sleep(0.02)
    assert bus.ping(1).id == 1
    assert bus.stats.dropped_bytes > 0
