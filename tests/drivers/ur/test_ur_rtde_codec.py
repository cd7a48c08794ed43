"""RTDE codec: frames built by hand from the wire description (docs/protocols.md 4.4)."""

from __future__ import annotations

import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st

from mmexec.drivers.ur import rtde_codec as c


def test_header_and_protocol_version_request() -> None:
    # size 5 = 3-byte header + uint16 payload; type 'V' = 0x56; version 2 big-endian
    assert c.encode_request_protocol_version(2) == bytes([0x00, 0x05, 0x56, 0x00, 0x02])
    assert c.decode_request_protocol_version(b"\x00\x02") == 2


def test_accepted_replies() -> None:
    assert c.encode_accepted(c.PackageType.REQUEST_PROTOCOL_VERSION, True) == b"\x00\x04V\x01"
    assert c.encode_accepted(c.PackageType.CONTROL_PACKAGE_START, False) == b"\x00\x04S\x00"
    assert c.encode_start() == b"\x00\x03S"
    assert c.encode_pause() == b"\x00\x03P"
    assert c.decode_accepted(b"\x01") is True
    assert c.decode_accepted(b"\x00") is False
    with pytest.raises(c.RTDECodecError):
        c.decode_accepted(b"")


def test_controller_version() -> None:
    frame = c.encode_controller_version(5, 15, 0, 12345)
    expected = b"\x00\x13v" + b"\x00\x00\x00\x05" + b"\x00\x00\x00\x0f" + b"\x00\x00\x00\x00" + b"\x00\x00\x30\x39"
    assert frame == expected
    assert c.encode_get_controller_version() == b"\x00\x03v"
    v = c.decode_controller_version(expected[3:])
    assert (v.major, v.minor, v.bugfix, v.build) == (5, 15, 0, 12345)
    assert str(v) == "5.15.0.12345"


def test_setup_outputs_request_with_trailing_comma() -> None:
    frame = c.encode_setup_outputs(125.0, ["timestamp", "actual_q"], trailing_comma=True)
    body = b"\x40\x5f\x40\x00\x00\x00\x00\x00" + b"timestamp,actual_q,"  # 125.0 as float64 BE
    assert frame == struct.pack(">HB", 3 + len(body), ord("O")) + body
    freq, names = c.decode_setup_outputs(body)
    assert freq == 125.0 and names == ["timestamp", "actual_q"]


def test_setup_reply_with_not_found() -> None:
    frame = c.encode_setup_reply(c.PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS, 0, ["DOUBLE", "NOT_FOUND"])
    assert frame == b"\x00\x14O\x00DOUBLE,NOT_FOUND"  # 3 + 1 + 16
    assert c.decode_setup_reply(frame[3:]) == (0, ["DOUBLE", "NOT_FOUND"])


def test_set_standard_digital_out_example_from_real_client() -> None:
    """setStandardDigitalOut(3, True): recipe 2 = int32 command 13, uint8 mask 0x08, uint8 value 0x08."""
    types = ["INT32", "UINT8", "UINT8"]
    frame = c.encode_data(2, types, [13, 0x08, 0x08])
    assert frame == bytes([0x00, 0x0A, 0x55, 0x02, 0x00, 0x00, 0x00, 0x0D, 0x08, 0x08])
    rid, values = c.decode_data(frame[3:], {2: types})
    assert rid == 2 and values == [13, 8, 8]


def test_setup_inputs_frame() -> None:
    names = ["input_int_register_0", "standard_digital_output_mask", "standard_digital_output"]
    frame = c.encode_setup_inputs(names)
    text = b"input_int_register_0,standard_digital_output_mask,standard_digital_output"
    assert frame == struct.pack(">HB", 3 + len(text), 0x49) + text
    assert c.decode_setup_inputs(text + b",") == names


def test_data_package_every_type_byte_exact() -> None:
    types = list(c.TYPE_FORMATS)
    values = [
        True,                          # BOOL
        0xAB,                          # UINT8
        -2,                            # INT32
        0xDEADBEEF,                    # UINT32
        0x0102030405060708,            # UINT64
        1.0,                           # DOUBLE
        (0.5, -0.5, 2.0),              # VECTOR3D
        (1.0, 2.0, 3.0, 4.0, 5.0, 6.0),  # VECTOR6D
        (-1, 0, 1, 2, 3, 4),           # VECTOR6INT32
        (1, 2, 3, 4, 5, 0xFFFFFFFF),   # VECTOR6UINT32
    ]
    payload = (
        b"\x01"
        + b"\xab"
        + b"\xff\xff\xff\xfe"
        + b"\xde\xad\xbe\xef"
        + b"\x01\x02\x03\x04\x05\x06\x07\x08"
        + b"\x3f\xf0\x00\x00\x00\x00\x00\x00"
        + b"\x3f\xe0" + b"\x00" * 6 + b"\xbf\xe0" + b"\x00" * 6 + b"\x40\x00" + b"\x00" * 6
        + b"".join(struct.pack(">d", x) for x in values[7])
        + b"\xff\xff\xff\xff" + b"\x00\x00\x00\x00" + b"\x00\x00\x00\x01"
        + b"\x00\x00\x00\x02" + b"\x00\x00\x00\x03" + b"\x00\x00\x00\x04"
        + b"".join(struct.pack(">I", x) for x in values[9])
    )
    assert c.pack_values(types, values) == payload
    frame = c.encode_data(1, types, values)
    assert frame[:4] == struct.pack(">HB", 3 + 1 + len(payload), 0x55) + b"\x01"
    rid, decoded = c.decode_data(frame[3:], {1: types})
    assert rid == 1 and decoded == values


