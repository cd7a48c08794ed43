"""Python-level fakes of ur_rtde's ``RTDEControlInterface`` and ``RTDEReceiveInterface``.

For adapter tests and for rehearsing without an arm. Both fakes share one
:class:`FakeURController` (the "robot"), whose motion runs on an injected
:class:`~mmexec.drivers.interfaces.Clock` (a :class:`ManualClock` in tests) and which
takes fault injections at any time, also mid-motion::

    ctrl = FakeURController(ManualClock())
    arm = URArm(URArmConfig(host="fake"), clock=ctrl.clock,
                control_factory=ctrl.control_factory, receive_factory=ctrl.receive_factory)
    ctrl.protective_stop()   # safety mode 3, status bit 2, motion halts, moves return False

Method names, argument order and return conventions follow ur_rtde 1.6.5
(docs/protocols.md 4.2/4.3): blocking moves return False rather than raise;
constructors and ``reconnect()`` raise ``RuntimeError("Error: Could not connect to: HOST at
30004, verify the IP")`` when connections are refused; getters keep returning the last
values after a connection loss; ``getInverseKinematics`` raises RuntimeError when no
solution exists. Simplifications (documented, deliberate): moves are trapezoidal
straight lines in joint space (``moveL`` too, through IK of its target), a protective
stop, e-stop, stopped program or dropped connection halts the arm at once, and the joint
speed is capped at the model's limit.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from mmexec.drivers.interfaces import Clock
from mmexec.drivers.ur import model as urmodel
from mmexec.drivers.ur import states

__all__ = ["FakeRTDEControl", "FakeRTDEReceive", "FakeURController"]

log = logging.getLogger(__name__)


@dataclass
class _Profile:
    """Straight joint-space motion: ``q(s) = q0 + u * s``, ``s`` in rad of the leading joint.

    ``kind`` "move": trapezoid from rest to rest over length ``length`` (speed ``v``,
    acceleration ``a``). ``kind`` "stop": from speed ``v`` decelerating at ``a``.
    """

    kind: str
    t0: float
    q0: np.ndarray
    u: np.ndarray
    length: float
    v: float
    a: float

    def duration(self) -> float:
        if self.kind == "stop":
            return self.v / self.a
        if self.length <= 0.0:
            return 0.0
        if self.length >= self.v * self.v / self.a:
            return 2.0 * self.v / self.a + (self.length - self.v * self.v / self.a) / self.v
        return 2.0 * math.sqrt(self.length / self.a)

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Joint positions [rad] and velocities [rad/s] at clock time ``t``."""
        tau = min(max(0.0, t - self.t0), self.duration())
        if self.kind == "stop":
            s = self.v * tau - 0.5 * self.a * tau * tau
            sd = self.v - self.a * tau
        else:
            T = self.duration()
            vp = min(self.v, math.sqrt(self.length * self.a)) if self.length > 0 else 0.0
            ta = vp / self.a if self.a > 0 else 0.0
            if tau < ta:
                s, sd = 0.5 * self.a * tau * tau, self.a * tau
            elif tau > T - ta:
                r = T - tau
                s, sd = self.length - 0.5 * self.a * r * r, self.a * r
            else:
                s, sd = 0.5 * self.a * ta * ta + vp * (tau - ta), vp
        return self.q0 + self.u * s, self.u * max(sd, 0.0)


