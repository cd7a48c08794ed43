"""RPLIDAR codec against frames written by hand from the protocol document
(docs/protocols.md section 5), byte by byte."""

from __future__ import annotations

import math

import pytest

from mmexec.drivers.rplidar import codec as c

# --------------------------------------------------------------------------- requests


@pytest.mark.parametrize("cmd, frame", [
    (c.Command.STOP, bytes([0xA5, 0x25])),            # A5 = sync, 25 = STOP, no payload
    (c.Command.RESET, bytes([0xA5, 0x40])),
    (c.Command.SCAN, bytes([0xA5, 0x20])),
    (c.Command.FORCE_SCAN, bytes([0xA5, 0x21])),
    (c.Command.GET_INFO, bytes([0xA5, 0x50])),
    (c.Command.GET_HEALTH, bytes([0xA5, 0x52])),
    (c.Command.GET_SAMPLERATE, bytes([0xA5, 0x59])),
])
def test_requests_without_payload_are_sync_and_command(cmd: c.Command, frame: bytes) -> None:
    assert c.encode_request(cmd) == frame


def test_set_motor_pwm_is_the_documents_example() -> None:
    # A5 sync, F0 SET_MOTOR_PWM, 02 payload size, 94 02 = 660 LE, C1 = A5^F0^02^94^02
    assert c.set_motor_pwm(660) == bytes([0xA5, 0xF0, 0x02, 0x94, 0x02, 0xC1])
    # PWM 0 stops the motor: A5^F0^02^00^00 = 57
    assert c.set_motor_pwm(0) == bytes([0xA5, 0xF0, 0x02, 0x00, 0x00, 0x57])
    with pytest.raises(c.CodecError):
        c.set_motor_pwm(1024)


def test_get_acc_board_flag_carries_four_zero_bytes() -> None:
    # A5, FF, size 04, 00 00 00 00, checksum A5^FF^04 = 5E
    assert c.get_acc_board_flag() == bytes([0xA5, 0xFF, 0x04, 0x00, 0x00, 0x00, 0x00, 0x5E])


def test_payload_only_with_bit_7() -> None:
    with pytest.raises(c.CodecError):
        c.encode_request(c.Command.SCAN, b"\x01")  # 0x20: bit 7 clear, no payload allowed
    # bit 7 set, empty payload: size 00 and the checksum A5^82^00 = 27
    assert c.encode_request(0x82) == bytes([0xA5, 0x82, 0x00, 0x27])


def test_request_parser_finds_requests_after_noise_and_drops_bad_checksums() -> None:
    p = c.RequestParser()
    stream = (bytes([0x00, 0x13])                              # noise before the first sync
              + bytes([0xA5, 0x50])                            # GET_INFO
              + bytes([0xA5, 0xF0, 0x02, 0x94, 0x02, 0xC2])    # PWM 660 with a wrong checksum
              + bytes([0xA5, 0xF0, 0x02, 0x94, 0x02, 0xC1]))   # PWM 660
    got = p.feed(stream[:5]) + p.feed(stream[5:])              # split inside a request
    assert got == [c.Request(0x50), c.Request(0xF0, bytes([0x94, 0x02]))]
    assert p.bad_checksum == 1 and p.discarded >= 2


# --------------------------------------------------------------------------- responses