def test_text_message() -> None:
    frame = c.encode_text_message("hi", "ur", 3)
    assert frame == b"\x00\x0aM\x02hi\x02ur\x03"
    m = c.decode_text_message(frame[3:])
    assert (m.message, m.source, m.level) == ("hi", "ur", 3)
    with pytest.raises(c.RTDECodecError):
        c.decode_text_message(b"\x05hi")


def test_split_packages_keeps_partial_tail_and_rejects_bad_size() -> None:
    a = c.encode_request_protocol_version()
    b = c.encode_setup_reply(c.PackageType.CONTROL_PACKAGE_SETUP_INPUTS, 1, ["INT32"])
    stream = a + b + b[:4]
    packages, rest = c.split_packages(stream)
    assert [p.type for p in packages] == [ord("V"), ord("I")]
    assert packages[1].payload == b"\x01INT32"
    assert rest == b[:4]
    packages, rest = c.split_packages(rest + b[4:])
    assert len(packages) == 1 and rest == b""
    with pytest.raises(c.RTDECodecError):
        c.split_packages(b"\x00\x02V")


def test_strict_split_rejects_unknown_type_in_the_first_header() -> None:
    # a text service on the port ("Connected: ...") reads as size 0x436f, type 'n'
    assert c.split_packages(b"Connected: Universal") == ([], b"Connected: Universal")
    with pytest.raises(c.RTDECodecError, match=r"unknown package type 110 \(0x6e\)"):
        c.split_packages(b"Connected: Universal", strict=True)
    v = c.encode_request_protocol_version()
    assert c.split_packages(v + v[:3], strict=True) == ([c.Package(ord("V"), b"\x00\x02")], v[:3])


def test_wrong_lengths_raise() -> None:
    with pytest.raises(c.RTDECodecError, match="needs 6 values"):
        c.pack_values(["VECTOR6D"], [(1.0, 2.0)])
    with pytest.raises(c.RTDECodecError, match="2 fields"):
        c.pack_values(["DOUBLE", "INT32"], [1.0])
    with pytest.raises(c.RTDECodecError, match="needs 8 bytes"):
        c.unpack_values(["DOUBLE"], b"\x00")
    with pytest.raises(c.RTDECodecError, match="unknown recipe id 4"):
        c.decode_data(b"\x04", {1: ["DOUBLE"]})
    with pytest.raises(c.RTDECodecError, match="unknown RTDE type"):
        c.pack_values(["FLOAT"], [1.0])


def test_variable_types() -> None:
    assert c.variable_type("actual_q") == "VECTOR6D"
    assert c.variable_type("robot_mode") == "INT32"
    assert c.variable_type("runtime_state") == "UINT32"
    assert c.variable_type("actual_digital_output_bits") == "UINT64"
    assert c.variable_type("payload_cog") == "VECTOR3D"
    assert c.variable_type("joint_mode") == "VECTOR6INT32"
    assert c.variable_type("output_int_register_19") == "INT32"
    assert c.variable_type("output_double_register_12") == "DOUBLE"
    assert c.variable_type("input_bit_register_64") == "BOOL"
    assert c.variable_type("input_bit_register_3") == c.NOT_FOUND
    assert c.variable_type("output_int_register_48") == c.NOT_FOUND
    assert c.variable_type("actual_qq") == c.NOT_FOUND


_VALUE = {
    "BOOL": st.booleans(),
    "UINT8": st.integers(0, 255),
    "INT32": st.integers(-(2**31), 2**31 - 1),
    "UINT32": st.integers(0, 2**32 - 1),
    "UINT64": st.integers(0, 2**64 - 1),
    "DOUBLE": st.floats(allow_nan=False),
    "VECTOR3D": st.tuples(*[st.floats(allow_nan=False)] * 3),
    "VECTOR6D": st.tuples(*[st.floats(allow_nan=False)] * 6),
    "VECTOR6INT32": st.tuples(*[st.integers(-(2**31), 2**31 - 1)] * 6),
    "VECTOR6UINT32": st.tuples(*[st.integers(0, 2**32 - 1)] * 6),
}


@st.composite
def _recipe(draw: st.DrawFn) -> tuple[list[str], list[object]]:
    types = draw(st.lists(st.sampled_from(sorted(_VALUE)), min_size=1, max_size=12))
    return types, [draw(_VALUE[t]) for t in types]


@given(_recipe(), st.integers(1, 255))
def test_data_round_trip(recipe: tuple[list[str], list[object]], rid: int) -> None:
    types, values = recipe
    frame = c.encode_data(rid, types, values)
    (pkg,), rest = c.split_packages(frame)
    assert rest == b"" and pkg.type == ord("U")
    assert c.decode_data(pkg.payload, {rid: types}) == (rid, values)