class FakeURController:
    """The shared fake robot: state, motion, faults. Thread-safe (one lock).

    ``connect_delay`` [s, real time]: how long each constructor blocks (a slow network).
    ``command_delay`` [s, real time]: how long every control command blocks (a stalled
    link), for deadline tests. ``servo_timeout`` [s, clock time]: servoJ/speedJ watchdog;
    streaming that stops for longer halts the arm.
    """

    def __init__(
        self,
        clock: Clock,
        *,
        model: str = "ur5e",
        q0: Sequence[float] = (0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0),
        connect_delay: float = 0.0,
        servo_timeout: float = 0.1,
        controller_version: tuple[int, int, int, int] = (5, 15, 0, 12345),
    ) -> None:
        self.clock = clock
        self.model = model
        self.limits = urmodel.joint_limits(model)
        self.connect_delay = connect_delay
        self.command_delay = 0.0
        self.servo_timeout = servo_timeout
        self.controller_version = controller_version
        self._lock = threading.RLock()
        self._release = threading.Event()
        self._t_start = clock.now()
        self._q = np.array(q0, dtype=float)
        self._qd = np.zeros(6)
        self._t_last = clock.now()
        self._mode = "idle"  # idle | move | stop | servo | speed
        self._profile: _Profile | None = None
        self._queue: list[tuple[np.ndarray, float, float]] = []
        self._servo_target = self._q.copy()
        self._servo_speed = np.zeros(6)
        self._last_stream = 0.0
        self.robot_mode = 7
        self.safety_mode = 1
        self.safety_status_bits = 1
        self.runtime_state = 2
        self.refusing = False
        self.frozen = False
        self.ik_fails = False
        self.safety_refuses = False
        self.not_found: set[str] = set()
        self.watchdog_expired = 0
        self._session = 0
        self._snapshot: dict[str, Any] | None = None
        self.connections = 0
        self.disconnects = 0

    # ------------------------------------------------------------------ injection
    def protective_stop(self) -> None:
        """Safety mode 3, status bit 2; the arm halts; moves return False until cleared."""
        with self._lock:
            self._halt()
            self.safety_mode, self.safety_status_bits = 3, 1 << 2

    def emergency_stop(self) -> None:
        """Safety mode 7 (robot e-stop), status bits 6 and 7, robot mode 3 (power off)."""
        with self._lock:
            self._halt()
            self.safety_mode, self.safety_status_bits, self.robot_mode = 7, (1 << 6) | (1 << 7), 3

    def stop_program(self) -> None:
        """Runtime state 1 (stopped): the control script is gone; the arm halts."""
        with self._lock:
            self._halt()
            self.runtime_state = 1

    def set_state(self, *, robot_mode: int | None = None, safety_mode: int | None = None,
                  runtime_state: int | None = None) -> None:
        """Any controller state by the vendor's numbers (docs/protocols.md 4.2), e.g.
        power off ``robot_mode=3``, brakes engaged ``robot_mode=5``, safeguard stop
        ``safety_mode=5``; the safety status bits follow. A state in which the arm cannot
        move halts it. ValueError for a number the vendor does not define."""
        with self._lock:
            rm = self.robot_mode if robot_mode is None else int(robot_mode)
            sm = self.safety_mode if safety_mode is None else int(safety_mode)
            rt = self.runtime_state if runtime_state is None else int(runtime_state)
            bits = states.safety_status_bits(sm)
            states.robot_status_bits(rm, rt)  # validates the robot mode and runtime state
            if states.running_fault(rm, sm, bits, rt):
                self._halt()
            self.robot_mode, self.safety_mode, self.runtime_state, self.safety_status_bits = rm, sm, rt, bits

    def power_off(self) -> None:
        """Robot mode 3 (power off): the arm halts, the power-on status bit clears."""
        self.set_state(robot_mode=3)

    def clear_faults(self) -> None:
        """Back to normal: safety mode 1, robot mode 7, runtime state 2."""
        with self._lock:
            self._advance()
            self.safety_mode, self.safety_status_bits, self.robot_mode, self.runtime_state = 1, 1, 7, 2

    def drop_connections(self) -> None:
        """Every open interface loses its connection (isConnected False, getters go stale)."""
        with self._lock:
            self._halt()
            self._snapshot = self._read()
            self._session += 1

    def refuse_connections(self, on: bool = True) -> None:
        """Constructors and reconnect() raise 'Could not connect' while on."""
        with self._lock:
            self.refusing = on

    def freeze(self, on: bool = True) -> None:
        """Keep connections up but stop updating received data (stale timestamp)."""
        with self._lock:
            self._snapshot = self._read() if on else None
            self.frozen = on

    def release_blocked_calls(self) -> None:
        """Wake constructors / commands blocked by ``connect_delay`` / ``command_delay``
        and set both delays to 0 (calls no longer block)."""
        self.connect_delay = self.command_delay = 0.0
        self._release.set()

    # ------------------------------------------------------------------ factories
    def control_factory(self, host: str, frequency: float = -1.0) -> FakeRTDEControl:
        return FakeRTDEControl(host, frequency, controller=self)

    def receive_factory(self, host: str, frequency: float = -1.0, variables: Sequence[str] = ()) -> FakeRTDEReceive:
        return FakeRTDEReceive(host, frequency, list(variables), controller=self)

    # ------------------------------------------------------------------ model
    @property
    def faulted(self) -> bool:
        return self.safety_mode != 1 or self.runtime_state != 2 or self.robot_mode != 7

    def _halt(self) -> None:
        self._advance()
        self._mode, self._profile, self._queue = "idle", None, []
        self._qd = np.zeros(6)

    def _advance(self) -> None:
        """Bring q, qd up to the clock's now (lazy integration). Call under the lock."""
        now = self.clock.now()
        if self._mode in ("move", "stop"):
            assert self._profile is not None
            self._q, self._qd = self._profile.at(now)
            if now >= self._profile.t0 + self._profile.duration() - 1e-9:
                self._qd = np.zeros(6)
                if self._queue and self._mode == "move":
                    q1, v, a = self._queue.pop(0)
                    self._start_profile(q1, v, a, self._profile.t0 + self._profile.duration())
                    self._advance()
                    return
                self._mode, self._profile = "idle", None
        elif self._mode in ("servo", "speed"):
            end = min(now, self._last_stream + self.servo_timeout)
            dt = end - self._t_last
            if dt > 0:
                vmax = np.array([lim.velocity for lim in self.limits])
                if self._mode == "servo":
                    step = np.clip(self._servo_target - self._q, -vmax * dt, vmax * dt)
                else:
                    step = np.clip(self._servo_speed, -vmax, vmax) * dt
                self._q = self._q + step
                self._qd = step / dt
            if now > self._last_stream + self.servo_timeout:
                self.watchdog_expired += 1
                log.info("fake UR: servo/speed watchdog expired, arm stopped")
                self._mode, self._qd = "idle", np.zeros(6)
        self._t_last = now

    def _start_profile(self, q1: np.ndarray, speed: float, accel: float, t0: float) -> None:
        dq = q1 - self._q
        length = float(np.max(np.abs(dq)))
        vcap = min(lim.velocity for lim in self.limits)
        u = dq / length if length > 0 else np.zeros(6)
        self._profile = _Profile("move", t0, self._q.copy(), u, length, min(speed, vcap), max(accel, 1e-6))
        self._mode = "move"

    def _read(self) -> dict[str, Any]:
        """Snapshot of everything a receive interface reports (under the lock)."""
        self._advance()
        tcp = urmodel.matrix_to_pose(urmodel.forward_kinematics(self._q, self.model))
        return {
            "timestamp": self.clock.now() - self._t_start,
            "actual_q": [float(x) for x in self._q],
            "actual_qd": [float(x) for x in self._qd],
            "target_q": [float(x) for x in (self._servo_target if self._mode == "servo" else self._q)],
            "actual_TCP_pose": tcp,
            "actual_current": [0.0] * 6,
            "robot_mode": self.robot_mode,
            "safety_mode": self.safety_mode,
            "safety_status_bits": self.safety_status_bits,
            "runtime_state": self.runtime_state,
            "robot_status_bits": states.robot_status_bits(self.robot_mode, self.runtime_state),
        }

    def _block(self, seconds: float) -> None:
        """Block the calling thread for ``seconds`` of real time (a slow link), releasable."""
        if seconds > 0 and not self._release.is_set():
            self._release.wait(seconds)

    def _connect(self, host: str) -> int:
        self._block(self.connect_delay)
        with self._lock:
            if self.refusing:
                raise RuntimeError(f"Error: Could not connect to: {host} at 30004, verify the IP")
            self.connections += 1
            return self._session

    # ------------------------------------------------------------------ kinematics
    def inverse_kinematics(self, pose: Sequence[float], qnear: Sequence[float] | None) -> np.ndarray | None:
        """Damped least-squares IK in ``base`` from ``qnear`` (or the current q); None if
        it does not converge to 0.1 mm / 1 mrad or leaves the joint limits."""
        if self.ik_fails:
            return None
        target = urmodel.pose_to_matrix(pose)
        with self._lock:
            q = np.array(qnear if qnear else self._q, dtype=float)
        for _ in range(200):
            T = urmodel.forward_kinematics(q, self.model)
            err = np.concatenate([target[:3, 3] - T[:3, 3], urmodel.rotation_vector(target[:3, :3] @ T[:3, :3].T)])
            if np.linalg.norm(err[:3]) < 1e-4 and np.linalg.norm(err[3:]) < 1e-3:
                if all(lim.contains(x) for lim, x in zip(self.limits, q)):
                    return q
                return None
            J = np.zeros((6, 6))
            h = 1e-6
            for i in range(6):
                dq = q.copy()
                dq[i] += h
                Ti = urmodel.forward_kinematics(dq, self.model)
                J[:3, i] = (Ti[:3, 3] - T[:3, 3]) / h
                J[3:, i] = urmodel.rotation_vector(Ti[:3, :3] @ T[:3, :3].T) / h
            lam = 1e-2
            q = q + J.T @ np.linalg.solve(J @ J.T + lam * lam * np.eye(6), err)
        return None

    def joints_within_limits(self, q: Sequence[float]) -> bool:
        return not self.safety_refuses and len(q) == 6 and all(
            lim.contains(float(x)) for lim, x in zip(self.limits, q)
        )


