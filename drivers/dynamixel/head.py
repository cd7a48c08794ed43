"""The LoCoBot's pan/tilt head (servos 10 and 11, one 2XL430-W250) as a
:class:`~mmexec.drivers.interfaces.Head` on a :class:`~mmexec.drivers.dynamixel.wx250s.WX250s`.

The head shares the arm's U2D2 bus, bring-up and I/O thread: with ``locobot: true`` the
device brings both servos up in position mode with the Interbotix velocity profile (pi
rad/s, acceleration 15), writes their Min/Max Position Limit (1024..3072 pulses) so the
servos themselves refuse anything beyond, and streams their Goal Position in the same
Sync Write as the arm joints (only when a goal changed) and reads them in the same Sync
Read. This adapter adds the goals:

* :meth:`WX250sHead.point` checks both targets against the description's limits (pan
  +-pi/2, tilt -pi/2..1.309 rad: tighter than the register limits) and returns a FAILED
  goal naming the joint when one is outside, before anything is sent; otherwise it sets
  the two goal positions, which the next cycle writes. The I/O thread then checks the
  goal every cycle (:meth:`WX250sHead._on_cycle`): SUCCEEDED when both present positions
  are within the device's ``tolerance`` of the target and slower than 0.1 rad/s; FAILED
  (holding where the head is) when that takes longer than the profile's travel time plus
  ``settle_timeout``; cancel holds the present position and then marks it CANCELLED.
* a hardware fault on 10 or 11, or any fault while a head goal runs, fails it naming the
  servo (the device's alert handling); a lost link fails it ("link lost"); closing the
  device cancels it.

Position mode needs no Bus Watchdog (the servo holds its last goal by itself, which is
the safe state), exactly as for the arm joints; ``torque_off_on_close`` of the arm's
config turns the head's torque off on close with the arm's (the tilt then sags under the
camera's weight). Angles [rad], velocities [rad/s]; ``pan`` positive turns the camera
left, ``tilt`` positive looks down (docs/robots.md 1.2; the tilt servo's Drive Mode is
reversed).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import TYPE_CHECKING

from mmexec.drivers.descriptions import locobot_wx250s
from mmexec.drivers.descriptions.head import HeadModel
from mmexec.drivers.dynamixel.control_table import rad_to_pulses
from mmexec.drivers.dynamixel.model import PAN_TILT
from mmexec.drivers.interfaces import Goal, GoalState, Head, HeadState, JointLimit

if TYPE_CHECKING:
    from mmexec.drivers.dynamixel.wx250s import WX250s

__all__ = ["HEAD_ACCELERATION", "HEAD_SETTLED_SPEED", "WX250sHead"]

#: rad/s: both head joints slower than this count as arrived
HEAD_SETTLED_SPEED = 0.1
#: rad/s^2 of the pan/tilt profile: acceleration 15 units of 214.577 rev/min^2 (bring-up)
HEAD_ACCELERATION = 15 * 214.577 * 2.0 * 3.141592653589793 / 3600.0


@dataclass
class _HeadRun:
    goal: Goal
    target: tuple[float, float]
    deadline: float


class WX250sHead(Head):
    """:class:`~mmexec.drivers.interfaces.Head` over the pan/tilt servos of a LoCoBot
    :class:`WX250s` (built by the device when its config has ``locobot: true``). ``home``:
    the robot's default head pose [rad] (the config's ``robot.head.home``)."""

    def __init__(self, device: WX250s, home: tuple[float, float] = (0.0, 0.0)) -> None:
        self._dev = device
        self._home = (float(home[0]), float(home[1]))
        self._model = HeadModel.of(locobot_wx250s.DESCRIPTION)
        self._run: _HeadRun | None = None
        self._lock = threading.Lock()
        self.tolerance = device.config.tolerance
        #: index of each head joint in the device's position-joint goals
        self._slots = tuple(device.position_joints.index(j) for j in PAN_TILT)

    # -- Head
    @property
    def joint_names(self) -> tuple[str, str]:
        return (PAN_TILT[0].name, PAN_TILT[1].name)

    @property
    def limits(self) -> tuple[JointLimit, JointLimit]:
        return (PAN_TILT[0].limit(), PAN_TILT[1].limit())

    @property
    def home(self) -> tuple[float, float]:
        return self._home

    @home.setter
    def home(self, value: tuple[float, float]) -> None:
        problem = self.limit_problem(*value)
        if problem:
            raise ValueError(f"head home: {problem}")
        self._home = (float(value[0]), float(value[1]))

    @property
    def kinematics(self) -> HeadModel | None:
        return self._model

    def state(self) -> HeadState:
        """Present pan and tilt from the last Sync Read (NotConnected before the first)."""
        dev = self._dev
        with dev._lock:
            readings = [dev._readings.get(j.id) for j in PAN_TILT]
            faults = [(j, dev._faults.get(j.id)) for j in PAN_TILT]
        if readings[0] is None or readings[1] is None:
            from mmexec.drivers.dynamixel.bus import NotConnected

            raise NotConnected(f"{dev.bus.port}: no head state yet (call connect() first)")
        fault = "; ".join(f"servo id {j.id} ({j.name}): {', '.join(f)}" for j, f in faults if f)
        if not fault and dev.link_error:
            fault = dev.link_error
        return HeadState(readings[0].position, readings[1].position, dev.clock.now(),
                         readings[0].velocity, readings[1].velocity, fault)

    def point(self, pan: float, tilt: float) -> Goal:
        """Check the limits, set both goal positions (the next cycle sends them) and
        return the goal the I/O thread finishes. Never blocks."""
        dev = self._dev
        if not dev.connected:
            return Goal.failed("head.point", f"{dev.bus.port}: wx250s is not connected (call connect() first)")
        problem = self.limit_problem(pan, tilt)
        if problem:
            return Goal.failed("head.point", problem)
        target = (float(pan), float(tilt))
        with dev._lock:
            faulty = [j for j in PAN_TILT if j.id in dev._faults]
            if faulty:
                return Goal.failed("head.point", dev._fault_text())
            present = [dev._readings[j.id].position if j.id in dev._readings else q for j, q in zip(PAN_TILT, target)]
            travel = max(abs(q - p) for q, p in zip(target, present))
            speed = PAN_TILT[0].velocity
            deadline = dev.clock.now() + travel / speed + speed / HEAD_ACCELERATION + dev.config.settle_timeout
            goal = Goal("head.point", on_cancel=self._on_cancel)
            for slot, j, q in zip(self._slots, PAN_TILT, target):
                dev._goals_pulses[slot] = min(max(rad_to_pulses(q), j.min_pulses), j.max_pulses)
        with self._lock:
            prev, self._run = self._run, _HeadRun(goal, target, deadline)
        if prev is not None:
            prev.goal.mark_cancelled("preempted by a new head goal")
        return goal

    def stop(self) -> None:
        """Cancel the running goal (the I/O thread holds the head), or hold it now."""
        with self._lock:
            run = self._run
        if run is not None:
            run.goal.cancel()
        elif self._dev.connected:
            self._dev._request(self._hold_request)

    # -- device side
    def _on_cancel(self, goal: Goal) -> None:
        dev = self._dev
        if not dev.connected or dev._thread is None:
            goal.mark_cancelled("cancelled (driver not running)")

    def _hold_request(self) -> bool:
        self._dev._hold_present(PAN_TILT)
        return True

    def _finish(self, reason: str, *, cancelled: bool = False, only: _HeadRun | None = None) -> None:
        """End the running goal (link lost, faults, close): FAILED or CANCELLED; with
        ``only``, that run's goal and only while it is still the running one."""
        with self._lock:
            run = self._run
            if run is None or (only is not None and run is not only):
                return
            self._run = None
        if cancelled:
            run.goal.mark_cancelled(reason)
        else:
            run.goal.fail(reason)

    def _on_cycle(self, now: float) -> None:
        """I/O thread, after each cycle's Sync Read: finish the goal when it is done."""
        with self._lock:
            run = self._run
        if run is None:
            return
        if run.goal.state is GoalState.CANCELLING:
            self._dev._hold_present(PAN_TILT)
            self._finish("cancelled: head holding", cancelled=True, only=run)
            return
        dev = self._dev
        with dev._lock:
            readings = [dev._readings.get(j.id) for j in PAN_TILT]
        if readings[0] is None or readings[1] is None:
            return
        errs = [abs(r.position - q) for r, q in zip(readings, run.target)]
        if max(errs) <= self.tolerance and max(abs(r.velocity) for r in readings) < HEAD_SETTLED_SPEED:
            with self._lock:
                if self._run is run:
                    self._run = None
            run.goal.succeed(self.state())
        elif now > run.deadline:
            k = 0 if errs[0] >= errs[1] else 1
            self._dev._hold_present(PAN_TILT)
            self._finish(f"head joint {PAN_TILT[k].name} (servo id {PAN_TILT[k].id}) is {errs[k]:.3f} rad short of "
                         f"its target {dev.config.settle_timeout:.2f} s after the move should have ended "
                         "(blocked?); holding", only=run)
