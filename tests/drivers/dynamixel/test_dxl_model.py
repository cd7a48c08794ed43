"""The driver's WX250s model (model.py) against the vendor table the fake bus holds.

The fake is written from docs/protocols.md 2.4-2.5 and the ROBOTIS e-Manual, not from
model.py, so these checks catch a wrong fact in the driver without a bus.
"""

from __future__ import annotations

from mmexec.drivers.dynamixel import model
from mmexec.drivers.dynamixel.control_table import MODELS
from mmexec.drivers.fakes.dynamixel import VENDOR_MODEL_NUMBERS, FakeServo, wx250s_servos


def test_vendor_model_numbers() -> None:
    # ROBOTIS e-Manual control tables (address 0) / DynamixelSDK dynamixel_item.h
    assert VENDOR_MODEL_NUMBERS == {
        "XM430-W350": 1020,
        "XM430-W210": 1030,
        "XL430-W250": 1060,
        "XC430-W150": 1070,
        "XC430-W240": 1080,
        "2XL430-W250": 1090,
        "XM540-W270": 1120,
        "XM540-W150": 1130,
    }
    # every model the driver knows carries the vendor's number under the vendor's name
    assert {m.name: n for n, m in MODELS.items()} == {
        name: VENDOR_MODEL_NUMBERS[name] for name in (m.name for m in MODELS.values())
    }


def test_driver_model_matches_the_vendor_bus() -> None:
    servos = {s.id: s for s in wx250s_servos(locobot=True, configured=True)}
    joints = model.ARM_JOINTS + (model.GRIPPER,) + model.PAN_TILT
    expected_ids = {j.id for j in joints} | {j.shadow for j in joints if j.shadow is not None}
    assert set(servos) == expected_ids == set(range(1, 12))
    for j in joints:
        s = servos[j.id]
        assert (j.model.number, j.model.name) == (s.model_number, s.servo), j.name
        assert bool(s.get("drive_mode") & 0x01) == j.reversed, j.name
        if j.shadow is not None:
            shadow = servos[j.shadow]
            assert shadow.get("secondary_id") == j.id and shadow.model_number == j.model.number


def test_fake_servo_reports_its_vendor_number_after_factory_reset() -> None:
    s = FakeServo(10, "2XL430-W250")
    assert s.get("model_number") == 1090 and s.model.reg("present_load").address == 126
    s.factory_reset(0xFF, 0.0)
    assert s.get("model_number") == 1090 and s.id == 1