class _FakeInterface:
    def __init__(self, host: str, controller: FakeURController) -> None:
        self._ctrl = controller
        self._host = host
        self._session = controller._connect(host)
        self._closed = False

    def isConnected(self) -> bool:
        with self._ctrl._lock:
            return not self._closed and self._session == self._ctrl._session

    def reconnect(self) -> bool:
        self._session = self._ctrl._connect(self._host)
        self._closed = False
        return True

    def disconnect(self) -> None:
        with self._ctrl._lock:
            if not self._closed:
                self._closed = True
                self._ctrl.disconnects += 1


class FakeRTDEReceive(_FakeInterface):
    """Same methods as ``rtde_receive.RTDEReceiveInterface`` (the ones a driver needs)."""

    def __init__(
        self,
        hostname: str,
        frequency: float = -1.0,
        variables: list[str] | None = None,
        verbose: bool = False,
        *,
        controller: FakeURController,
    ) -> None:
        missing = [v for v in (variables or []) if v in controller.not_found]
        super().__init__(hostname, controller)
        if missing:
            raise RuntimeError(
                f"The following variables was not found by the controller: [{','.join(missing)}]"
            )

    def _get(self, key: str) -> Any:
        with self._ctrl._lock:
            if self._ctrl._snapshot is not None and (self._ctrl.frozen or not self.isConnected()):
                data = self._ctrl._snapshot
            else:
                data = self._ctrl._read()
            return data[key]

    def getTimestamp(self) -> float:
        return float(self._get("timestamp"))

    def getActualQ(self) -> list[float]:
        return list(self._get("actual_q"))

    def getActualQd(self) -> list[float]:
        return list(self._get("actual_qd"))

    def getTargetQ(self) -> list[float]:
        return list(self._get("target_q"))

    def getActualCurrent(self) -> list[float]:
        return list(self._get("actual_current"))

    def getActualTCPPose(self) -> list[float]:
        return list(self._get("actual_TCP_pose"))

    def getRobotMode(self) -> int:
        return int(self._get("robot_mode"))

    def getSafetyMode(self) -> int:
        return int(self._get("safety_mode"))

    def getSafetyStatusBits(self) -> int:
        return int(self._get("safety_status_bits"))

    def getRuntimeState(self) -> int:
        return int(self._get("runtime_state"))

    def getRobotStatus(self) -> int:
        return int(self._get("robot_status_bits"))

    def isProtectiveStopped(self) -> bool:
        return bool(self.getSafetyStatusBits() & (1 << 2))

    def isEmergencyStopped(self) -> bool:
        return bool(self.getSafetyStatusBits() & (1 << 7))


