"""A DYNAMIXEL Protocol 2.0 bus on a pseudo-terminal: servos that speak the real protocol.

Use it to rehearse bring-up without an arm (``mmexec hw fake dynamixel`` prints the port)
and in tests. :class:`FakeDxlBus` parses instruction packets (with byte stuffing) from the
driver and answers like X-series servos (docs/protocols.md section 2.6):

* one :class:`FakeServo` per id, built from the vendor's tables (model numbers of the ROBOTIS
  e-Manual, the WX250s / LoCoBot bus of docs/protocols.md 2.5; never from the driver's
  model.py), with the X-series register layout of :mod:`mmexec.drivers.dynamixel.control_table`;
  EEPROM locked while torque is on (error 7), position limits (error 6), data length (5),
  data range (4: bad operating mode, goal write after the bus watchdog fired), unknown
  instruction or Action without Reg Write (2);
* Ping, Read, Write, Reg Write + Action, Reboot, Factory Reset, Clear, Sync Read/Write,
  Bulk Read/Write; broadcast; Status Return Level; Return Delay Time; Secondary (shadow) ID:
  a shadow executes what its master receives and never answers; Sync Read answered in
  list order;
* motion: in position modes the present position moves linearly from where it was to the
  goal over the profile time (time-based profile: Profile Velocity in ms; velocity-based:
  at Profile Velocity, or the Velocity Limit when 0), never faster than the Velocity Limit;
  in PWM mode it moves at ``goal_pwm / pwm_limit * velocity_limit`` until a mechanical stop
  or an injected obstacle, where it stalls and reports load.

Fault switches (attributes or methods on :class:`FakeDxlBus`):

* :meth:`FakeDxlBus.inject_hardware_error` (``"overload"``, ``"overheating"``, ...): sets the
  bit in Hardware Error Status; if it is enabled in Shutdown the servo drops torque and sets
  the alert bit in every status until a Reboot;
* ``servo.present = False``: a missing servo (never answers);
* ``corrupt_replies`` / ``truncate_replies``: how many of the next status packets get a
  wrong CRC / are cut short; ``corrupt_every`` / ``drop_every``: every n-th status packet
  gets a wrong CRC / is never sent (a noisy bus, for link-quality tests; 0 = off);
* ``corrupt_instructions``: how many of the next instructions arrive corrupted; the servo
  answers with error 3 if ``crc_error_reply`` is True, else stays silent (which one real
  X-series firmware does is unconfirmed, so the driver is tested both ways);
* ``reboot_time``: seconds a servo stays silent while it restarts after a Reboot;
* Bus Watchdog (address 98, ROBOTIS e-Manual): armed with 1-127 (x 20 ms) while torque is on,
  it fires when no instruction packet reached the servo for longer than that: the servo
  stops (Goal PWM, Goal Velocity and Goal Current become 0, a position mode holds where it
  is; torque stays on), the register reads -1 and goal writes answer data range error
  until 0 is written to it. The motion model runs up to the moment it fired, so the
  position shows how far the servo went after the host fell silent; the fake's own tick
  (every 20 ms, servos with an armed watchdog) and :meth:`FakeDxlBus.register` advance it
  without any traffic.
  :meth:`FakeDxlBus.expire_watchdog` fires it at once. Which packets refresh it: the
  e-Manual counts "all the Instruction Packet"; whether one addressed to other ids counts is
  unconfirmed, so the fake takes the stricter reading: only a packet that addresses the
  servo (its id or secondary id, broadcast, or listed in a Sync/Bulk Read/Write).
* and the :class:`~mmexec.drivers.fakes.pty.PtyDevice` switches: ``silent``, ``unplug()``, ``inject()``.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Iterable, Sequence

from mmexec.drivers.dynamixel import codec
from mmexec.drivers.dynamixel.codec import (
    BROADCAST_ID,
    BadFrame,
    CodecError,
    Instruction,
    Packet,
    StatusResult,
)
from mmexec.drivers.dynamixel.control_table import (
    BUS_WATCHDOG_TRIPPED,
    BUS_WATCHDOG_UNIT_S,
    XL430_W250,
    XM430_W350,
    Area,
    Model,
    OperatingMode,
    encode_hardware_error,
    rad_to_pulses,
)
from mmexec.drivers.dynamixel.model import gripper_angle_for_width
from mmexec.drivers.fakes.pty import PtyDevice

__all__ = ["VENDOR_MODEL_NUMBERS", "FakeDxlBus", "FakeServo", "servos_from_ids", "wx250s_servos"]

log = logging.getLogger(__name__)

_MEM_SIZE = 160
_ALERT = 0x80
#: pulses per second per velocity unit (0.229 rev/min)
_PULSES_S_PER_UNIT = 0.229 * 4096.0 / 60.0

# The servo facts below are copied from the vendor documents (docs/protocols.md 2.4-2.5,
# the ROBOTIS e-Manual control tables, DynamixelSDK's dynamixel_item.h), not from the
# driver's model (mmexec.drivers.dynamixel.model): a fake that reads the driver's table
# agrees with the driver's mistakes. Only the register layout is shared
# (control_table.py; the X-series addresses are the same on every model here).

#: Model Number register (address 0) per servo, from the ROBOTIS e-Manual control tables.
VENDOR_MODEL_NUMBERS: dict[str, int] = {
    "XM430-W350": 1020,
    "XM430-W210": 1030,
    "XL430-W250": 1060,
    "XC430-W150": 1070,
    "XC430-W240": 1080,
    "2XL430-W250": 1090,  # dual-axis unit: the same number on both of its ids
    "XM540-W270": 1120,
    "XM540-W150": 1130,
}
#: register layout per servo: XM / XM540 report Present Current at 126, the XL430 family
#: (XL430, 2XL430, XC430) Present Load, and has no current-control modes
_LAYOUT: dict[str, Model] = {
    name: XM430_W350 if name.startswith("XM") else XL430_W250 for name in VENDOR_MODEL_NUMBERS
}

#: The WX250s bus (docs/protocols.md 2.5): id, servo, Drive Mode bit 0 (reversed),
#: Secondary ID (255: none), Min / Max Position Limit [pulses], joint index in the sleep
#: pose (a shadow sits where its primary does; None: 2048 pulses)
_WX250S_BUS: tuple[tuple[int, str, int, int, int, int, int | None], ...] = (
    (1, "XM430-W350", 0, 255, 0, 4095, 0),  # waist
    (2, "XM430-W350", 0, 255, 819, 3345, 1),  # shoulder
    (3, "XM430-W350", 1, 2, 819, 3345, 1),  # shoulder_shadow
    (4, "XM430-W350", 0, 255, 648, 3094, 2),  # elbow
    (5, "XM430-W350", 1, 4, 648, 3094, 2),  # elbow_shadow
    (6, "XM430-W350", 0, 255, 0, 4095, 3),  # forearm_roll
    (7, "XM430-W350", 1, 255, 910, 3447, 4),  # wrist_angle
    (8, "XL430-W250", 0, 255, 0, 4095, 5),  # wrist_rotate
    (9, "XL430-W250", 0, 255, 0, 4095, None),  # gripper
)
#: the LoCoBot's pan (10) and tilt (11): the two ids of one 2XL430-W250
_LOCOBOT_HEAD: tuple[tuple[int, int, int, int, int], ...] = (
    (10, 0, 255, 1024, 3072),
    (11, 1, 255, 1024, 3072),
)
#: sleep poses [rad], waist .. wrist_rotate (docs/protocols.md 2.5)
_SLEEP = (0.0, -1.80, 1.55, 0.0, 0.8, 0.0)
_LOCOBOT_SLEEP = (0.0, -1.1, 1.55, 0.0, 0.5, 0.0)


class FakeServo:
    """One simulated X-series servo: control-table memory plus a simple motion model.

    ``servo`` is the vendor's name (a key of :data:`VENDOR_MODEL_NUMBERS`); it sets the
    Model Number the servo reports and its register layout (:attr:`model`). ``stops`` are
    mechanical end stops [pulses] (e.g. the gripper fingers), ``obstacle`` an injected
    object position [pulses] that stalls motion toward it.
    """

    def __init__(
        self,
        dxl_id: int,
        servo: str = "XM430-W350",
        *,
        position: int = 2048,
        stops: tuple[int, int] | None = None,
    ) -> None:
        if servo not in VENDOR_MODEL_NUMBERS:
            raise ValueError(f"unknown servo {servo!r} (known: {', '.join(VENDOR_MODEL_NUMBERS)})")
        self.servo = servo
        self.model_number = VENDOR_MODEL_NUMBERS[servo]
        self.model = _LAYOUT[servo]
        self.present = True
        self.stops = stops
        self.obstacle: int | None = None
        self.booting_until = 0.0  # time.monotonic() until which a rebooting servo is silent
        self._obstacle_dir = 0
        self._factory_id = dxl_id
        self.mem = bytearray(_MEM_SIZE)
        self._reset_memory(keep_id=False, keep_baud=False)
        self._set("id", dxl_id)
        self._set("baud_rate", 3)
        self.pos = float(position)
        self.vel = 0.0  # [velocity units]
        self.load = 0  # [0.1 % or current units]
        self._from = self.pos
        self._goal = self.pos
        self._t0 = 0.0
        self._dur = 0.0
        self._last = time.monotonic()
        #: time.monotonic() of the last instruction packet that addressed this servo, and
        #: its present position [pulses] then
        self.last_instruction = self._last
        self.position_at_last_instruction = self.pos
        #: times the Bus Watchdog fired, and the position [pulses] each time it did
        self.watchdog_fires: list[tuple[float, float]] = []
        #: every Goal Position [pulses] this servo accepted, in order (bounded)
        self.goal_log: list[int] = []
        self.registered: tuple[int, bytes] | None = None
        self._store_motion()

    # -- memory helpers
    def _reset_memory(self, *, keep_id: bool, keep_baud: bool) -> None:
        keep = {n: self.get(n) for n, k in (("id", keep_id), ("baud_rate", keep_baud)) if k}
        for r in self.model.registers:
            self.mem[r.address : r.address + r.size] = (
                r.default & ((1 << (8 * r.size)) - 1)
            ).to_bytes(r.size, "little")
        self._set("model_number", self.model_number)
        for n, v in keep.items():
            self._set(n, v)

    def get(self, name: str) -> int:
        r = self.model.reg(name)
        return int.from_bytes(self.mem[r.address : r.address + r.size], "little", signed=r.signed)

    def _set(self, name: str, value: int) -> None:
        r = self.model.reg(name)
        self.mem[r.address : r.address + r.size] = codec.int_to_le(int(value), r.size)

    @property
    def id(self) -> int:
        return self.get("id")

    @property
    def secondary_id(self) -> int:
        return self.get("secondary_id")

    @property
    def torque(self) -> bool:
        return self.get("torque_enable") == 1

    @property
    def hardware_error(self) -> int:
        return self.get("hardware_error_status")

    @property
    def alert(self) -> bool:
        return bool(self.hardware_error & self.get("shutdown"))

    # -- motion model
    def _vmax(self) -> float:
        v = self.get("velocity_limit")
        return float(v if v > 0 else 1023)

    def update(self, now: float) -> None:
        """Advance to ``now`` (time.monotonic()); a Bus Watchdog that expired on the way
        fires at its moment, with the motion before it and the stop after it."""
        wd = self.get("bus_watchdog")
        if wd > 0 and self.torque:
            expiry = self.last_instruction + wd * BUS_WATCHDOG_UNIT_S
            if expiry < now:
                self._move(max(expiry, self._last))
                self._watchdog_fire(max(expiry, self._last))
        self._move(now)

    def _move(self, now: float) -> None:
        dt = now - self._last
        if dt <= 0.0:
            return
        self._last = now
        mode = self.get("operating_mode")
        if not self.torque:
            self.vel, self.load = 0.0, 0
        elif mode == OperatingMode.PWM:
            pwm = self.get("goal_pwm")
            limit = max(1, self.get("pwm_limit"))
            v = max(-1.0, min(1.0, pwm / limit)) * self._vmax()
            step = v * _PULSES_S_PER_UNIT * dt
            new = self.pos + step
            blocked = False
            obs = self.obstacle
            if obs is not None and step != 0:
                direction = 1 if step > 0 else -1
                if (self.pos < obs <= new) or (new <= obs < self.pos):
                    new, blocked, self._obstacle_dir = float(obs), True, direction
                elif self.pos == obs and direction == self._obstacle_dir:
                    new, blocked = float(obs), True
            if self.stops is not None:
                lo, hi = self.stops
                if step < 0 and new <= lo:
                    new, blocked = float(lo), True
                elif step > 0 and new >= hi:
                    new, blocked = float(hi), True
            self.vel = 0.0 if blocked else v
            self.load = round(1000 * pwm / limit) if blocked else round(100 * pwm / limit)
            self.pos = new
        else:
            if self._dur <= 0 or now >= self._t0 + self._dur:
                self.pos, self.vel = self._goal, 0.0
            else:
                a = (now - self._t0) / self._dur
                self.pos = self._from + a * (self._goal - self._from)
                self.vel = (self._goal - self._from) / self._dur / _PULSES_S_PER_UNIT
            self.load = round(self.vel * 2)
        self._store_motion()

    def _store_motion(self) -> None:
        self._set("present_position", round(self.pos))
        self._set("present_velocity", round(self.vel))
        self._set(
            "present_load" if self.model.has("present_load") else "present_current", self.load
        )
        moving = 1 if abs(self.vel) > 0.5 else 0
        self._set("moving", moving)
        self._set("moving_status", 0 if moving else 1)

    def _start_move(self, goal: int, now: float) -> None:
        self._from, self._goal, self._t0 = self.pos, float(goal), now
        dist = abs(self._goal - self._from)
        pulses_per_s_per_unit = _PULSES_S_PER_UNIT
        t_vmax = dist / (self._vmax() * pulses_per_s_per_unit)
        pv = self.get("profile_velocity")
        if self.get("drive_mode") & 0x04:
            t = pv / 1000.0
        else:
            t = dist / (pv * pulses_per_s_per_unit) if pv > 0 else t_vmax
        self._dur = max(t, t_vmax)

    def hold(self, now: float) -> None:
        self.update(now)
        self._goal = self._from = self.pos
        self._dur = 0.0
        self._set("goal_position", round(self.pos))

    def _watchdog_fire(self, when: float) -> None:
        """The Bus Watchdog fires (motion already advanced to ``when``): the servo stops,
        torque stays on, the register reads -1 (e-Manual, Bus Watchdog)."""
        for name in ("goal_pwm", "goal_velocity", "goal_current"):
            if self.model.has(name):
                self._set(name, 0)
        self._goal = self._from = self.pos
        self._dur = 0.0
        self.vel = 0.0
        self._store_motion()
        self._set("bus_watchdog", BUS_WATCHDOG_TRIPPED)
        self.watchdog_fires.append((when, self.pos))

    def fault(self, bits: int, now: float) -> None:
        self.update(now)
        self._set("hardware_error_status", self.hardware_error | bits)
        if bits & self.get("shutdown"):
            self.hold(now)
            self._set("torque_enable", 0)

    def reboot(self, now: float) -> None:
        self.update(now)
        self._set("hardware_error_status", 0)
        self._set("torque_enable", 0)
        self.hold(now)
        self._set("bus_watchdog", 0)
        self.registered = None

    # -- instruction semantics: return a result code
    def read(self, address: int, length: int, now: float) -> tuple[int, bytes]:
        self.update(now)
        if length <= 0 or address + length > _MEM_SIZE or not self.model.covering(address, 1):
            return StatusResult.ACCESS_ERROR, b""
        return 0, bytes(self.mem[address : address + length])

    def check_write(self, address: int, data: bytes) -> int:
        regs = self.model.covering(address, len(data))
        if not regs:
            return StatusResult.ACCESS_ERROR
        for r in regs:
            if r.address < address or r.address + r.size > address + len(data):
                return StatusResult.DATA_LENGTH_ERROR
            if not r.writable:
                return StatusResult.ACCESS_ERROR
            if r.area is Area.EEPROM and self.torque:
                return StatusResult.ACCESS_ERROR
            value = int.from_bytes(
                data[r.address - address : r.address - address + r.size], "little", signed=r.signed
            )
            if r.name == "operating_mode" and value not in self.model.operating_modes:
                return StatusResult.DATA_RANGE_ERROR
            if (
                r.name in ("goal_position", "goal_pwm", "goal_velocity", "goal_current")
                and self.get("bus_watchdog") == -1
            ):
                return StatusResult.DATA_RANGE_ERROR
            in_position_mode = self.get("operating_mode") == OperatingMode.POSITION
            lo, hi = self.get("min_position_limit"), self.get("max_position_limit")
            if r.name == "goal_position" and in_position_mode and not lo <= value <= hi:
                return StatusResult.DATA_LIMIT_ERROR
            if r.name == "goal_pwm" and abs(value) > self.get("pwm_limit"):
                return StatusResult.DATA_LIMIT_ERROR
            if r.name == "torque_enable" and value == 1 and self.alert:
                return StatusResult.RESULT_FAIL
        return 0

    def write(self, address: int, data: bytes, now: float) -> int:
        self.update(now)
        err = self.check_write(address, data)
        if err:
            return err
        torque_before = self.torque
        self.mem[address : address + len(data)] = data
        if not torque_before and self.torque:
            # torque on: hold where it is unless a goal is written in the same packet
            self.hold(now)
        if self.model.reg("goal_position").address in range(address, address + len(data)):
            if len(self.goal_log) < 10000:
                self.goal_log.append(self.get("goal_position"))
            if self.torque:
                self._start_move(self.get("goal_position"), now)
        return 0

    def touch(self, now: float) -> None:
        """An instruction packet addressed this servo (refreshes its Bus Watchdog); call
        after :meth:`update` to ``now``."""
        self.last_instruction = now
        self.position_at_last_instruction = self.pos

    def factory_reset(self, option: int, now: float) -> None:
        self.update(now)
        self._reset_memory(keep_id=option in (0x01, 0x02), keep_baud=option == 0x02)
        if option == 0xFF:
            self._set("id", 1)
        self.hold(now)


def wx250s_servos(
    *, locobot: bool = False, configured: bool = False, head: str = "2XL430-W250"
) -> list[FakeServo]:
    """The servos of a WX250s arm (ids 1-9; LoCoBot adds pan 10 and tilt 11) at the sleep pose.

    The table is the vendor's (docs/protocols.md 2.5), not the driver's. ``configured=False``
    leaves the EEPROM at factory values (apart from id and baud rate) so a driver's bring-up
    has to write them; True pre-applies the Interbotix settings. ``head`` is the servo of the
    LoCoBot's pan/tilt (a real LoCoBot: one 2XL430-W250, model 1090 on both ids).
    """
    sleep = _LOCOBOT_SLEEP if locobot else _SLEEP
    # finger end stops: 30 mm and 74 mm between the pads (docs/robots.md 1.3)
    grip_stops = (
        rad_to_pulses(gripper_angle_for_width(0.030)),
        rad_to_pulses(gripper_angle_for_width(0.074)),
    )
    bus = list(_WX250S_BUS)
    if locobot:
        bus += [(i, head, drive, sec, lo, hi, None) for i, drive, sec, lo, hi in _LOCOBOT_HEAD]
    servos = []
    for dxl_id, servo, drive, secondary, lo, hi, joint in bus:
        s = FakeServo(
            dxl_id,
            servo,
            position=2048 if joint is None else rad_to_pulses(sleep[joint]),
            stops=grip_stops if dxl_id == 9 else None,
        )
        if configured:
            s._set("return_delay_time", 0)
            s._set("drive_mode", drive | (0x04 if dxl_id <= 8 else 0))
            s._set("secondary_id", secondary)
            s._set("min_position_limit", lo)
            s._set("max_position_limit", hi)
            s._set("velocity_limit", 131)
            if dxl_id == 9:
                s._set("operating_mode", OperatingMode.PWM)
        servos.append(s)
    return servos


class FakeDxlBus(PtyDevice):
    """A multidrop bus of :class:`FakeServo` on a pty (see the module docstring)."""

    #: a servo with an armed Bus Watchdog also runs on this tick (one watchdog unit), not only
    #: when packets arrive, so it fires with no traffic at all
    tick_period = 0.02

    def __init__(
        self,
        servos: Iterable[FakeServo] | None = None,
        *,
        name: str = "fake-dxl",
        honour_return_delay: bool = True,
    ) -> None:
        super().__init__(name)
        self.servos: list[FakeServo] = list(servos) if servos is not None else wx250s_servos()
        self.honour_return_delay = honour_return_delay
        self.crc_error_reply = True
        self.corrupt_instructions = 0
        self.corrupt_replies = 0
        self.truncate_replies = 0
        self.corrupt_every = 0
        self.drop_every = 0
        self.status_packets = 0  # status packets the servos had to send (every-n-th switches)
        self.reboot_time = 0.0  # s a servo stays silent while restarting after Reboot
        self.goal_writes = 0  # packets that wrote Goal Position / Goal PWM to a servo
        self.instructions: list[tuple[int, int]] = []  # (id, instruction) received, bounded
        self._parser = codec.PacketParser()
        self._mlock = threading.Lock()

    # -- servo lookup
    def servo(self, dxl_id: int) -> FakeServo:
        for s in self.servos:
            if s.id == dxl_id:
                return s
        raise KeyError(f"no fake servo with id {dxl_id}")

    def _addressed(self, dxl_id: int) -> list[tuple[FakeServo, bool]]:
        """Servos that execute an instruction to ``dxl_id``: (servo, replies?)."""
        out = []
        now = time.monotonic()
        for s in self.servos:
            if not s.present or s.booting_until > now:
                continue
            if dxl_id == BROADCAST_ID:
                out.append((s, False))
            elif s.id == dxl_id:
                out.append((s, True))
            elif s.secondary_id == dxl_id:
                out.append((s, False))
        return out

    # -- fault injection
    def inject_hardware_error(self, dxl_id: int, *faults: str) -> None:
        with self._mlock:
            self.servo(dxl_id).fault(encode_hardware_error(faults), time.monotonic())

    def expire_watchdog(self, dxl_id: int) -> None:
        """Fire ``dxl_id``'s Bus Watchdog now (as if its period had just run out)."""
        with self._mlock:
            s = self.servo(dxl_id)
            now = time.monotonic()
            s.update(now)
            s._watchdog_fire(now)

    def register(self, dxl_id: int, name: str) -> int:
        """``name``'s value in servo ``dxl_id`` now: its motion and Bus Watchdog advanced to
        this moment (a test observing the servo while the host sends nothing)."""
        with self._mlock:
            s = self.servo(dxl_id)
            s.update(time.monotonic())
            return s.get(name)

    def set_obstacle(self, dxl_id: int, pulses: int | None) -> None:
        with self._mlock:
            self.servo(dxl_id).obstacle = pulses

    # -- device side
    def on_tick(self, now: float) -> None:
        with self._mlock:
            for s in self.servos:
                if s.get("bus_watchdog") > 0:
                    s.update(now)

    def on_bytes(self, data: bytes) -> None:
        with self._mlock:
            for item in self._parser.feed(data):
                self._handle(item)

    def _reply(self, servo: FakeServo, error: int, data: bytes = b"") -> None:
        self._send_status(self._status(servo, error, data))

    def _status(self, servo: FakeServo, error: int, data: bytes = b"") -> tuple[bytes, float]:
        """The status frame ``servo`` answers now, and its Return Delay [s]. Built before an
        instruction's effect (reboot, factory reset) and sent after it, so the host never
        sees a reply before the fake's state has changed."""
        if servo.alert:
            error |= _ALERT
        frame = codec.encode_status(servo.id, error, data)
        self.status_packets += 1
        n = self.status_packets
        noise = self.corrupt_every > 0 and n % self.corrupt_every == 0
        if self.drop_every > 0 and n % self.drop_every == 0:
            frame = b""  # lost on the bus
        elif noise or self.corrupt_replies > 0:
            if not noise:
                self.corrupt_replies -= 1
            frame = frame[:-1] + bytes((frame[-1] ^ 0x5A,))
        elif self.truncate_replies > 0:
            self.truncate_replies -= 1
            frame = frame[: len(frame) // 2]
        return frame, servo.get("return_delay_time") * 2e-6

    def _send_status(self, status: tuple[bytes, float]) -> None:
        frame, delay = status
        if not frame:
            return
        if self.honour_return_delay and delay > 0:
            time.sleep(delay)
        self.send(frame)

    def _handle(self, item: Packet | BadFrame) -> None:
        now = time.monotonic()
        if isinstance(item, Packet) and self.corrupt_instructions > 0:
            self.corrupt_instructions -= 1
            item = BadFrame(item.id, b"", "injected corruption")
        if isinstance(item, BadFrame):
            if self.crc_error_reply and item.id != BROADCAST_ID:
                for s, replies in self._addressed(item.id):
                    if replies:
                        self._reply(s, StatusResult.CRC_ERROR)
            return
        if item.is_status:
            return
        if len(self.instructions) < 10000:
            self.instructions.append((item.id, item.instruction))
        ids = _addressed_ids(item)
        for s in self.servos:
            s.update(now)  # a Bus Watchdog expires on the gap before this instruction
            if ids is None or s.id in ids or s.secondary_id in ids:
                s.touch(now)
        handler = _HANDLERS.get(item.instruction)
        if handler is None:
            for s, replies in self._addressed(item.id):
                if replies:
                    self._reply(s, StatusResult.INSTRUCTION_ERROR)
            return
        handler(self, item, now)

    def _count_goal(self, address: int, length: int) -> None:
        if address <= 116 < address + length or address <= 100 < address + length:
            self.goal_writes += 1

    # instruction handlers
    def _ping(self, p: Packet, now: float) -> None:
        for s, replies in sorted(self._addressed(p.id), key=lambda x: x[0].id):
            if replies or p.id == BROADCAST_ID:
                fw = s.get("firmware_version")
                self._reply(s, 0, codec.int_to_le(s.get("model_number"), 2) + bytes((fw,)))

    def _read(self, p: Packet, now: float) -> None:
        if len(p.params) != 4:
            return self._each_reply(p, StatusResult.DATA_LENGTH_ERROR)
        address, length = (
            int.from_bytes(p.params[:2], "little"),
            int.from_bytes(p.params[2:], "little"),
        )
        for s, replies in self._addressed(p.id):
            err, data = s.read(address, length, now)
            if replies and s.get("status_return_level") >= 1:
                self._reply(s, err, data)

    def _write(self, p: Packet, now: float) -> None:
        if len(p.params) < 3:
            return self._each_reply(p, StatusResult.DATA_LENGTH_ERROR)
        address, data = int.from_bytes(p.params[:2], "little"), p.params[2:]
        self._count_goal(address, len(data))
        out = []
        for s, replies in self._addressed(p.id):  # every servo acts, then the replies go out
            err = s.write(address, data, now)
            if replies and s.get("status_return_level") >= 2:
                out.append((s, err))
        for s, err in out:
            self._reply(s, err)

    def _reg_write(self, p: Packet, now: float) -> None:
        if len(p.params) < 3:
            return self._each_reply(p, StatusResult.DATA_LENGTH_ERROR)
        address, data = int.from_bytes(p.params[:2], "little"), p.params[2:]
        for s, replies in self._addressed(p.id):
            err = s.check_write(address, data)
            if not err:
                s.registered = (address, data)
                s._set("registered_instruction", 1)
            if replies and s.get("status_return_level") >= 2:
                self._reply(s, err)

    def _action(self, p: Packet, now: float) -> None:
        out = []
        for s, replies in self._addressed(p.id):
            if s.registered is None:
                err = StatusResult.INSTRUCTION_ERROR
            else:
                address, data = s.registered
                s.registered = None
                s._set("registered_instruction", 0)
                self._count_goal(address, len(data))
                err = s.write(address, data, now)
            if replies and s.get("status_return_level") >= 2:
                out.append((s, err))
        for s, err in out:
            self._reply(s, err)

    def _reboot(self, p: Packet, now: float) -> None:
        out = []
        for s, replies in self._addressed(p.id):
            if replies and s.get("status_return_level") >= 2:
                out.append(self._status(s, 0))  # answered as the servo was, sent after
            s.reboot(now)
            s.booting_until = now + self.reboot_time
        for status in out:
            self._send_status(status)

    def _factory_reset(self, p: Packet, now: float) -> None:
        option = p.params[0] if p.params else 0xFF
        out = []
        for s, replies in self._addressed(p.id):
            err = StatusResult.ACCESS_ERROR if s.torque else 0
            if replies:
                out.append(self._status(s, err))  # answered as the servo was, sent after
            if not err:
                s.factory_reset(option, now)
        for status in out:
            self._send_status(status)

    def _clear(self, p: Packet, now: float) -> None:
        ok = p.params == b"\x01" + codec.CLEAR_KEY
        for s, replies in self._addressed(p.id):
            s.update(now)
            err = (
                0
                if ok and s.vel == 0
                else (StatusResult.DATA_RANGE_ERROR if not ok else StatusResult.RESULT_FAIL)
            )
            if replies and s.get("status_return_level") >= 2:
                self._reply(s, err)

    def _sync_read(self, p: Packet, now: float) -> None:
        address, length, ids = codec.parse_sync_read(p.params)
        for dxl_id in ids:
            for s, replies in self._addressed(dxl_id):
                err, data = s.read(address, length, now)
                if replies and s.get("status_return_level") >= 1:
                    self._reply(s, err, data)

    def _sync_write(self, p: Packet, now: float) -> None:
        address, length, per_id = codec.parse_sync_write(p.params)
        self._count_goal(address, length)
        for dxl_id, data in per_id.items():
            for s, _ in self._addressed(dxl_id):
                s.write(address, data, now)

    def _bulk_read(self, p: Packet, now: float) -> None:
        for dxl_id, address, length in codec.parse_bulk_read(p.params):
            for s, replies in self._addressed(dxl_id):
                err, data = s.read(address, length, now)
                if replies and s.get("status_return_level") >= 1:
                    self._reply(s, err, data)

    def _bulk_write(self, p: Packet, now: float) -> None:
        for dxl_id, address, data in codec.parse_bulk_write(p.params):
            self._count_goal(address, len(data))
            for s, _ in self._addressed(dxl_id):
                s.write(address, data, now)

    def _each_reply(self, p: Packet, err: int) -> None:
        for s, replies in self._addressed(p.id):
            if replies:
                self._reply(s, err)


def _addressed_ids(p: Packet) -> set[int] | None:
    """Ids an instruction addresses (None: every servo, a broadcast); a Sync or Bulk
    instruction addresses the ids it lists (none if its parameters do not parse)."""
    try:
        if p.instruction in (Instruction.SYNC_READ, Instruction.SYNC_WRITE):
            if p.instruction == Instruction.SYNC_READ:
                return set(codec.parse_sync_read(p.params)[2])
            return set(codec.parse_sync_write(p.params)[2])
        if p.instruction == Instruction.BULK_READ:
            return {i for i, _, _ in codec.parse_bulk_read(p.params)}
        if p.instruction == Instruction.BULK_WRITE:
            return {i for i, _, _ in codec.parse_bulk_write(p.params)}
    except CodecError:
        return set()
    return None if p.id == BROADCAST_ID else {p.id}


_HANDLERS = {
    Instruction.PING: FakeDxlBus._ping,
    Instruction.READ: FakeDxlBus._read,
    Instruction.WRITE: FakeDxlBus._write,
    Instruction.REG_WRITE: FakeDxlBus._reg_write,
    Instruction.ACTION: FakeDxlBus._action,
    Instruction.REBOOT: FakeDxlBus._reboot,
    Instruction.FACTORY_RESET: FakeDxlBus._factory_reset,
    Instruction.CLEAR: FakeDxlBus._clear,
    Instruction.SYNC_READ: FakeDxlBus._sync_read,
    Instruction.SYNC_WRITE: FakeDxlBus._sync_write,
    Instruction.BULK_READ: FakeDxlBus._bulk_read,
    Instruction.BULK_WRITE: FakeDxlBus._bulk_write,
}


def servos_from_ids(ids: Sequence[int], servo: str = "XM430-W350") -> list[FakeServo]:
    """Plain servos with the given ids, all of one vendor model (for generic bus tests)."""
    return [FakeServo(i, servo) for i in ids]
