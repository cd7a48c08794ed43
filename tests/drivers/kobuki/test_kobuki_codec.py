"""Kobuki codec: the doc's worked frame byte for byte, resynchronisation, decoders, odometry."""

from __future__ import annotations

import math

import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from mmexec.drivers.kobuki import codec as k

EXAMPLE = bytes.fromhex("AA 55 06 01 04 C8 00 00 00 CB")


def test_worked_example_frame_byte_for_byte() -> None:
    speed, radius = k.velocity_to_speed_radius(0.2, 0.0)
    assert (speed, radius) == (200, 0)
    assert k.encode_frame(k.base_control(speed, radius)) == EXAMPLE
    p = k.FrameParser()
    [payload] = p.feed(EXAMPLE)
    assert payload == bytes.fromhex("01 04 C8 00 00 00")
    assert k.decode_commands(payload) == [k.Command("base_control", (200, 0))]
    # receiver check: XOR of everything after the header is 0
    x = 0
    for b in EXAMPLE[2:]:
        x ^= b
    assert x == 0


def test_resync_after_stray_bytes_and_split_delivery() -> None:
    p = k.FrameParser()
    stream = b"\x00\xaa\x13\xaa" + EXAMPLE + b"\x55\xaa" + EXAMPLE
    got: list[bytes] = []
    for i in range(len(stream)):  # one byte at a time
        got += p.feed(stream[i : i + 1])
    assert len(got) == 2 and p.frames == 2
    assert p.discarded >= 4


def test_bad_checksum_rejected_and_next_frame_found() -> None:
    bad = EXAMPLE[:-1] + bytes((EXAMPLE[-1] ^ 0x01,))
    p = k.FrameParser()
    assert p.feed(bad) == []
    assert p.bad_checksum == 1
    assert p.feed(EXAMPLE) == [EXAMPLE[3:-1]]


def test_truncated_frame_then_valid_frame() -> None:
    p = k.FrameParser()
    out = p.feed(EXAMPLE[:6] + EXAMPLE)
    assert out == [EXAMPLE[3:-1]]


def test_impossible_length_is_skipped() -> None:
    p = k.FrameParser()
    out = p.feed(b"\xaa\x55\x01\x00" + EXAMPLE)
    assert out == [EXAMPLE[3:-1]] and p.bad_length == 1


@given(st.binary(max_size=300))
def test_parser_never_loses_a_frame_after_garbage(garbage: bytes) -> None:
    p = k.FrameParser()
    out = p.feed(garbage + EXAMPLE * 30)
    # a false header in the garbage may claim up to 255 bytes and swallow the frames
    # inside them (at most 26 of 10 bytes); rejection drops one byte at a time, so
    # every frame after that is recovered
    assert len(out) >= 30 - 26 and out[-1] == EXAMPLE[3:-1]
    assert p.pending == 0


def _core(**kw: object) -> k.CoreSensors:
    base = {
        "timestamp_ms": 1234, "bumper": 0, "wheel_drop": 0, "cliff": 0, "left_encoder": 100, "right_encoder": 65535,
        "left_pwm": -3, "right_pwm": 7, "buttons": 0x02, "charger": 0x16, "battery": 16.5, "overcurrent": 0,
    }
    base.update(kw)
    return k.CoreSensors(**base)  # type: ignore[arg-type]


def test_core_sensor_layout_by_offset() -> None:
    sp = k.encode_core_sensors(_core())
    assert sp[:2] == b"\x01\x0f"
    d = sp[2:]
    assert d[0:2] == (1234).to_bytes(2, "little")
    assert d[5:7] == (100).to_bytes(2, "little") and d[7:9] == b"\xff\xff"
    assert d[9] == 0xFD and d[10] == 7 and d[11] == 0x02 and d[12] == 0x16 and d[13] == 165


