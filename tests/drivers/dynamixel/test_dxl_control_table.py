"""Control tables as data, unit conversions and hardware fault names."""

from __future__ import annotations

import math

import pytest

from mmexec.drivers.dynamixel import control_table as ct


def test_models_and_registers() -> None:
    assert set(ct.MODELS) == {1020, 1060, 1090, 1120}
    xm, xl, x540 = ct.MODELS[1020], ct.MODELS[1060], ct.MODELS[1120]
    assert xm.name == "XM430-W350" and xl.name == "XL430-W250" and x540.name == "XM540-W270"
    # the LoCoBot's pan/tilt unit: the XL430's table under its own model number
    two_xl = ct.MODELS[1090]
    assert two_xl.name == "2XL430-W250" and two_xl.reg("model_number").default == 1090
    assert [r.address for r in two_xl.registers] == [r.address for r in xl.registers]
    gp = xm.reg("goal_position")
    assert (gp.address, gp.size, gp.access, gp.area) == (116, 4, ct.Access.RW, ct.Area.RAM)
    assert xm.reg("operating_mode").area is ct.Area.EEPROM
    assert xm.reg("present_current").address == 126 and xm.reg("present_current").signed
    assert xl.reg("present_load").address == 126 and not xl.has("present_current")
    assert not xl.has("current_limit") and x540.reg("current_limit").default == 2047
    assert xl.reg("temperature_limit").default == 72 and xm.reg("temperature_limit").default == 80
    assert (
        ct.OperatingMode.CURRENT not in xl.operating_modes
        and ct.OperatingMode.PWM in xl.operating_modes
    )
    assert [r.name for r in xm.covering(126, 12)] == [
        "present_current",
        "present_velocity",
        "present_position",
        "velocity_trajectory",
    ]
    with pytest.raises(KeyError, match="unknown DYNAMIXEL model number 12"):
        ct.model_by_number(12)


def test_unit_conversions() -> None:
    assert ct.pulses_to_rad(2048) == 0.0
    assert ct.pulses_to_rad(3072) == pytest.approx(math.pi / 2)
    assert ct.pulses_to_rad(0) == pytest.approx(-math.pi)
    assert ct.rad_to_pulses(-math.pi / 2) == 1024
    assert ct.rad_to_pulses(ct.pulses_to_rad(819)) == 819
    assert ct.velocity_to_rad_s(131) == pytest.approx(math.pi, rel=1e-3)  # 30 rpm
    assert ct.rad_s_to_velocity(0.02398) == 1
    assert ct.current_to_amps(1193) == pytest.approx(3.209, abs=1e-3)
    assert ct.load_to_fraction(-1000) == -1.0


def test_hardware_error_names() -> None:
    assert ct.decode_hardware_error(0) == ()
    assert ct.decode_hardware_error(0x01) == ("input_voltage",)
    assert ct.decode_hardware_error(0x34) == ("overheating", "electrical_shock", "overload")
    assert ct.decode_hardware_error(0x08) == ("motor_encoder",)
    assert ct.encode_hardware_error(["overload", "input_voltage"]) == 0x21
    with pytest.raises(KeyError, match="unknown hardware fault"):
        ct.encode_hardware_error(["melted"])