@pytest.mark.parametrize("cmd, frame, length, mode, dtype", [
    # A5 5A | 05 00 00 40 = 0x40000005: length 5, mode 1 (bits 30-31) | type 81
    (c.Command.SCAN, bytes([0xA5, 0x5A, 0x05, 0x00, 0x00, 0x40, 0x81]), 5, c.SendMode.MULTIPLE, 0x81),
    # A5 5A | 14 00 00 00: 20 bytes, single | type 04
    (c.Command.GET_INFO, bytes([0xA5, 0x5A, 0x14, 0x00, 0x00, 0x00, 0x04]), 20, c.SendMode.SINGLE, 0x04),
    (c.Command.GET_HEALTH, bytes([0xA5, 0x5A, 0x03, 0x00, 0x00, 0x00, 0x06]), 3, c.SendMode.SINGLE, 0x06),
    (c.Command.GET_SAMPLERATE, bytes([0xA5, 0x5A, 0x04, 0x00, 0x00, 0x00, 0x15]), 4, c.SendMode.SINGLE, 0x15),
    (c.Command.GET_ACC_BOARD_FLAG, bytes([0xA5, 0x5A, 0x04, 0x00, 0x00, 0x00, 0xFF]), 4, c.SendMode.SINGLE, 0xFF),
])
def test_descriptors_of_the_document(cmd: c.Command, frame: bytes, length: int, mode: c.SendMode,
                                     dtype: int) -> None:
    d = c.decode_descriptor(frame)
    assert (d.length, d.mode, d.data_type) == (length, mode, dtype)
    assert c.response_descriptor(cmd) == d
    assert c.encode_descriptor(length, mode, dtype) == frame


def test_descriptor_rejects_wrong_sync_and_size() -> None:
    with pytest.raises(c.CodecError):
        c.decode_descriptor(bytes([0xA5, 0x5B, 0x03, 0x00, 0x00, 0x00, 0x06]))
    with pytest.raises(c.CodecError):
        c.decode_descriptor(bytes([0xA5, 0x5A, 0x03, 0x00, 0x00, 0x00]))


def test_find_response_skips_leading_bytes_and_waits_for_the_data() -> None:
    health = bytes([0xA5, 0x5A, 0x03, 0x00, 0x00, 0x00, 0x06])
    buf = bytes([0x3E, 0x81, 0xA5]) + health + bytes([0x01, 0x34])   # stale node bytes, data incomplete
    expected = c.response_descriptor(c.Command.GET_HEALTH)
    assert c.find_response(buf, expected) is None
    buf += bytes([0x12, 0x99])                                         # last data byte, then more
    end, data = c.find_response(buf, expected)  # type: ignore[misc]
    assert data == bytes([0x01, 0x34, 0x12]) and buf[end:] == bytes([0x99])
    # a stream descriptor has no data: the nodes follow
    scan = bytes([0xA5, 0x5A, 0x05, 0x00, 0x00, 0x40, 0x81, 0x3E])
    assert c.find_response(scan, c.response_descriptor(c.Command.SCAN)) == (7, b"")


def test_get_info_data() -> None:
    data = bytes([0x28,              # model: series 2 (high nibble), sub-model 8: A2M8
                  0x1D,              # firmware minor 29
                  0x01,              # firmware major 1
                  0x07])             # hardware 7
    data += bytes(range(0x10, 0x20))  # serial number, 16 bytes
    info = c.decode_info(data)
    assert (info.model, info.firmware_major, info.firmware_minor, info.hardware) == (0x28, 1, 29, 7)
    assert info.model_name == "A2M8" and info.firmware == "1.29"
    assert info.serial_text == "101112131415161718191A1B1C1D1E1F"
    assert c.encode_info(info) == data
    with pytest.raises(c.CodecError):
        c.decode_info(data[:19])


@pytest.mark.parametrize("data, status, code", [
    (bytes([0x00, 0x00, 0x00]), c.HealthStatus.GOOD, 0),
    (bytes([0x01, 0x12, 0x00]), c.HealthStatus.WARNING, 0x0012),   # code 0x0012 LE
    (bytes([0x02, 0x34, 0x12]), c.HealthStatus.ERROR, 0x1234),     # code 0x1234 LE
])
def test_get_health_data(data: bytes, status: c.HealthStatus, code: int) -> None:
    h = c.decode_health(data)
    assert (h.status, h.error_code) == (status, code)
    assert c.encode_health(h) == data


def test_get_health_unknown_status_is_an_error() -> None:
    with pytest.raises(c.CodecError):
        c.decode_health(bytes([0x03, 0x00, 0x00]))


