"""X-series control tables (Protocol 2.0) as data, unit conversions and fault names.

Addresses, sizes and defaults follow docs/protocols.md section 2.4. Units:

* position: 4096 pulses per revolution; Interbotix takes 2048 pulses as 0 rad, so
  ``rad = (pulses - 2048) * 2 pi / 4096``;
* velocity: 0.229 rev/min per unit (0.023981 rad/s);
* current (XM series, address 126): 2.69 mA per unit; load (XL430, address 126): 0.1 % of
  the maximum torque per unit, +/-1000;
* voltage: 0.1 V per unit; temperature: degC; time-based profile: ms.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass

from mmexec.drivers.dynamixel.codec import int_to_le

__all__ = [
    "BAUD_RATES",
    "BUS_WATCHDOG_MAX",
    "BUS_WATCHDOG_TRIPPED",
    "BUS_WATCHDOG_UNIT_S",
    "HARDWARE_ERROR_BITS",
    "MODELS",
    "TWO_XL430_W250",
    "WATCHDOG_MIN_FIRMWARE",
    "Access",
    "Area",
    "Model",
    "OperatingMode",
    "Register",
    "baud_rate_problem",
    "common_register",
    "current_to_amps",
    "decode_hardware_error",
    "load_to_fraction",
    "model_by_number",
    "pulses_to_rad",
    "rad_s_to_velocity",
    "rad_to_pulses",
    "velocity_to_rad_s",
]

PULSES_PER_REV = 4096
CENTER_PULSES = 2048
RAD_PER_PULSE = 2.0 * math.pi / PULSES_PER_REV
RPM_PER_VELOCITY_UNIT = 0.229
RAD_S_PER_VELOCITY_UNIT = RPM_PER_VELOCITY_UNIT * 2.0 * math.pi / 60.0
AMPS_PER_CURRENT_UNIT = 2.69e-3
FRACTION_PER_LOAD_UNIT = 1e-3
VOLTS_PER_UNIT = 0.1
PWM_FRACTION_PER_UNIT = 0.00113


#: Baud Rate register (address 8) value -> bit/s (X series, Protocol 2.0; ROBOTIS e-Manual)
BAUD_RATES: dict[int, int] = {
    0: 9600,
    1: 57600,
    2: 115200,
    3: 1_000_000,
    4: 2_000_000,
    5: 3_000_000,
    6: 4_000_000,
    7: 4_500_000,
}

#: Bus Watchdog (address 98): seconds per unit; largest value (127 x 20 ms = 2.54 s); the value
#: it reads after it fired (goal writes then answer data range error until 0 is written);
#: the first firmware that has it (ROBOTIS e-Manual)
BUS_WATCHDOG_UNIT_S = 0.020
BUS_WATCHDOG_MAX = 127
BUS_WATCHDOG_TRIPPED = -1
WATCHDOG_MIN_FIRMWARE = 38


def baud_rate_problem(baudrate: object) -> str:
    """Why ``baudrate`` [bit/s] cannot be used on an X-series bus ("" when it can: one of
    the values of the Baud Rate register, :data:`BAUD_RATES`, from the ROBOTIS e-Manual)."""
    if isinstance(baudrate, int) and not isinstance(baudrate, bool) and (
        baudrate in BAUD_RATES.values()
    ):
        return ""
    rates = ", ".join(str(b) for b in BAUD_RATES.values())
    return f"{baudrate!r} bit/s is not a DYNAMIXEL baud rate (one of {rates})"


class Access(enum.Enum):
    R = "R"
    RW = "RW"


class Area(enum.Enum):
    EEPROM = "EEPROM"
    RAM = "RAM"


class OperatingMode(enum.IntEnum):
    """Operating Mode register (address 11) values."""

    CURRENT = 0
    VELOCITY = 1
    POSITION = 3
    EXTENDED_POSITION = 4
    CURRENT_BASED_POSITION = 5
    PWM = 16


@dataclass(frozen=True)
class Register:
    """One control-table item: ``address``, ``size`` [bytes], access, area, unit, default."""

    name: str
    address: int
    size: int
    access: Access
    area: Area
    unit: str = ""
    default: int = 0
    signed: bool = False

    @property
    def writable(self) -> bool:
        return self.access is Access.RW


def _r(
    name: str,
    address: int,
    size: int,
    access: str,
    area: str,
    unit: str = "",
    default: int = 0,
    signed: bool = False,
) -> Register:
    return Register(name, address, size, Access(access), Area(area), unit, default, signed)


def _x_series(
    *,
    model_number: int,
    current_limit: int | None,
    temperature_limit: int,
    max_voltage: int,
    min_voltage: int,
) -> tuple[Register, ...]:
    regs = [
        _r("model_number", 0, 2, "R", "EEPROM", "", model_number),
        _r("model_information", 2, 4, "R", "EEPROM"),
        _r("firmware_version", 6, 1, "R", "EEPROM", "", 46),
        _r("id", 7, 1, "RW", "EEPROM", "", 1),
        _r("baud_rate", 8, 1, "RW", "EEPROM", "code", 1),
        _r("return_delay_time", 9, 1, "RW", "EEPROM", "2 us", 250),
        _r("drive_mode", 10, 1, "RW", "EEPROM", "bits", 0),
        _r("operating_mode", 11, 1, "RW", "EEPROM", "mode", 3),
        _r("secondary_id", 12, 1, "RW", "EEPROM", "", 255),
        _r("protocol_type", 13, 1, "RW", "EEPROM", "", 2),
        _r("homing_offset", 20, 4, "RW", "EEPROM", "pulse", 0, True),
        _r("moving_threshold", 24, 4, "RW", "EEPROM", "0.229 rpm", 10),
        _r("temperature_limit", 31, 1, "RW", "EEPROM", "degC", temperature_limit),
        _r("max_voltage_limit", 32, 2, "RW", "EEPROM", "0.1 V", max_voltage),
        _r("min_voltage_limit", 34, 2, "RW", "EEPROM", "0.1 V", min_voltage),
        _r("pwm_limit", 36, 2, "RW", "EEPROM", "0.113 %", 885),
        _r("velocity_limit", 44, 4, "RW", "EEPROM", "0.229 rpm", 265),
        _r("max_position_limit", 48, 4, "RW", "EEPROM", "pulse", 4095),
        _r("min_position_limit", 52, 4, "RW", "EEPROM", "pulse", 0),
        _r("shutdown", 63, 1, "RW", "EEPROM", "bits", 52),
        _r("torque_enable", 64, 1, "RW", "RAM", "", 0),
        _r("led", 65, 1, "RW", "RAM", "", 0),
        _r("status_return_level", 68, 1, "RW", "RAM", "", 2),
        _r("registered_instruction", 69, 1, "R", "RAM", "", 0),
        _r("hardware_error_status", 70, 1, "R", "RAM", "bits", 0),
        _r("velocity_i_gain", 76, 2, "RW", "RAM", "", 1920),
        _r("velocity_p_gain", 78, 2, "RW", "RAM", "", 100),
        _r("position_d_gain", 80, 2, "RW", "RAM", "", 0),
        _r("position_i_gain", 82, 2, "RW", "RAM", "", 0),
        _r("position_p_gain", 84, 2, "RW", "RAM", "", 800),
        _r("bus_watchdog", 98, 1, "RW", "RAM", "20 ms", 0, True),
        _r("goal_pwm", 100, 2, "RW", "RAM", "0.113 %", 0, True),
        _r("goal_velocity", 104, 4, "RW", "RAM", "0.229 rpm", 0, True),
        _r("profile_acceleration", 108, 4, "RW", "RAM", "214.577 rev/min^2 or ms", 0),
        _r("profile_velocity", 112, 4, "RW", "RAM", "0.229 rpm or ms", 0),
        _r("goal_position", 116, 4, "RW", "RAM", "pulse", 0, True),
        _r("realtime_tick", 120, 2, "R", "RAM", "ms", 0),
        _r("moving", 122, 1, "R", "RAM", "", 0),
        _r("moving_status", 123, 1, "R", "RAM", "bits", 0),
        _r("present_pwm", 124, 2, "R", "RAM", "0.113 %", 0, True),
        _r("present_velocity", 128, 4, "R", "RAM", "0.229 rpm", 0, True),
        _r("present_position", 132, 4, "R", "RAM", "pulse", 0, True),
        _r("velocity_trajectory", 136, 4, "R", "RAM", "0.229 rpm", 0, True),
        _r("position_trajectory", 140, 4, "R", "RAM", "pulse", 0, True),
        _r("present_input_voltage", 144, 2, "R", "RAM", "0.1 V", 120),
        _r("present_temperature", 146, 1, "R", "RAM", "degC", 30),
    ]
    if current_limit is not None:
        regs += [
            _r("current_limit", 38, 2, "RW", "EEPROM", "2.69 mA", current_limit),
            _r("goal_current", 102, 2, "RW", "RAM", "2.69 mA", 0, True),
            _r("present_current", 126, 2, "R", "RAM", "2.69 mA", 0, True),
        ]
    else:
        regs.append(_r("present_load", 126, 2, "R", "RAM", "0.1 %", 0, True))
    return tuple(sorted(regs, key=lambda r: r.address))


@dataclass(frozen=True)
class Model:
    """A servo model: number reported by Ping, name, register map, allowed operating modes."""

    number: int
    name: str
    registers: tuple[Register, ...]
    operating_modes: frozenset[int]

    def __post_init__(self) -> None:
        object.__setattr__(self, "_by_name", {r.name: r for r in self.registers})
        object.__setattr__(self, "_by_addr", {r.address: r for r in self.registers})

    def reg(self, name: str) -> Register:
        """Register by name; KeyError lists the known names."""
        try:
            return self._by_name[name]  # type: ignore[attr-defined,no-any-return]
        except KeyError:
            raise KeyError(f"{self.name} has no register {name!r}") from None

    def has(self, name: str) -> bool:
        return name in self._by_name  # type: ignore[attr-defined]

    def at(self, address: int) -> Register | None:
        """The register starting at ``address`` (None if none starts there)."""
        return self._by_addr.get(address)  # type: ignore[attr-defined,no-any-return]

    def covering(self, address: int, length: int) -> list[Register]:
        """Registers overlapping ``[address, address + length)``."""
        return [
            r
            for r in self.registers
            if r.address < address + length and address < r.address + r.size
        ]

    def encode(self, name: str, value: int) -> bytes:
        """``value`` [the register's unit] as the bytes of register ``name`` (its size,
        little-endian, two's complement for negatives); KeyError for an unknown name."""
        return int_to_le(value, self.reg(name).size)

    @property
    def has_current_sensor(self) -> bool:
        return self.has("present_current")

    @property
    def effort_register(self) -> Register:
        """Present Current (XM series) or Present Load (XL430 family), both at 126."""
        return self.reg("present_current" if self.has_current_sensor else "present_load")


_ALL_MODES = frozenset(int(m) for m in OperatingMode)
XM430_W350 = Model(
    1020,
    "XM430-W350",
    _x_series(
        model_number=1020, current_limit=1193, temperature_limit=80, max_voltage=160, min_voltage=95
    ),
    _ALL_MODES,
)
XM540_W270 = Model(
    1120,
    "XM540-W270",
    _x_series(
        model_number=1120, current_limit=2047, temperature_limit=80, max_voltage=160, min_voltage=95
    ),
    _ALL_MODES,
)


def _xl430(number: int, name: str) -> Model:
    """The XL430 family's table: no current sensor (Present Load at 126), no current modes."""
    return Model(
        number,
        name,
        _x_series(
            model_number=number,
            current_limit=None,
            temperature_limit=72,
            max_voltage=140,
            min_voltage=60,
        ),
        _ALL_MODES - {OperatingMode.CURRENT, OperatingMode.CURRENT_BASED_POSITION},
    )


XL430_W250 = _xl430(1060, "XL430-W250")

#: The LoCoBot pan/tilt head: one dual-axis unit with two ids, each its own X-series control
#: table (the XL430-W250's, Present Load at 126), but Model Number 1090, not 1060 (ROBOTIS
#: e-Manual 2XL430-W250 control table; DynamixelSDK's ``XL430_W250_2``).
TWO_XL430_W250 = _xl430(1090, "2XL430-W250")

MODELS: dict[int, Model] = {
    m.number: m for m in (XM430_W350, XM540_W270, XL430_W250, TWO_XL430_W250)
}


def common_register(models: Iterable[Model], name: str | Callable[[Model], Register]) -> Register:
    """Register ``name`` (or the one ``name(model)`` picks, e.g. :attr:`Model.effort_register`)
    where it is at the same address with the same size in every one of ``models``: the one
    address a Sync Read/Write or a model-less exchange may use. ValueError otherwise."""
    pick = name if callable(name) else lambda m: m.reg(name)
    regs = {m.name: pick(m) for m in models}
    if not regs:
        raise ValueError(f"register {name!r}: no models given")
    places = {(r.address, r.size) for r in regs.values()}
    if len(places) != 1:
        where = ", ".join(f"{n} {r.name} {r.address}/{r.size}" for n, r in regs.items())
        raise ValueError(f"register differs between models: {where}")
    return next(iter(regs.values()))


def model_by_number(number: int) -> Model:
    """The model reporting ``number`` in Ping; KeyError names the known models."""
    try:
        return MODELS[number]
    except KeyError:
        known = ", ".join(f"{m.number} {m.name}" for m in MODELS.values())
        raise KeyError(f"unknown DYNAMIXEL model number {number} (known: {known})") from None


# --------------------------------------------------------------------------- hardware errors

#: Hardware Error Status (address 70) bit -> fault name
HARDWARE_ERROR_BITS: dict[int, str] = {
    0: "input_voltage",
    2: "overheating",
    3: "motor_encoder",
    4: "electrical_shock",
    5: "overload",
}


def decode_hardware_error(value: int) -> tuple[str, ...]:
    """Named faults set in a Hardware Error Status byte (unknown bits as ``bitN``)."""
    out = []
    for bit in range(8):
        if value & (1 << bit):
            out.append(HARDWARE_ERROR_BITS.get(bit, f"bit{bit}"))
    return tuple(out)


def encode_hardware_error(names: Iterable[str]) -> int:
    """Inverse of :func:`decode_hardware_error` (for fakes and tests)."""
    value = 0
    rev = {v: k for k, v in HARDWARE_ERROR_BITS.items()}
    for n in names:
        if n not in rev:
            raise KeyError(f"unknown hardware fault {n!r} (known: {', '.join(rev)})")
        value |= 1 << rev[n]
    return value


# --------------------------------------------------------------------------- unit conversions


def pulses_to_rad(pulses: float) -> float:
    """Position register [pulses] to joint angle [rad] with 2048 pulses = 0 rad."""
    return (pulses - CENTER_PULSES) * RAD_PER_PULSE


def rad_to_pulses(rad: float) -> int:
    """Joint angle [rad] to the nearest position register value [pulses]."""
    return round(rad / RAD_PER_PULSE) + CENTER_PULSES


def velocity_to_rad_s(units: float) -> float:
    """Velocity register [0.229 rpm units] to [rad/s]."""
    return units * RAD_S_PER_VELOCITY_UNIT


def rad_s_to_velocity(rad_s: float) -> int:
    """[rad/s] to velocity register units (0.229 rpm), rounded."""
    return round(rad_s / RAD_S_PER_VELOCITY_UNIT)


def current_to_amps(units: int) -> float:
    """Present Current (XM series) [2.69 mA units] to [A]."""
    return units * AMPS_PER_CURRENT_UNIT


def load_to_fraction(units: int) -> float:
    """Present Load (XL430) [0.1 % units] to a fraction of the maximum torque (-1 .. 1)."""
    return units * FRACTION_PER_LOAD_UNIT