class FakeRTDEControl(_FakeInterface):
    """Same methods as ``rtde_control.RTDEControlInterface`` (motion, stop, IK, status)."""

    def __init__(self, hostname: str, frequency: float = -1.0, *, controller: FakeURController) -> None:
        super().__init__(hostname, controller)
        self._period_start = 0.0

    # -- helpers
    def _ready(self) -> bool:
        """Wait out an injected command delay, then: can the robot take a command now?"""
        self._ctrl._block(self._ctrl.command_delay)
        return self.isConnected() and not self._ctrl.faulted

    def _wait_motion(self, blocking_timeout: float = 300.0) -> bool:
        """Blocking move: poll (real time, 5 ms) until the clock has carried it out."""
        deadline = time.monotonic() + blocking_timeout
        while time.monotonic() < deadline:
            with self._ctrl._lock:
                self._ctrl._advance()
                if self._ctrl.faulted or not self.isConnected():
                    return False
                if self._ctrl._mode == "idle":
                    return True
            self._ctrl._release.wait(0.005)
        return False

    @staticmethod
    def _is_path(arg: Sequence[Any]) -> bool:
        return len(arg) > 0 and isinstance(arg[0], (list, tuple))

    # -- moves
    def moveJ(self, q: Sequence[Any], speed: float = 1.05, acceleration: float = 1.4, asynchronous: bool = False) -> bool:
        """Joint move (or path of [q(6), speed, acceleration, blend]); True when accepted/done."""
        if not self._ready():
            return False
        moves = [(list(p[:6]), float(p[6]), float(p[7])) for p in q] if self._is_path(q) else [(list(q), speed, acceleration)]
        if any(not self._ctrl.joints_within_limits(m[0]) for m in moves):
            return False
        with self._ctrl._lock:
            self._ctrl._advance()
            first, *rest = moves
            self._ctrl._queue = [(np.array(m[0], dtype=float), m[1], m[2]) for m in rest]
            self._ctrl._start_profile(np.array(first[0], dtype=float), first[1], first[2], self._ctrl.clock.now())
        return True if asynchronous else self._wait_motion()

    def moveL(self, pose: Sequence[Any], speed: float = 0.25, acceleration: float = 1.2, asynchronous: bool = False) -> bool:
        """Tool move: IK of the target, then a joint-space move (fake simplification);
        ``speed`` [m/s] is used as the leading joint's rad/s."""
        if self._is_path(pose):
            return all(self.moveL(list(p[:6]), float(p[6]), float(p[7]), asynchronous=False) for p in pose)
        q = self._ctrl.inverse_kinematics(pose, None)
        if q is None:
            return False
        return self.moveJ(list(q), speed, acceleration, asynchronous)

    def servoJ(self, q: Sequence[float], speed: float, acceleration: float, time: float, lookahead_time: float, gain: float) -> bool:
        """Stream a joint target; the arm tracks it at its speed limit until the watchdog."""
        if not self._ready() or not self._ctrl.joints_within_limits(q):
            return False
        with self._ctrl._lock:
            self._ctrl._advance()
            self._ctrl._mode = "servo"
            self._ctrl._servo_target = np.array(q, dtype=float)
            self._ctrl._last_stream = self._ctrl.clock.now()
        return True

    def speedJ(self, qd: Sequence[float], acceleration: float = 0.5, time: float = 0.0) -> bool:
        if not self._ready():
            return False
        with self._ctrl._lock:
            self._ctrl._advance()
            self._ctrl._mode = "speed"
            self._ctrl._servo_speed = np.array(qd, dtype=float)
            self._ctrl._last_stream = self._ctrl.clock.now()
        return True

    def _decelerate(self, a: float) -> None:
        with self._ctrl._lock:
            self._ctrl._advance()
            qd = self._ctrl._qd
            v = float(np.max(np.abs(qd)))
            self._ctrl._queue = []
            if v <= 1e-9:
                self._ctrl._mode, self._ctrl._profile = "idle", None
                self._ctrl._qd = np.zeros(6)
                return
            prof = _Profile("stop", self._ctrl.clock.now(), self._ctrl._q.copy(), qd / v, 0.0, v, max(a, 1e-6))
            self._ctrl._profile, self._ctrl._mode = prof, "stop"

    def stopJ(self, a: float = 2.0, asynchronous: bool = False) -> None:
        """Decelerate at ``a`` [rad/s^2] to rest (returns None, like ur_rtde)."""
        if not self._ready():
            return
        self._decelerate(a)
        if not asynchronous:
            self._wait_motion()

    def stopL(self, a: float = 10.0, asynchronous: bool = False) -> None:
        self.stopJ(a, asynchronous)

    def servoStop(self, a: float = 10.0) -> bool:
        if not self._ready():
            return False
        self._decelerate(a)
        return True

    def speedStop(self, a: float = 10.0) -> bool:
        return self.servoStop(a)

    def triggerProtectiveStop(self) -> bool:
        self._ctrl.protective_stop()
        return True

    # -- status
    def isProgramRunning(self) -> bool:
        return self.isConnected() and self._ctrl.runtime_state == 2

    def isSteady(self) -> bool:
        with self._ctrl._lock:
            self._ctrl._advance()
            return self._ctrl._mode == "idle" and not np.any(self._ctrl._qd)

    def getRobotStatus(self) -> int:
        return states.robot_status_bits(self._ctrl.robot_mode, self._ctrl.runtime_state)

    def getAsyncOperationProgress(self) -> int:
        """Index of the path segment being executed, or -1 when no async move runs."""
        with self._ctrl._lock:
            self._ctrl._advance()
            return 0 if self._ctrl._mode == "move" else -1

    # -- kinematics and safety
    def getInverseKinematics(self, x: Sequence[float], qnear: Sequence[float] = (), max_position_error: float = 1e-10, max_orientation_error: float = 1e-10) -> list[float]:
        q = self._ctrl.inverse_kinematics(x, list(qnear) or None)
        if q is None:
            raise RuntimeError("getInverseKinematics: no solution found")
        return [float(v) for v in q]

    def getInverseKinematicsHasSolution(self, x: Sequence[float], qnear: Sequence[float] = (), max_position_error: float = 1e-10, max_orientation_error: float = 1e-10) -> bool:
        return self._ctrl.inverse_kinematics(x, list(qnear) or None) is not None

    def getForwardKinematics(self, q: Sequence[float] = (), tcp_offset: Sequence[float] = ()) -> list[float]:
        with self._ctrl._lock:
            self._ctrl._advance()
            qq = list(q) if q else list(self._ctrl._q)
        return urmodel.matrix_to_pose(urmodel.forward_kinematics(qq, self._ctrl.model))

    def isJointsWithinSafetyLimits(self, q: Sequence[float]) -> bool:
        return self._ctrl.joints_within_limits(q)

    def isPoseWithinSafetyLimits(self, pose: Sequence[float]) -> bool:
        return not self._ctrl.safety_refuses and self._ctrl.inverse_kinematics(pose, None) is not None

    # -- pacing and housekeeping
    def initPeriod(self) -> float:
        self._period_start = time.monotonic()
        return self._period_start

    def waitPeriod(self, t_cycle_start: float) -> None:
        """Wait until one control period (2 ms) after ``t_cycle_start`` (real time)."""
        left = t_cycle_start + 0.002 - time.monotonic()
        if left > 0:
            threading.Event().wait(left)

    def setWatchdog(self, min_frequency: float = 10.0) -> bool:
        self._ctrl.servo_timeout = 1.0 / min_frequency
        return True

    def kickWatchdog(self) -> bool:
        with self._ctrl._lock:
            self._ctrl._last_stream = self._ctrl.clock.now()
        return True

    def setTcp(self, pose: Sequence[float]) -> bool:
        return self._ready()

    def setPayload(self, mass: float, cog: Sequence[float] = ()) -> bool:
        return self._ready()

    def stopScript(self) -> None:
        self._ctrl.stop_program()

    def reuploadScript(self) -> bool:
        with self._ctrl._lock:
            if not self.isConnected():
                return False
            self._ctrl.runtime_state = 2
        return True

