"""Interbotix WidowX-250 6DOF (wx250s) arm and gripper, optionally with LoCoBot pan/tilt.

:class:`WX250s` owns one :class:`~mmexec.drivers.dynamixel.bus.DxlBus` and an I/O thread.
Construction does no I/O. :meth:`WX250s.connect` runs the Interbotix bring-up (ping every
configured id with 3 attempts, torque off, EEPROM settings, operating modes, profiles, goal =
present position, torque on) and starts the thread. Each control cycle (``rate_hz``, 100 Hz
by default) the thread does one Sync Write of Goal Position for the position-controlled
joint ids (shadows follow through their Secondary ID) and one Sync Read of 12 bytes from
address 126 (current/load, velocity, position) for the joint ids, then advances the goals:

* trajectories are streamed as timed waypoints, linearly interpolated every cycle (from the
  position at start to the first waypoint, then between waypoints); the goal succeeds once
  the last waypoint is reached within ``tolerance`` [rad] and fails if that takes more than
  ``settle_timeout`` [s] beyond the trajectory's duration;
* joint-range and velocity limits are checked in :meth:`WX250s.follow` before anything is
  sent: a violating trajectory gives a FAILED goal naming the joint, and nothing moves;
* a status with the hardware alert bit makes the thread read Hardware Error Status and fail
  the running goals with the named fault (``overload``, ``overheating``, ``input_voltage``,
  ``motor_encoder``, ``electrical_shock``); :meth:`WX250s.reboot` / :meth:`WX250s.smart_reboot`
  clear it on request;
* cancel holds the present position (goal = present) and then marks the goal CANCELLED;
  :meth:`WX250s.close` holds, stops the thread and closes the port (torque stays on unless
  ``torque_off_on_close``);
* a lost port fails the running goals with "link lost" and ends the thread.

Every register is read and written by name at the address and size of the servo's own
model (:mod:`.control_table`); the Arm/Gripper capability adapters the device hands out
(:attr:`WX250s.arm`, :attr:`WX250s.gripper`) live in :mod:`.arm`, the LoCoBot's pan/tilt
Head (:attr:`WX250s.head`, with ``locobot``) in :mod:`.head`.

Positions are radians with 2048 pulses = 0 rad, velocities rad/s, efforts in amperes (XM
servos) or fraction of maximum torque (XL430); the gripper width is metres between the
finger pads, from the servo angle through the horn/arm linkage of docs/protocols.md 2.5.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Self, TypeVar

import numpy as np

from mmexec.drivers.dynamixel import codec
from mmexec.drivers.dynamixel.arm import WX250sArm, WX250sGripper
from mmexec.drivers.dynamixel.bus import (
    BusConfig,
    CorruptReply,
    DxlBus,
    DxlLinkError,
    DynamixelError,
    HardwareFault,
    LinkLost,
    NoReply,
    NotConnected,
    PingInfo,
    ServoError,
)
from mmexec.drivers.dynamixel.codec import Status, StatusResult
from mmexec.drivers.dynamixel.control_table import (
    BUS_WATCHDOG_MAX,
    BUS_WATCHDOG_TRIPPED,
    BUS_WATCHDOG_UNIT_S,
    MODELS,
    WATCHDOG_MIN_FIRMWARE,
    Model,
    OperatingMode,
    Register,
    baud_rate_problem,
    common_register,
    current_to_amps,
    decode_hardware_error,
    load_to_fraction,
    pulses_to_rad,
    rad_s_to_velocity,
    rad_to_pulses,
    velocity_to_rad_s,
)
from mmexec.drivers.dynamixel.head import WX250sHead
from mmexec.drivers.dynamixel.model import (
    ARM_JOINTS,
    FINGER_MAX,
    FINGER_MIN,
    GRIPPER,
    LOCOBOT_MOUNT,
    PAN_TILT,
    JointSpec,
    finger_offset,
    gripper_angle_for_width,
    gripper_width,
)
from mmexec.drivers.interfaces import (
    Clock,
    Goal,
    GoalState,
    GraspState,
    GripperState,
    JointState,
    JointTrajectory,
    MonotonicClock,
)

__all__ = [
    "ARM_JOINTS",
    "GRIPPER",
    "LOCOBOT_MOUNT",
    "PAN_TILT",
    "CycleIO",
    "JointSpec",
    "ServoReading",
    "WX250s",
    "WX250sConfig",
    "finger_offset",
    "gripper_angle_for_width",
    "gripper_width",
]

log = logging.getLogger(__name__)

_T = TypeVar("_T")

#: bytes of the per-cycle Sync Read: current/load, velocity and position are 10 (their
#: table entries), plus the first 2 of Velocity Trajectory, which this driver has always
#: asked for (and ignores); kept so the bus traffic (and its benchmark) stay the same
PRESENT_READ_LEN = 12
BUS_WATCHDOG_UNIT_MS = round(BUS_WATCHDOG_UNIT_S * 1000)
#: PWM Limit of the gripper servo: the factory value (its model's table default), which
#: bring-up keeps
GRIPPER_PWM_LIMIT = GRIPPER.model.reg("pwm_limit").default
#: Velocity Limit bring-up writes to every servo (30 rev/min)
VELOCITY_LIMIT_RAD_S = math.pi
#: the pan/tilt servos' velocity-based profile (drive mode 0): 30 rev/min, and acceleration
#: 15 units of 214.577 rev/min^2 (the Interbotix value; the table has no conversion for it)
PAN_TILT_PROFILE_VELOCITY_RAD_S = math.pi
PAN_TILT_PROFILE_ACCELERATION = 15
#: operating modes whose last goal is an effort that goes on while the host is silent (the
#: servo keeps pushing or turning): the Bus Watchdog is armed on servos in these modes. In the
#: position modes the servo holds its last goal by itself, which is the safe state; a fired
#: watchdog there would only make the next goals (Sync Write, no status) vanish unnoticed.
WATCHDOG_MODES = frozenset({OperatingMode.PWM, OperatingMode.VELOCITY, OperatingMode.CURRENT})

# --------------------------------------------------------------------------- one control cycle


@dataclass(frozen=True)
class ServoReading:
    """Decoded 12 bytes from address 126: position [rad], velocity [rad/s], effort (A for XM
    current, fraction of max torque for XL430 load), raw ``error`` byte of the status."""

    position: float
    velocity: float
    effort: float
    error: int
    raw_position: int
    raw_velocity: int
    raw_effort: int


def _span(first: Register, last: Register) -> tuple[int, int]:
    """Address and length of the block from ``first`` through ``last``."""
    return first.address, last.address + last.size - first.address


class CycleIO:
    """The per-cycle bus traffic: Sync Write Goal Position to ``write_ids``, Sync Read of
    present current/load, velocity and position (12 bytes at 126) from ``read_ids``; the
    addresses come from the servos' control tables (one address for all of them, as a Sync
    exchange needs). Pure composition of codec + bus, shared by the arm's I/O thread and the
    benchmark."""

    def __init__(
        self,
        bus: DxlBus,
        write_ids: Sequence[int],
        read_ids: Sequence[int],
        models: dict[int, Model],
    ) -> None:
        self.bus = bus
        self.write_ids = tuple(write_ids)
        self.read_ids = tuple(read_ids)
        self._has_current = {i: models[i].has_current_sensor for i in read_ids}
        self._goal = common_register((models[i] for i in write_ids), "goal_position")
        read_models = [models[i] for i in read_ids]
        effort = common_register(read_models, lambda m: m.effort_register)
        velocity = common_register(read_models, "present_velocity")
        position = common_register(read_models, "present_position")
        address, length = _span(effort, position)
        self._block = (address, max(length, PRESENT_READ_LEN))
        #: (offset, size) of effort, velocity, position in the block
        self._fields = [
            (r.address - effort.address, r.size) for r in (effort, velocity, position)
        ]

    def write_goals(self, pulses: Sequence[int]) -> None:
        """One Sync Write of Goal Position [pulses], in ``write_ids`` order."""
        if len(pulses) != len(self.write_ids):
            raise ValueError(f"expected {len(self.write_ids)} goals, got {len(pulses)}")
        reg = self._goal
        self.bus.sync_write(
            reg.address,
            reg.size,
            [(i, codec.int_to_le(p, reg.size)) for i, p in zip(self.write_ids, pulses)],
        )

    def read_state(self) -> dict[int, ServoReading]:
        """One Sync Read of present current/load, velocity and position."""
        address, length = self._block
        statuses = self.bus.sync_read(address, length, self.read_ids)
        return {i: self.decode(i, st) for i, st in statuses.items()}

    def decode(self, dxl_id: int, st: Status) -> ServoReading:
        d = st.data
        if len(d) < sum(self._fields[-1]):
            raise DxlLinkError(self.bus.port, f"short state reply from servo id {dxl_id}", dxl_id)
        eff, vel, pos = (
            int.from_bytes(d[at : at + size], "little", signed=True) for at, size in self._fields
        )
        effort = current_to_amps(eff) if self._has_current[dxl_id] else load_to_fraction(eff)
        return ServoReading(
            pulses_to_rad(pos), velocity_to_rad_s(vel), effort, st.error, pos, vel, eff
        )

    def cycle(self, pulses: Sequence[int]) -> dict[int, ServoReading]:
        self.write_goals(pulses)
        return self.read_state()


# --------------------------------------------------------------------------- config


@dataclass(frozen=True)
class WX250sConfig:
    """Driver settings. Times in seconds unless the name says ms; angles in rad.

    ``baudrate``: one of the DYNAMIXEL rates (9600 .. 4.5M bit/s, the Baud Rate register's
    table); ``latency``: USB adapter latency (1 ms for the U2D2 with the Interbotix udev rule);
    ``profile_velocity_ms`` / ``profile_acceleration_ms``: the time-based profile written to
    the arm servos. Interbotix uses 2000 / 300 ms for single set-point moves; this driver
    streams interpolated waypoints every cycle, so a 100 ms profile (the servo reaches each
    streamed set-point 0.1 s later, smoothly) is the default. ``shutdown_mask``: Shutdown
    register value; 0x3D makes all five named faults cut torque and raise the alert bit the
    driver watches (factory 0x34 would leave input voltage and encoder faults unreported).
    ``bus_watchdog_ms``: the Bus Watchdog armed on the servos driven by an effort rather than
    a position (the gripper in PWM mode): with no instruction for that long the servo zeroes
    its goal and stops. 0 leaves it off; else 20 .. 2540 in steps of 20 ms, and long enough
    for 3 control cycles plus 4 reply deadlines (:meth:`min_bus_watchdog_ms`), so normal
    traffic never lets it fire. None (default): 100 ms, or that minimum rounded up to 20 ms
    when the link is slower (:attr:`watchdog_ms`).

    Construction checks every value (:meth:`problems`) and raises one ValueError naming each
    bad field, so the robot backend reports it at the arm's config section.
    """

    port: str = "/dev/ttyDXL"
    baudrate: int = 1_000_000
    latency: float = 0.001
    locobot: bool = False
    rate_hz: float = 100.0
    write_eeprom: bool = True
    profile_velocity_ms: int = 100
    profile_acceleration_ms: int = 30
    ping_attempts: int = 3
    tolerance: float = 0.02
    settle_timeout: float = 1.0
    max_missed_cycles: int = 3
    torque_off_on_close: bool = False
    shutdown_mask: int = 0x3D
    reboot_timeout: float = 1.0
    bus_watchdog_ms: int | None = None
    gripper_pwm_min: int = 150
    gripper_pwm_max: int = 350
    gripper_max_force: float = 5.0
    gripper_load_threshold: float = 0.2
    gripper_width_tolerance: float = 0.002
    gripper_timeout: float = 3.0

    def __post_init__(self) -> None:
        bad = self.problems()
        if bad:
            raise ValueError("; ".join(f"{name}: {message}" for name, message in bad))

    def min_bus_watchdog_ms(self) -> float:
        """The shortest Bus Watchdog [ms] that normal traffic refreshes in time: 3 control
        periods plus 4 reply deadlines (a cycle with failed exchanges; derived)."""
        reply_s = 2.0 * self.latency + 0.002
        return 1000.0 * (3.0 / self.rate_hz + 4.0 * reply_s)

    def problems(self) -> list[tuple[str, str]]:
        """(field, message) for every unusable value; empty when the config is usable."""
        out: list[tuple[str, str]] = []
        problem = baud_rate_problem(self.baudrate)
        if problem:
            out.append(("baudrate", problem))
        if not (math.isfinite(self.latency) and 0.0 <= self.latency <= 1.0):
            out.append(("latency", f"must be 0..1 s, got {self.latency}"))
        if not 0 < self.rate_hz <= 1000:
            out.append(("rate_hz", f"must be in (0, 1000], got {self.rate_hz}"))
        if not 1 <= self.ping_attempts <= 100:
            out.append(("ping_attempts", f"must be 1..100, got {self.ping_attempts}"))
        if not 1 <= self.max_missed_cycles <= 1000:
            out.append(("max_missed_cycles", f"must be 1..1000, got {self.max_missed_cycles}"))
        if not 0 <= self.profile_velocity_ms <= 32767:
            out.append(("profile_velocity_ms", f"must be 0..32767 ms, got {self.profile_velocity_ms}"))
        elif not 0 <= 2 * self.profile_acceleration_ms <= self.profile_velocity_ms:
            msg = (
                "time-based profile needs 0 <= 2 * profile_acceleration_ms <= profile_velocity_ms, "
                f"got {self.profile_acceleration_ms} and {self.profile_velocity_ms}"
            )
            out.append(("profile_acceleration_ms", msg))
        if not 0 <= self.shutdown_mask <= 0xFF:
            out.append(("shutdown_mask", f"must be a byte 0..255, got {self.shutdown_mask}"))
        for name in (
            "tolerance",
            "settle_timeout",
            "reboot_timeout",
            "gripper_max_force",
            "gripper_width_tolerance",
            "gripper_timeout",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                out.append((name, f"must be a finite number > 0, got {value}"))
        if not 0 < self.gripper_load_threshold <= 1:
            msg = f"must be in (0, 1] (fraction of max torque), got {self.gripper_load_threshold}"
            out.append(("gripper_load_threshold", msg))
        if not 0 <= self.gripper_pwm_min <= self.gripper_pwm_max <= GRIPPER_PWM_LIMIT:
            msg = (
                f"need 0 <= gripper_pwm_min <= gripper_pwm_max <= {GRIPPER_PWM_LIMIT} (the "
                f"servo's PWM Limit), got {self.gripper_pwm_min} and {self.gripper_pwm_max}"
            )
            out.append(("gripper_pwm_max", msg))
        wd, unit = self.watchdog_ms, BUS_WATCHDOG_UNIT_MS
        top = BUS_WATCHDOG_MAX * unit
        if wd != 0 and (not unit <= wd <= top or wd % unit):
            msg = f"must be 0 (off) or {unit}..{top} ms in steps of {unit} ms, got {wd}"
            if self.bus_watchdog_ms is None:
                msg = f"the {wd} ms this link needs is above {top} ms: set bus_watchdog_ms: 0"
            out.append(("bus_watchdog_ms", msg))
        elif wd != 0 and not out and wd < self.min_bus_watchdog_ms():
            msg = (
                f"{wd} ms would fire during normal traffic at rate_hz {self.rate_hz:g} and "
                f"latency {self.latency:g} s: use at least {self.min_bus_watchdog_ms():.0f} ms "
                "(3 control cycles plus 4 reply deadlines)"
            )
            out.append(("bus_watchdog_ms", msg))
        return out

    @property
    def watchdog_ms(self) -> int:
        """The Bus Watchdog period [ms] in use: ``bus_watchdog_ms``, or when None the larger
        of 100 ms and :meth:`min_bus_watchdog_ms` rounded up to 20 ms (0 = off)."""
        if self.bus_watchdog_ms is not None:
            return self.bus_watchdog_ms
        unit = BUS_WATCHDOG_UNIT_MS
        need = self.min_bus_watchdog_ms() if self.rate_hz > 0 else 0.0
        if not math.isfinite(need):
            return 0
        return max(100, unit * math.ceil(need / unit))

    @property
    def bus_watchdog_units(self) -> int:
        """The Bus Watchdog register value (20 ms units; 0 = off)."""
        return self.watchdog_ms // BUS_WATCHDOG_UNIT_MS


def _detail(e: Exception | None) -> str:
    if e is None:
        return "no error recorded"
    return str(getattr(e, "detail", e))



# --------------------------------------------------------------------------- device


@dataclass
class _TrajRun:
    goal: Goal
    traj: JointTrajectory
    start: float
    q0: tuple[float, ...]


@dataclass
class _GripRun:
    goal: Goal
    target_angle: float
    pwm: int
    closing: bool
    start: float
    cycles: int = 0
    still: int = 0
    sent: bool = False


class WX250s:
    """The arm bus device. Use :attr:`arm` and :attr:`gripper` as capabilities."""

    def __init__(
        self, config: WX250sConfig, *, clock: Clock | None = None, bus: DxlBus | None = None
    ) -> None:
        self.config = config
        self.clock: Clock = clock if clock is not None else MonotonicClock()
        self.bus = (
            bus
            if bus is not None
            else DxlBus(BusConfig(config.port, config.baudrate, config.latency))
        )
        self.joints: tuple[JointSpec, ...] = ARM_JOINTS
        self.position_joints: tuple[JointSpec, ...] = ARM_JOINTS + (
            PAN_TILT if config.locobot else ()
        )
        self.all_joints: tuple[JointSpec, ...] = (
            ARM_JOINTS + (GRIPPER,) + (PAN_TILT if config.locobot else ())
        )
        self.read_ids = tuple(j.id for j in self.all_joints)
        self.by_id = {j.id: j for j in self.all_joints}
        self.name_of = {j.id: j.name for j in self.all_joints}
        for j in self.all_joints:
            if j.shadow is not None:
                self.name_of[j.shadow] = f"{j.name}_shadow"
        self.found: dict[int, PingInfo] = {}
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._state: JointState | None = None
        self._readings: dict[int, ServoReading] = {}
        self._goals_pulses: list[int] = []
        self._sent_goals: list[int] = []
        self._traj: _TrajRun | None = None
        self._grip: _GripRun | None = None
        self._grip_pwm = 0
        self._grip_state: GripperState | None = None
        self._faults: dict[int, tuple[str, ...]] = {}
        self._requests: list[Callable[[], bool]] = []
        self._missed = 0
        self._link_error = ""
        self._connected = False
        self._io: CycleIO | None = None
        #: servos whose Bus Watchdog is armed (effort-driven modes, see WATCHDOG_MODES)
        self.watchdog_ids: tuple[int, ...] = (
            tuple(j.id for j in self.all_joints if self._mode_of(j) in WATCHDOG_MODES)
            if config.bus_watchdog_units
            else ()
        )
        #: Bus Watchdog trips seen and cleared since construction (diagnostics)
        self.watchdog_trips = 0
        self._arm = WX250sArm(self)
        self._gripper = WX250sGripper(self)
        self._head = WX250sHead(self) if config.locobot else None

    # -- capabilities
    @property
    def arm(self) -> WX250sArm:
        return self._arm

    @property
    def gripper(self) -> WX250sGripper:
        return self._gripper

    @property
    def head(self) -> WX250sHead | None:
        """The LoCoBot's pan/tilt head (None without ``locobot``)."""
        return self._head

    @property
    def connected(self) -> bool:
        return self._connected

    @property
    def faults(self) -> dict[str, tuple[str, ...]]:
        """Active hardware faults by joint name."""
        with self._lock:
            return {self.name_of.get(i, str(i)): f for i, f in self._faults.items()}

    @property
    def link_error(self) -> str:
        """Why the I/O thread stopped ("" while running)."""
        return self._link_error

    # -- bring-up
    def servo_ids(self) -> list[int]:
        """Every id on the bus (joints, shadows, gripper, pan/tilt), ascending."""
        ids = set(self.read_ids)
        ids.update(j.shadow for j in self.all_joints if j.shadow is not None)
        return sorted(ids)

    @staticmethod
    def _mode_of(j: JointSpec) -> OperatingMode:
        """Operating Mode the bring-up writes: PWM for the gripper, position for the rest."""
        return OperatingMode.PWM if j is GRIPPER else OperatingMode.POSITION

    def _model_of(self, dxl_id: int) -> Model:
        if dxl_id in self.by_id:
            return self.by_id[dxl_id].model
        master = next(j for j in self.all_joints if j.shadow == dxl_id)
        return master.model

    # -- register access: by name, at the address and size of the servo's own model
    def _write(self, dxl_id: int, name: str, value: int) -> None:
        """Write ``value`` [the register's unit] to register ``name`` of servo ``dxl_id``."""
        model = self._model_of(dxl_id)
        self.bus.write(dxl_id, model.reg(name).address, model.encode(name, value))

    def _read(self, dxl_id: int, name: str) -> int:
        """Register ``name`` of servo ``dxl_id`` (signed where the table says so)."""
        reg = self._model_of(dxl_id).reg(name)
        return codec.int_from_le(self.bus.read(dxl_id, reg.address, reg.size), signed=reg.signed)

    def _send_gripper_pwm(self, pwm: int) -> None:
        """Goal PWM of the gripper servo, as the one-servo Sync Write (no status) the I/O
        thread uses for it."""
        reg = GRIPPER.model.reg("goal_pwm")
        self.bus.sync_write(reg.address, reg.size, [(GRIPPER.id, GRIPPER.model.encode(reg.name, pwm))])

    def connect(self) -> None:
        """Open the port, run the bring-up and start the I/O thread.

        Bounded by the link deadlines (a few hundred ms); call it from setup, not from a
        tick. Raises a :class:`DynamixelError` naming the port and the servo id on failure
        (and closes the port again).
        """
        if self._connected:
            return
        self.bus.open()
        try:
            self._bring_up()
        except BaseException:
            self.bus.close()
            raise
        self._stop.clear()
        self._link_error = ""
        self._connected = True
        self._thread = threading.Thread(
            target=self._run, name=f"wx250s-{self.bus.port}", daemon=True
        )
        self._thread.start()

    def _bring_up(self) -> None:
        cfg, bus = self.config, self.bus
        self.found = {}
        for dxl_id in self.servo_ids():
            last: Exception | None = None
            for _ in range(cfg.ping_attempts):
                try:
                    self.found[dxl_id] = bus.ping(dxl_id)
                    break
                except DxlLinkError as e:
                    if isinstance(e, LinkLost):
                        raise
                    last = e
                except ServoError as e:
                    if e.result is not StatusResult.CRC_ERROR:
                        raise
                    last = e
            if dxl_id not in self.found:
                raise NoReply(
                    bus.port,
                    f"servo id {dxl_id} ({self.name_of[dxl_id]}) did not answer ping "
                    f"({cfg.ping_attempts} attempts; last: {_detail(last)})",
                    dxl_id,
                )
            want = self._model_of(dxl_id)
            got = self.found[dxl_id].model
            if got != want.number:
                name = MODELS[got].name if got in MODELS else "unknown model"
                raise DynamixelError(
                    f"{bus.port}: servo id {dxl_id} ({self.name_of[dxl_id]}) is {name} ({got}), "
                    f"expected {want.name} ({want.number})"
                )
            fw = self.found[dxl_id].firmware
            if dxl_id in self.watchdog_ids and fw < WATCHDOG_MIN_FIRMWARE:
                raise DynamixelError(
                    f"{bus.port}: servo id {dxl_id} ({self.name_of[dxl_id]}) has firmware {fw}, "
                    f"which has no Bus Watchdog (firmware {WATCHDOG_MIN_FIRMWARE} or later): "
                    "update it with DYNAMIXEL Wizard, or set bus_watchdog_ms: 0"
                )

        def retry(call: Callable[..., _T], *args: object) -> _T:
            """One configuration exchange, repeated (``ping_attempts`` in all) when its reply
            is missing or corrupt: the writes are idempotent, and one lost status on a noisy
            bus should not fail the bring-up. Link loss and servo errors are not retried."""
            last: DxlLinkError | None = None
            for _ in range(cfg.ping_attempts):
                try:
                    return call(*args)
                except (NoReply, CorruptReply) as e:
                    log.debug("%s: bring-up exchange retried: %s", bus.port, e)
                    last = e
            assert last is not None
            raise last

        velocity_limit = rad_s_to_velocity(VELOCITY_LIMIT_RAD_S)
        pan_tilt_velocity = rad_s_to_velocity(PAN_TILT_PROFILE_VELOCITY_RAD_S)
        ids = self.servo_ids()
        for dxl_id in ids:
            retry(self._write, dxl_id, "torque_enable", 0)
        for dxl_id in ids:
            # Bus Watchdog off, which also clears a watchdog error left from before (a link
            # lost while armed): until then every goal write would answer data range error
            retry(self._write, dxl_id, "bus_watchdog", 0)
        for dxl_id in ids:
            if retry(self._read, dxl_id, "hardware_error_status"):
                raise HardwareFault(
                    bus.port,
                    dxl_id,
                    decode_hardware_error(retry(self._read, dxl_id, "hardware_error_status")),
                    self.name_of[dxl_id],
                )
        for j in self.all_joints:
            arm_group = j in ARM_JOINTS
            drive = (0x01 if j.reversed else 0) | (0x04 if arm_group else 0)
            targets = [(j.id, drive, 255)]
            if j.shadow is not None:
                targets.append((j.shadow, drive | 0x01, j.id))
            mode = self._mode_of(j)
            for dxl_id, dmode, secondary in targets:
                if cfg.write_eeprom:
                    retry(self._write, dxl_id, "return_delay_time", 0)
                    retry(self._write, dxl_id, "drive_mode", dmode)
                    retry(self._write, dxl_id, "secondary_id", secondary)
                    retry(self._write, dxl_id, "velocity_limit", velocity_limit)
                    retry(self._write, dxl_id, "max_position_limit", j.max_pulses)
                    retry(self._write, dxl_id, "min_position_limit", j.min_pulses)
                    retry(self._write, dxl_id, "shutdown", cfg.shutdown_mask)
                retry(self._write, dxl_id, "operating_mode", int(mode))
                if j is GRIPPER:
                    retry(self._write, dxl_id, "goal_pwm", 0)
                elif arm_group:
                    # time-based profile (drive mode bit 2): both in ms
                    retry(self._write, dxl_id, "profile_acceleration", cfg.profile_acceleration_ms)
                    retry(self._write, dxl_id, "profile_velocity", cfg.profile_velocity_ms)
                else:
                    retry(self._write, dxl_id, "profile_acceleration", PAN_TILT_PROFILE_ACCELERATION)
                    retry(self._write, dxl_id, "profile_velocity", pan_tilt_velocity)
        models = {i: self.by_id[i].model for i in self.read_ids}
        self._io = CycleIO(bus, [j.id for j in self.position_joints], self.read_ids, models)
        readings = retry(self._io.read_state)
        goals = []
        for j in self.position_joints:
            p = min(max(readings[j.id].raw_position, j.min_pulses), j.max_pulses)
            goals.append(p)
            retry(self._write, j.id, "goal_position", p)
        for dxl_id in ids:
            retry(self._write, dxl_id, "torque_enable", 1)
        for dxl_id in self.watchdog_ids:
            # armed last: it watches only while torque is on, and the I/O thread's Sync Read
            # (every cycle, this id included) refreshes it from now on
            retry(self._write, dxl_id, "bus_watchdog", cfg.bus_watchdog_units)
        with self._lock:
            self._goals_pulses = goals
            self._sent_goals = list(goals)
            self._grip_pwm = 0
            self._faults = {}
            self._update_state(readings)
        log.info(
            "%s: wx250s%s up: %s",
            bus.port,
            " (LoCoBot)" if cfg.locobot else "",
            ", ".join(f"{i}:{MODELS[p.model].name}" for i, p in sorted(self.found.items())),
        )

    # -- shutdown
    def close(self) -> None:
        """Hold position, stop the I/O thread, close the port. Idempotent; never raises
        link errors (they are logged)."""
        t, self._thread = self._thread, None
        self._stop.set()
        if t is not None and t is not threading.current_thread():
            t.join(timeout=2.0)
        if self._connected and not self._link_error and self.bus.is_open:
            try:
                self._hold_present()
                if self.config.torque_off_on_close:
                    for dxl_id in self.servo_ids():
                        self._write(dxl_id, "torque_enable", 0)
                for dxl_id in self.watchdog_ids:
                    # off (and any trip cleared): the next program on this bus, or our next
                    # connect(), finds goal writes accepted
                    self._write(dxl_id, "bus_watchdog", 0)
                if self._grip_pwm:
                    self._send_gripper_pwm(0)
            except DynamixelError as e:
                log.warning("%s: could not hold position on close: %s", self.bus.port, e)
        self._finish_goals("driver closed", cancelled=True)
        self._connected = False
        self.bus.close()

    def __enter__(self) -> Self:
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- commands (any thread; return at once)
    def _require(self) -> None:
        if not self._connected:
            why = f" ({self._link_error})" if self._link_error else ""
            raise NotConnected(
                f"{self.bus.port}: wx250s is not connected{why} (call connect() first)"
            )

    def follow(self, trajectory: JointTrajectory) -> Goal:
        """Validate and start streaming ``trajectory`` (arm joints); never blocks."""
        names = tuple(j.name for j in self.joints)
        if not self._connected:
            return Goal.failed(
                "follow", f"{self.bus.port}: wx250s is not connected (call connect() first)"
            )
        if set(trajectory.joint_names) != set(names) or len(trajectory.joint_names) != len(names):
            return Goal.failed(
                "follow", f"trajectory joints {trajectory.joint_names} do not match {names}"
            )
        order = [trajectory.joint_names.index(n) for n in names]
        points = [tuple(float(p[k]) for k in order) for p in trajectory.positions]
        traj = JointTrajectory(names, trajectory.times, tuple(points))
        with self._lock:
            if self._faults:
                return Goal.failed("follow", self._fault_text())
            state = self._state
        q0 = state.positions if state is not None else points[0]
        problem = check_limits(self.joints, q0, traj)
        if problem:
            return Goal.failed("follow", problem)
        goal = Goal("wx250s.follow", on_cancel=self._on_cancel)
        with self._lock:
            prev = self._traj
            self._traj = _TrajRun(goal, traj, self.clock.now(), tuple(q0))
        if prev is not None:
            prev.goal.mark_cancelled("preempted by a new trajectory")
        return goal

    def stop(self) -> None:
        """Cancel any trajectory and hold the present position."""
        with self._lock:
            run = self._traj
        if run is not None:
            run.goal.cancel()
        else:
            self._request(self._hold_request)

    def _on_cancel(self, goal: Goal) -> None:
        # the I/O thread notices CANCELLING, holds and marks the goal cancelled
        if not self._connected or self._thread is None:
            goal.mark_cancelled("cancelled (driver not running)")

    def gripper_move(self, width: float, force: float) -> Goal:
        """Drive the gripper toward ``width`` [m] in PWM mode with a PWM set from ``force`` [N]."""
        cfg = self.config
        if not self._connected:
            return Goal.failed(
                "gripper", f"{self.bus.port}: wx250s is not connected (call connect() first)"
            )
        lo, hi = 2 * FINGER_MIN, 2 * FINGER_MAX
        if not lo - 1e-9 <= width <= hi + 1e-9:
            return Goal.failed("gripper", f"width {width:.4f} m outside {lo:.3f}..{hi:.3f} m")
        with self._lock:
            if GRIPPER.id in self._faults:
                return Goal.failed("gripper", self._fault_text())
            reading = self._readings.get(GRIPPER.id)
        if reading is None:
            return Goal.failed("gripper", "no gripper state yet")
        target = gripper_angle_for_width(min(max(width, lo), hi))
        frac = min(max(force, 0.0) / cfg.gripper_max_force, 1.0)
        mag = round(cfg.gripper_pwm_min + frac * (cfg.gripper_pwm_max - cfg.gripper_pwm_min))
        closing = target < reading.position
        goal = Goal("wx250s.gripper", on_cancel=self._on_cancel)
        with self._lock:
            prev = self._grip
            self._grip = _GripRun(goal, target, -mag if closing else mag, closing, self.clock.now())
        if prev is not None:
            prev.goal.mark_cancelled("preempted by a new gripper command")
        return goal

    def reboot(self, joint: str) -> Goal:
        """Reboot one joint's servo (its shadow follows), then restore goal and torque."""
        ids = [i for i, n in self.name_of.items() if n == joint]
        if not ids:
            return Goal.failed(
                "reboot",
                f"unknown joint {joint!r} (known: {', '.join(sorted(set(self.name_of.values())))})",
            )
        return self._reboot_goal(ids)

    def smart_reboot(self) -> Goal:
        """Read Hardware Error Status of every servo and reboot only those reporting one."""
        return self._reboot_goal(None)

    def _reboot_goal(self, ids: list[int] | None) -> Goal:
        goal = Goal("wx250s.reboot")
        if not self._connected:
            goal.fail(f"{self.bus.port}: wx250s is not connected (call connect() first)")
            return goal

        state: dict[str, object] = {"targets": None, "since": 0.0}
        reboot_timeout = self.config.reboot_timeout

        def work() -> bool:
            """One step per cycle: reboot, then ping (one try per cycle) until every rebooted
            servo answers, then restore goal = present and torque. True when finished."""
            try:
                targets = state["targets"]
                if targets is None:
                    targets = ids
                    if targets is None:
                        targets = [i for i in self.servo_ids() if self._read(i, "hardware_error_status")]
                    for i in targets:
                        self.bus.reboot(i)
                    # the reboot goal's deadline is on the injected clock (a goal deadline, not
                    # a link reply deadline: each ping has its own, on wall time, in DxlBus)
                    state["targets"], state["since"] = targets, self.clock.now()
                assert isinstance(targets, list)
                for i in targets:
                    try:
                        self.bus.ping(i)
                    except (NoReply, DxlLinkError, ServoError) as e:
                        if isinstance(e, LinkLost):
                            raise
                        waited = self.clock.now() - float(state["since"])  # type: ignore[arg-type]
                        if waited > reboot_timeout:
                            goal.fail(
                                f"servo id {i} ({self.name_of.get(i, i)}) did not come back "
                                f"within {reboot_timeout:.1f} s after reboot: {e}"
                            )
                            return True
                        return False
                self._restore_after_reboot(targets)
                goal.succeed(tuple(self.name_of.get(i, str(i)) for i in targets))
            except LinkLost:
                raise
            except DynamixelError as e:
                goal.fail(f"reboot failed: {e}")
            return True

        self._request(work)
        return goal

    def _hold_request(self) -> bool:
        self._hold_present()
        return True

    def _restore_after_reboot(self, targets: list[int]) -> None:
        assert self._io is not None
        readings = self._io.read_state()
        for i in targets:
            j = self.by_id.get(i)
            if j is not None and j in self.position_joints and i in readings:
                p = min(max(readings[i].raw_position, j.min_pulses), j.max_pulses)
                self._write(i, "goal_position", p)
                with self._lock:
                    self._goals_pulses[self.position_joints.index(j)] = p
            self._write(i, "torque_enable", 1)
            if i in self.watchdog_ids:
                # a Reboot resets RAM: Goal PWM 0 and the Bus Watchdog off; arm it again
                self._write(i, "bus_watchdog", self.config.bus_watchdog_units)
            if i == GRIPPER.id:
                self._grip_pwm = 0
        with self._lock:
            for i in targets:
                self._faults.pop(i, None)
                master = next((j.id for j in self.all_joints if j.shadow == i), None)
                if master is not None:
                    self._faults.pop(master, None)

    def _request(self, fn: Callable[[], bool]) -> None:
        """Queue ``fn`` for the I/O thread; it runs once per cycle until it returns True."""
        with self._lock:
            self._requests.append(fn)

    # -- state
    def joint_state(self) -> JointState:
        with self._lock:
            st = self._state
        if st is None:
            raise NotConnected(f"{self.bus.port}: no joint state yet (call connect() first)")
        return st

    def gripper_state(self) -> GripperState:
        with self._lock:
            r = self._readings.get(GRIPPER.id)
            run = self._grip
            last = self._grip_state
            fault = ", ".join(self._faults.get(GRIPPER.id, ()))
        if r is None:
            raise NotConnected(f"{self.bus.port}: no gripper state yet (call connect() first)")
        grasp = (
            GraspState.MOVING
            if run is not None
            else (last.grasp if last else GraspState.AT_POSITION)
        )
        return GripperState(
            gripper_width(max(-math.pi / 2, min(math.pi / 2, r.position))),
            grasp,
            self.clock.now(),
            fault,
        )

    def _update_state(self, readings: dict[int, ServoReading]) -> None:
        self._readings.update(readings)
        js = [self._readings[j.id] for j in self.joints if j.id in self._readings]
        if len(js) == len(self.joints):
            self._state = JointState(
                tuple(j.name for j in self.joints),
                tuple(r.position for r in js),
                tuple(r.velocity for r in js),
                tuple(r.effort for r in js),
                self.clock.now(),
            )

    def _fault_text(self) -> str:
        parts = [
            f"servo id {i} ({self.name_of.get(i, i)}): {', '.join(f)}"
            for i, f in sorted(self._faults.items())
        ]
        return (
            f"hardware fault on {self.bus.port}: "
            + "; ".join(parts)
            + " (call reboot(joint) or smart_reboot())"
        )

    # -- I/O thread
    def _run(self) -> None:
        # paced on wall time, not the injected clock: the cycle is the bus traffic that
        # refreshes the servos' Bus Watchdog, which counts real milliseconds
        period = 1.0 / self.config.rate_hz
        next_t = time.monotonic()
        try:
            while not self._stop.is_set():
                self._cycle()
                next_t += period
                delay = next_t - time.monotonic()
                if delay < -period:
                    next_t = time.monotonic()
                    delay = 0.0
                if delay > 0:
                    self._stop.wait(delay)
        except LinkLost as e:
            self._link_error = f"link lost: {e}"
            log.error("%s", self._link_error)
            self._finish_goals(self._link_error)
            self._connected = False
        except Exception as e:
            self._link_error = f"driver error: {e}"
            log.exception("%s: I/O thread failed", self.bus.port)
            self._finish_goals(self._link_error)
            self._connected = False

    def _finish_goals(self, reason: str, *, cancelled: bool = False) -> None:
        with self._lock:
            runs = [r.goal for r in (self._traj, self._grip) if r is not None]
            self._traj = self._grip = None
            reqs, self._requests = self._requests, []
        for g in runs:
            if cancelled:
                g.mark_cancelled(reason)
            else:
                g.fail(reason)
        if self._head is not None:
            self._head._finish(reason, cancelled=cancelled)
        if reqs:
            log.debug("%d pending requests dropped: %s", len(reqs), reason)

    def _hold_present(self, joints: Sequence[JointSpec] | None = None) -> None:
        """Goal = present position (last reading) for ``joints`` (default: every position
        joint); the others keep their goals."""
        assert self._io is not None
        with self._lock:
            goals = list(self._goals_pulses)
            for k, j in enumerate(self.position_joints):
                if joints is not None and j not in joints:
                    continue
                r = self._readings.get(j.id)
                p = r.raw_position if r is not None else self._goals_pulses[k]
                goals[k] = min(max(p, j.min_pulses), j.max_pulses)
            self._goals_pulses = goals
        self._io.write_goals(goals)
        self._sent_goals = list(goals)

    def _cycle(self) -> None:
        assert self._io is not None
        with self._lock:
            reqs, self._requests = self._requests, []
        unfinished = [fn for fn in reqs if not fn()]
        if unfinished:
            with self._lock:
                self._requests[:0] = unfinished
        now = self.clock.now()
        self._advance_trajectory(now)
        with self._lock:
            goals = list(self._goals_pulses)
        if goals != self._sent_goals:
            # Sync Write only when a goal changed (every cycle while streaming)
            self._io.write_goals(goals)
            self._sent_goals = goals
        self._advance_gripper_pwm()
        try:
            readings = self._io.read_state()
            self._missed = 0
        except LinkLost:
            raise
        except DxlLinkError as e:
            partial = getattr(e, "received", {})
            readings = {i: self._io.decode(i, st) for i, st in partial.items()}
            self._missed += 1
            if self._missed >= self.config.max_missed_cycles:
                who = f" ({self.name_of.get(e.id, '')})" if e.id is not None else ""
                self._fail_running(f"{e}{who} for {self._missed} cycles")
        with self._lock:
            self._update_state(readings)
        self._check_watchdog()
        alerts = [i for i, r in readings.items() if r.error & codec.ALERT_BIT]
        if alerts:
            self._on_alerts(alerts)
        self._check_trajectory_done(self.clock.now())
        self._check_gripper(self.clock.now())
        if self._head is not None:
            self._head._on_cycle(self.clock.now())

    def _fail_running(self, reason: str) -> None:
        with self._lock:
            runs = [r.goal for r in (self._traj, self._grip) if r is not None]
            self._traj = self._grip = None
        for g in runs:
            g.fail(reason)
        if self._head is not None:
            self._head._finish(reason)
        if runs:
            self._hold_present()

    def _on_alerts(self, ids: list[int]) -> None:
        new = {}
        for i in ids:
            if i in self._faults:
                continue
            try:
                names = self.bus.hardware_error(i)
            except DxlLinkError as e:
                names = (f"alert (Hardware Error Status unreadable: {e.detail})",)
            new[i] = names or ("alert",)
        if not new:
            return
        with self._lock:
            self._faults.update(new)
            text = self._fault_text()
        log.error("%s", text)
        self._fail_running(text)
        self._hold_present()

    def _advance_trajectory(self, now: float) -> None:
        with self._lock:
            run = self._traj
        if run is None:
            return
        if run.goal.state is GoalState.CANCELLING:
            with self._lock:
                self._traj = None
            self._hold_present(self.joints)  # the arm's joints: a moving head goes on
            run.goal.mark_cancelled("cancelled: holding position")
            return
        t = now - run.start
        traj = run.traj
        if t < traj.times[0]:
            a = t / traj.times[0]
            q = [x0 + a * (x1 - x0) for x0, x1 in zip(run.q0, traj.positions[0])]
        else:
            q = list(traj.sample(t))
        pulses = [
            min(max(rad_to_pulses(x), j.min_pulses), j.max_pulses) for x, j in zip(q, self.joints)
        ]
        with self._lock:
            self._goals_pulses[: len(pulses)] = pulses

    def _check_trajectory_done(self, now: float) -> None:
        with self._lock:
            run = self._traj
            st = self._state
        if run is None or st is None or run.goal.state is not GoalState.ACTIVE:
            return
        t = now - run.start
        if t < run.traj.duration:
            return
        errs = [abs(a - b) for a, b in zip(st.positions, run.traj.positions[-1])]
        worst = int(np.argmax(errs))
        if errs[worst] <= self.config.tolerance:
            with self._lock:
                self._traj = None
            run.goal.succeed(st)
        elif t > run.traj.duration + self.config.settle_timeout:
            with self._lock:
                self._traj = None
            self._hold_present(self.joints)
            run.goal.fail(
                f"did not reach the last waypoint within {self.config.settle_timeout:.2f} s: "
                f"{self.joints[worst].name} off by {errs[worst]:.3f} rad"
            )

    def _advance_gripper_pwm(self) -> None:
        with self._lock:
            run = self._grip
        want = self._grip_pwm
        if run is not None and run.goal.state is GoalState.CANCELLING:
            with self._lock:
                self._grip = None
            want = 0
            self._send_gripper_pwm(0)
            self._grip_pwm = 0
            run.goal.mark_cancelled("cancelled: gripper stopped")
            return
        if run is not None and not run.sent:
            want = run.pwm
            run.sent = True
            if self._grip_pwm == 0 and self._watchdog_tripped(GRIPPER.id):
                # fired while the gripper was idle (nothing was pushing, so nothing to
                # undo); cleared before the goal write, which it would refuse
                log.warning(
                    "%s: servo id %d (gripper): Bus Watchdog had fired while idle; clearing it",
                    self.bus.port,
                    GRIPPER.id,
                )
                try:
                    self._rearm_watchdog(GRIPPER.id)
                except (NoReply, CorruptReply) as e:
                    # the goal write below is then refused, and this cycle's check fails
                    # the goal naming the watchdog
                    log.warning("%s: could not clear the Bus Watchdog: %s", self.bus.port, e)
        if want != self._grip_pwm:
            self._send_gripper_pwm(want)
            self._grip_pwm = want

    # -- Bus Watchdog (servos in WATCHDOG_MODES; the I/O thread only)
    def _watchdog_tripped(self, dxl_id: int) -> bool:
        """True when ``dxl_id``'s Bus Watchdog reads -1 (fired). A missing or corrupt reply
        counts as not known to have fired (the next check asks again)."""
        if dxl_id not in self.watchdog_ids:
            return False
        try:
            value = self._read(dxl_id, "bus_watchdog")
        except LinkLost:
            raise
        except (NoReply, CorruptReply) as e:
            log.debug("%s: Bus Watchdog check skipped: %s", self.bus.port, e)
            return False
        return value == BUS_WATCHDOG_TRIPPED

    def _rearm_watchdog(self, dxl_id: int) -> None:
        """Write 0 (clears the watchdog error: goal writes are accepted again), then arm it."""
        self._write(dxl_id, "bus_watchdog", 0)
        self._write(dxl_id, "bus_watchdog", self.config.bus_watchdog_units)
        self.watchdog_trips += 1

    def _check_watchdog(self) -> None:
        """Every cycle while the gripper is driven (Goal PWM not 0): did its Bus Watchdog fire?

        It fires when the host sent nothing for ``bus_watchdog_ms`` (a stalled host, a link
        gap); the servo then zeroed its Goal PWM. A running gripper move FAILS naming the
        watchdog (it is not resumed behind the caller's back; the caller may retry); a
        squeeze held on a grasped object (the goal already succeeded) is restored. Either
        way the watchdog is cleared and armed again.
        """
        if self._grip_pwm == 0 or not self._watchdog_tripped(GRIPPER.id):
            return
        cfg = self.config
        reason = (
            f"{self.bus.port}: servo id {GRIPPER.id} (gripper): Bus Watchdog fired (no "
            f"instruction for more than {cfg.watchdog_ms} ms): the gripper stopped"
        )
        with self._lock:
            run, self._grip = self._grip, None
        squeeze = self._grip_pwm if run is None else 0
        if run is not None:
            run.goal.fail(f"{reason}; the move was abandoned")
        log.warning("%s%s", reason, "; squeeze restored" if squeeze else "")
        try:
            self._rearm_watchdog(GRIPPER.id)
            self._send_gripper_pwm(squeeze)
        except (NoReply, CorruptReply) as e:
            # the watchdog still reads -1: the next goal write (or, while squeezing, the
            # next cycle's check) clears it again
            log.warning("%s: could not clear the Bus Watchdog yet: %s", self.bus.port, e)
        self._grip_pwm = squeeze

    def _check_gripper(self, now: float) -> None:
        cfg = self.config
        with self._lock:
            run = self._grip
            r = self._readings.get(GRIPPER.id)
        if run is None or r is None or not run.sent or run.goal.state is not GoalState.ACTIVE:
            return
        run.cycles += 1
        reached = (
            (r.position <= run.target_angle) if run.closing else (r.position >= run.target_angle)
        )
        width = gripper_width(max(-math.pi / 2, min(math.pi / 2, r.position)))
        near = abs(width - gripper_width(run.target_angle)) <= cfg.gripper_width_tolerance
        run.still = run.still + 1 if abs(r.velocity) < 0.03 else 0
        result: GraspState | None = None
        if reached or (near and run.still >= 2):
            result = GraspState.AT_POSITION
        elif run.cycles >= 3 and run.still >= 3:
            if abs(r.effort) >= cfg.gripper_load_threshold:
                result = GraspState.CONTACT_CLOSING if run.closing else GraspState.CONTACT_OPENING
            else:
                result = GraspState.AT_POSITION
        if result is None:
            if now - run.start > cfg.gripper_timeout:
                with self._lock:
                    self._grip = None
                self._send_gripper_pwm(0)
                self._grip_pwm = 0
                run.goal.fail(
                    f"gripper did not stop within {cfg.gripper_timeout:.1f} s (width {width:.4f} m)"
                )
            return
        if result is GraspState.AT_POSITION:
            # free fingers: stop pushing. On an object: keep squeezing at the commanded PWM.
            self._send_gripper_pwm(0)
            self._grip_pwm = 0
        state = GripperState(width, result, now)
        with self._lock:
            self._grip = None
            self._grip_state = state
        run.goal.succeed(state)


def check_limits(joints: Sequence[JointSpec], q0: Sequence[float], traj: JointTrajectory) -> str:
    """ "" when ``traj`` (joints in ``joints`` order, starting from ``q0``) respects every
    joint's range and velocity limit, else a one-line reason naming the joint."""
    prev_t, prev_q = 0.0, tuple(q0)
    for i, (t, q) in enumerate(zip(traj.times, traj.positions)):
        for j, x in zip(joints, q):
            if not math.isfinite(x):
                return f"waypoint {i}: {j.name} is not a finite number"
            if not j.lower - 1e-9 <= x <= j.upper + 1e-9:
                return (
                    f"waypoint {i}: {j.name} = {x:.4f} rad outside its limits "
                    f"[{j.lower:.4f}, {j.upper:.4f}] rad; nothing was sent"
                )
        dt = t - prev_t
        for j, a, b in zip(joints, prev_q, q):
            v = abs(b - a) / dt
            if v > j.velocity * (1 + 1e-6):
                return (
                    f"waypoint {i}: {j.name} would move at {v:.3f} rad/s, above its limit "
                    f"{j.velocity:.3f} rad/s; nothing was sent"
                )
        prev_t, prev_q = t, q
    return ""