def test_feedback_round_trip_every_subpayload_and_unknown_id_skipped() -> None:
    frame = k.encode_frame(
        k.encode_core_sensors(_core(bumper=0x05, cliff=0x02, wheel_drop=0x01, overcurrent=0x02)),
        k.encode_dock_ir(k.DockInfrared(1, 2, 4)),
        k.encode_inertia(math.radians(90.0), math.radians(-10.0)),
        k.encode_cliff(k.CliffSensors(4095, 2000, 0)),
        k.encode_current(0.12, 0.5),
        k.subpayload(0x30, b"\x01\x02\x03"),  # unknown id
        k.encode_gyro(7, [(0.1, -0.2, 0.3), (0.0, 0.0, -0.5)]),
        k.encode_gp_input(k.GpInput(0x05, (0.0, 1.65, 3.3, 0.5))),
        k.encode_version(k.HARDWARE, k.Version(1, 0, 4)),
        k.encode_version(k.FIRMWARE, k.Version(1, 2, 0)),
        k.encode_unique_id((0x01020304, 5, 0xFFFFFFFF)),
        k.encode_controller_info(k.ControllerInfo(False, 100.0, 0.1, 2.0)),
    )
    [payload] = k.FrameParser().feed(frame)
    fb = k.decode_feedback(payload)
    assert fb.unknown_ids == (0x30,)
    assert fb.core is not None and fb.core.battery == pytest.approx(16.5)
    assert fb.core.faults == {"bumper_right", "bumper_left", "cliff_centre", "wheel_drop_right", "overcurrent_right"}
    assert fb.core.charging_state == "charging" and fb.core.charge_source == "adapter"
    assert fb.dock_ir == k.DockInfrared(1, 2, 4)
    assert fb.inertia is not None and fb.inertia.heading == pytest.approx(math.pi / 2, abs=1e-4)
    assert fb.inertia.rate == pytest.approx(math.radians(-10.0), abs=1e-4)
    assert fb.cliff == k.CliffSensors(4095, 2000, 0) and fb.cliff.volts()[0] == pytest.approx(3.3)
    assert fb.current == k.WheelCurrent(pytest.approx(0.12), pytest.approx(0.5))  # type: ignore[arg-type]
    assert fb.gyro is not None and fb.gyro.frame_id == 7 and len(fb.gyro.samples) == 2
    assert fb.gyro.samples[0] == pytest.approx((0.1, -0.2, 0.3), abs=2e-4)
    assert fb.gp_input is not None and fb.gp_input.digital == 5
    assert fb.gp_input.analog == pytest.approx((0.0, 1.65, 3.3, 0.5), abs=1e-3)
    assert fb.hardware == k.Version(1, 0, 4) and fb.firmware == k.Version(1, 2, 0)
    assert str(fb.firmware) == "1.2.0"
    assert fb.unique_id == (0x01020304, 5, 0xFFFFFFFF)
    assert fb.controller == k.ControllerInfo(False, 100.0, 0.1, 2.0)


def test_version_packing_is_patch_minor_major() -> None:
    assert k.encode_version(k.FIRMWARE, k.Version(1, 2, 0)) == bytes.fromhex("0B 04 00 02 01 00")


def test_gyro_axes_rotation_from_raw() -> None:
    # raw x = 100 digits, raw y = 200, raw z = -300 -> robot x = -raw y, robot y = raw x
    raw = bytes.fromhex("0D 08 09 03") + (100).to_bytes(2, "little") + (200).to_bytes(2, "little") + (
        (-300) & 0xFFFF
    ).to_bytes(2, "little")
    fb = k.decode_feedback(raw)
    lsb = math.radians(0.00875)
    assert fb.gyro is not None
    assert fb.gyro.samples == (pytest.approx((-200 * lsb, 100 * lsb, -300 * lsb)),)


def test_malformed_subpayloads() -> None:
    with pytest.raises(k.CodecError, match="claims"):
        k.decode_feedback(b"\x01\x0f\x00\x00")
    with pytest.raises(k.CodecError, match="malformed sub-payload id 6"):
        k.decode_feedback(b"\x06\x03\x00\x00\x00")
    with pytest.raises(k.CodecError, match="malformed sub-payload id 13"):
        k.decode_feedback(b"\x0d\x04\x00\x03\x00\x00")


def test_command_encoders() -> None:
    assert k.sound(440.0, 100) == bytes((3, 3)) + round(1 / (440 * 2.75e-6)).to_bytes(2, "little") + b"\x64"
    assert k.sound_sequence(4) == b"\x04\x01\x04"
    assert k.request_extra(k.REQUEST_HARDWARE | k.REQUEST_FIRMWARE | k.REQUEST_UID) == b"\x09\x02\x0b\x00"
    assert k.gp_output(0x00F0 | 0x0100) == b"\x0c\x02\xf0\x01"
    g = k.set_controller_gain(True, 100.0, 0.1, 2.0)
    assert g[:2] == b"\x0d\x0d" and g[2] == 1 and g[3:7] == (100000).to_bytes(4, "little")
    assert k.get_controller_gain() == b"\x0e\x01\x00"
    frame = k.encode_frame(k.base_control(-100, 1), k.sound_sequence(0), k.request_extra(2), g, k.get_controller_gain())
    [payload] = k.FrameParser().feed(frame)
    cmds = k.decode_commands(payload)
    assert [c.kind for c in cmds] == ["base_control", "sound_sequence", "request_extra", "set_gain", "get_gain"]
    assert cmds[0].values == (-100, 1) and cmds[3].values == (True, 100.0, 0.1, 2.0)
    with pytest.raises(k.CodecError):
        k.sound_sequence(7)