def test_get_samplerate_and_acc_board_flag_data() -> None:
    # Tstandard 500 us = F4 01, Texpress 250 us = FA 00
    rate = c.decode_sample_rate(bytes([0xF4, 0x01, 0xFA, 0x00]))
    assert (rate.standard_us, rate.express_us) == (500, 250)
    assert rate.standard_hz == pytest.approx(2000.0)
    # uint32 LE 1: bit 0, motor control supported
    assert c.decode_acc_board_flag(bytes([0x01, 0x00, 0x00, 0x00])) & c.ACC_BOARD_MOTOR_CONTROL


# --------------------------------------------------------------------------- nodes


def test_the_documents_node_example() -> None:
    # 3E = 0b00111110: S (bit 0) 0, not-S (bit 1) 1, quality (bits 2-7) 15
    # 81 = 0b10000001: C (bit 0) 1, angle_q6 bits 0-6 = 0x40; 5A: angle_q6 bits 7-14
    # angle_q6 = 0x40 | 0x5A << 7 = 0x2D40 = 11584 -> 181.0 deg; 20 4E: 0x4E20 = 20000 -> 5000 mm
    node = c.decode_node(bytes([0x3E, 0x81, 0x5A, 0x20, 0x4E]))
    assert node == c.MeasurementNode(start=False, quality=15, angle_q6=11584, distance_q2=20000)
    assert node.angle_deg == pytest.approx(181.0) and node.distance_m == pytest.approx(5.0)
    assert c.encode_node(node) == bytes([0x3E, 0x81, 0x5A, 0x20, 0x4E])


def test_start_node_and_no_return() -> None:
    # FD = 0b11111101: S 1, not-S 0, quality 63; 01 00: C 1, angle 0; 00 00: no valid return
    node = c.decode_node(bytes([0xFD, 0x01, 0x00, 0x00, 0x00]))
    assert node.start and node.quality == 63 and node.angle_q6 == 0
    assert node.distance_m == math.inf


@pytest.mark.parametrize("frame", [
    bytes([0x3F, 0x81, 0x5A, 0x20, 0x4E]),  # S 1 and not-S 1
    bytes([0x3C, 0x81, 0x5A, 0x20, 0x4E]),  # S 0 and not-S 0
    bytes([0x3E, 0x80, 0x5A, 0x20, 0x4E]),  # C 0
])
def test_corrupt_nodes_are_refused(frame: bytes) -> None:
    assert not c.node_is_valid(frame)
    with pytest.raises(c.CodecError):
        c.decode_node(frame)


@pytest.mark.parametrize("angle_q6, ccw", [
    (0, 0.0),
    (90 * 64, -math.pi / 2),         # 90 deg clockwise = to the right = -pi/2 CCW
    (270 * 64, math.pi / 2),         # 270 deg clockwise = to the left
    (180 * 64, -math.pi),            # the back, at the start of [-pi, pi)
])
def test_clockwise_device_angles_become_ccw(angle_q6: int, ccw: float) -> None:
    assert c.ccw_angle(angle_q6) == pytest.approx(ccw)


def test_node_parser_resynchronises_byte_by_byte() -> None:
    good = bytes([0x3E, 0x81, 0x5A, 0x20, 0x4E])
    start = bytes([0xFD, 0x01, 0x00, 0x00, 0x00])
    truncated = good[:3]
    bad_c = bytes([0x3E, 0x80, 0x5A, 0x20, 0x4E])
    p = c.NodeParser()
    out = p.feed(start + truncated + good[:2])     # a node cut short, then half a node
    out += p.feed(good[2:] + bad_c + good)
    nodes = [n for _skip, n in out]
    assert nodes[0].start and nodes[-1] == c.decode_node(good)
    assert p.dropped > 0 and p.pending < c.NODE_SIZE
    # what was skipped is reported on the next valid node
    assert sum(skip for skip, _n in out) == p.dropped
