"""Protocol 2.0 codec: CRC, vendor example frames byte for byte, hand-built frames, stuffing, parser."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from mmexec.drivers.dynamixel import codec
from mmexec.drivers.dynamixel.codec import BadFrame, Packet, StatusResult


def h(text: str) -> bytes:
    return bytes.fromhex(text)


def frame(head_id: int, body: bytes) -> bytes:
    """Build a frame by hand from the spec: header, id, LEN = len(body) + 2, body, CRC LE."""
    length = len(body) + 2
    f = h("FFFFFD00") + bytes((head_id, length & 0xFF, length >> 8)) + body
    crc = codec.crc16(f)
    return f + bytes((crc & 0xFF, crc >> 8))


def test_crc_check_value() -> None:
    assert codec.crc16(b"123456789") == 0xFEE8
    assert codec.crc16(b"") == 0


def test_ping_worked_example_from_doc() -> None:
    assert codec.ping(7) == h("FF FF FD 00 07 03 00 01 19 36")


def test_read_and_write_examples() -> None:
    # e-Manual: read 4 bytes of Present Position (132) from id 1; write 512 to Goal Position
    assert codec.read(1, 132, 4) == h("FF FF FD 00 01 07 00 02 84 00 04 00 1D 15")
    assert codec.write(1, 116, (512).to_bytes(4, "little")) == h(
        "FF FF FD 00 01 09 00 03 74 00 00 02 00 00 CA 89"
    )


def test_sync_write_two_servos_by_hand() -> None:
    # addr 116, len 4; id 1 -> 150, id 2 -> 170; LEN = 1 + 4 + 2*5 + 2 = 0x11
    expected = h("FF FF FD 00 FE 11 00 83 74 00 04 00 01 96 00 00 00 02 AA 00 00 00 82 87")
    got = codec.sync_write(116, 4, {1: (150).to_bytes(4, "little"), 2: (170).to_bytes(4, "little")})
    assert got == expected
    assert got == frame(0xFE, h("83 74 00 04 00 01 96 00 00 00 02 AA 00 00 00"))


def test_sync_read_and_its_status_replies() -> None:
    assert codec.sync_read(132, 4, [1, 2]) == h("FF FF FD 00 FE 09 00 82 84 00 04 00 01 02 CE FA")
    r1 = h("FF FF FD 00 01 08 00 55 00 A6 00 00 00 8C C0")
    r2 = h("FF FF FD 00 02 08 00 55 00 1F 08 00 00 BA BE")
    assert codec.encode_status(1, 0, (166).to_bytes(4, "little")) == r1
    s1, s2 = codec.decode_status(r1), codec.decode_status(r2)
    assert (s1.id, s1.error, codec.int_from_le(s1.data)) == (1, 0, 166)
    assert (s2.id, codec.int_from_le(s2.data)) == (2, 2079)


def test_other_instructions_by_hand() -> None:
    assert codec.reg_write(3, 116, b"\x00\x08\x00\x00") == frame(3, h("04 74 00 00 08 00 00"))
    assert codec.action(0xFE) == frame(0xFE, h("05"))
    assert codec.reboot(2) == frame(2, h("08"))
    assert codec.factory_reset(1, 0x01) == frame(1, h("06 01"))
    assert codec.clear_multi_turn(1) == frame(1, h("10 01 44 58 4C 22"))
    assert codec.bulk_read([(1, 132, 4), (2, 126, 2)]) == frame(
        0xFE, h("92 01 84 00 04 00 02 7E 00 02 00")
    )
    assert codec.bulk_write([(1, 64, b"\x01"), (2, 116, b"\x00\x08\x00\x00")]) == frame(
        0xFE, h("93 01 40 00 01 00 01 02 74 00 04 00 00 08 00 00")
    )


def test_stuffed_packet() -> None:
    # writing FF FF FD xx to Goal Position puts FF FF FD in the body: one FD is inserted,
    # LEN counts it and the CRC covers the stuffed bytes
    pkt = codec.write(1, 116, h("FF FF FD 01"))
    body = h("03 74 00 FF FF FD FD 01")
    assert pkt == frame(1, body)
    assert pkt[5] == len(body) + 2
    parsed = codec.PacketParser().feed(pkt)
    assert parsed == [Packet(1, 0x03, h("74 00 FF FF FD 01"))]
    st_frame = codec.encode_status(1, 0, h("FF FF FD 00"))
    assert h("FF FF FD FD 00") in st_frame
    assert codec.decode_status(st_frame).data == h("FF FF FD 00")


def test_parser_drops_garbage_and_resyncs_after_bad_crc() -> None:
    good1 = codec.encode_status(1, 0, b"\x01\x02")
    good2 = codec.encode_status(2, 0x80 | 6, b"")
    bad = bytearray(codec.encode_status(3, 0, b"\x05"))
    bad[-1] ^= 0xFF
    stream = b"\x00\xff\x13\xff\xff" + good1 + bytes(bad) + b"\xfd\x00garbage" + good2
    p = codec.PacketParser()
    out = []
    for b in stream:  # one byte at a time: framing must not depend on chunking
        out += p.feed(bytes((b,)))
    assert [type(x) for x in out] == [Packet, BadFrame, Packet]
    assert out[0] == Packet(1, 0x55, b"\x00\x01\x02")
    assert isinstance(out[1], BadFrame) and out[1].id == 3
    st2 = codec.status_from_packet(out[2])  # type: ignore[arg-type]
    assert st2.alert and st2.result is StatusResult.DATA_LIMIT_ERROR
    assert p.pending == 0 and p.dropped > 0


def test_parser_reports_truncation_as_pending() -> None:
    p = codec.PacketParser()
    full = codec.encode_status(4, 0, b"\x00" * 12)
    assert p.feed(full[:9]) == []
    assert p.pending == 9
    assert p.feed(full[9:]) and p.pending == 0


def test_impossible_length_is_skipped() -> None:
    p = codec.PacketParser()
    junk = h("FF FF FD 00 01 FF FF")  # LEN 65535
    good = codec.encode_status(1, 0)
    assert p.feed(junk + good) == [Packet(1, 0x55, b"\x00")]


def test_parse_instruction_params_round_trip() -> None:
    per = {1: b"\x01\x02", 4: b"\x03\x04"}
    pk = codec.PacketParser().feed(codec.sync_write(100, 2, per))[0]
    assert isinstance(pk, Packet) and codec.parse_sync_write(pk.params) == (100, 2, per)
    pk = codec.PacketParser().feed(codec.sync_read(126, 12, [1, 2, 4]))[0]
    assert isinstance(pk, Packet) and codec.parse_sync_read(pk.params) == (126, 12, [1, 2, 4])


def test_bad_arguments_are_rejected() -> None:
    import pytest

    with pytest.raises(codec.CodecError, match="servo id 253"):
        codec.ping(253)
    with pytest.raises(codec.CodecError, match="expected 4"):
        codec.sync_write(116, 4, {1: b"\x00"})
    with pytest.raises(codec.CodecError):
        codec.int_to_le(70000, 2)
    assert codec.int_to_le(-1, 4) == b"\xff\xff\xff\xff"
    assert codec.int_from_le(b"\xff\xff", signed=True) == -1


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=64), st.integers(0, 252))
def test_stuffing_round_trip(params: bytes, dxl_id: int) -> None:
    pkt = codec.encode_instruction(dxl_id, 0x03, params)
    assert codec.unstuff(codec.stuff(params)) == params
    assert codec.PacketParser().feed(b"\xff\xfd" + pkt) == [Packet(dxl_id, 0x03, params)]