@pytest.mark.parametrize(
    ("v", "w", "expected"),
    [
        (0.2, 0.0, (200, 0)),                         # rule 1: straight
        (-0.3, 0.00009, (-300, 0)),                   # rule 1: |w| below epsilon
        (0.0, 1.0, (115, 1)),                         # rule 2: pure rotation, CCW
        (0.0, -2.0, (-230, 1)),                       # rule 2: CW
        (0.0005, 1.0, (115, 1)),                      # rule 2: |radius| <= 1 mm
        (0.2, 0.5, (round((400 + 115) * 0.5), 400)),  # rule 3: left turn
        (0.2, -0.5, (round((-400 - 115) * -0.5), -400)),  # rule 3: right turn
        (-0.2, 0.5, (round((-400 - 115) * 0.5), -400)),   # reversing
        (40.0, 0.0, (32767, 0)),                      # int16 clamp
    ],
)
def test_velocity_to_speed_radius_rules(v: float, w: float, expected: tuple[int, int]) -> None:
    assert k.velocity_to_speed_radius(v, w) == expected


@given(st.floats(-0.7, 0.7), st.floats(-3.0, 3.0))
@example(v=0.001953125, w=1.875)  # radius 1.04 mm: rounded to the pure-rotation marker 1
@example(v=-0.0028, w=2.0)        # radius -1.4 mm: rounded to -1
def test_inverse_mapping_recovers_velocity(v: float, w: float) -> None:
    speed, radius = k.velocity_to_speed_radius(v, w)
    left, right = k.speed_radius_to_wheels(speed, radius)
    v2 = (left + right) / 2000.0
    w2 = (right - left) / (1000.0 * k.BIAS)
    if abs(w) < 1e-4:
        assert v2 == pytest.approx(v, abs=1e-3)
    elif abs(v) < 1e-4 or abs(1000 * v / w) <= 1.0:
        assert v2 == pytest.approx(0.0, abs=1e-9) and w2 == pytest.approx(w, abs=1e-2)
    elif abs(1000 * v / w) < 30000:
        assert v2 == pytest.approx(v, abs=5e-3) and w2 == pytest.approx(w, abs=2e-2)


def test_wrap_diff16() -> None:
    assert k.wrap_diff16(5, 65530) == 11
    assert k.wrap_diff16(65530, 5) == -11
    assert k.wrap_diff16(100, 40) == 60


def test_odometry_straight_across_encoder_and_timestamp_wrap() -> None:
    odo = k.Odometry()
    ticks_per_m = 1.0 / (k.TICK_TO_RAD * k.WHEEL_RADIUS)
    step = round(0.004 * ticks_per_m)  # ~4 mm per 20 ms frame = 0.2 m/s
    enc, ts = 65000, 65500
    odo.update(enc, enc, ts)
    for _ in range(50):
        enc = (enc + step) & 0xFFFF
        ts = (ts + 20) & 0xFFFF
        s = odo.update(enc, enc, ts)
        assert s.dt == pytest.approx(0.02)
    assert odo.x == pytest.approx(50 * step / ticks_per_m, rel=1e-9)
    assert odo.y == pytest.approx(0.0) and odo.theta == pytest.approx(0.0)
    assert s.v == pytest.approx(step / ticks_per_m / 0.02)


def test_odometry_rotation_and_backwards_wrap() -> None:
    odo = k.Odometry()
    odo.update(3, 65533, 0)
    # right wheel +n, left wheel -n: rotation in place CCW
    n = 100
    s = odo.update((3 - n) & 0xFFFF, (65533 + n) & 0xFFFF, 20)
    expected = 2 * n * k.TICK_TO_RAD * k.WHEEL_RADIUS / k.BIAS
    assert s.dtheta == pytest.approx(expected) and odo.theta == pytest.approx(expected)
    assert odo.x == pytest.approx(0.0, abs=1e-12)


def test_odometry_gyro_heading_zeroed_at_first_reading() -> None:
    odo = k.Odometry(theta=0.5)
    odo.update(0, 0, 0, heading=2.0)
    odo.update(100, 100, 20, heading=2.1)
    assert odo.theta == pytest.approx(0.6)
    assert odo.x > 0 and odo.y > 0
