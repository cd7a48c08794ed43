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
solution exists.

The control script, as ur_rtde uploads it: a lost connection does not stop the arm (the
script keeps servoing to the last ``servoJ`` target, a ``moveJ`` runs to its end);
``setWatchdog(f)`` arms the controller's RTDE watchdog, URScript
``rtde_set_watchdog("input_int_register_0", f, "stop")``: every command package ur_rtde
sends (any control-interface command, including one the script refuses, and
``kickWatchdog()``) updates that register, and when no update arrives for ``1 / f``
seconds of controller (clock) time the program is stopped (runtime state 1, the arm
stops, the watchdog is removed with the program). Each such stop is recorded in
:attr:`FakeURController.watchdog_stops`. A new control interface uploads and starts the
script again (runtime state 2, no watchdog), or raises ur_rtde's ``Failed to start
control script`` while a safety stop or power-off prevents it.

Simplifications (documented, deliberate): moves are trapezoidal straight lines in joint
space (``moveL`` too, through IK of its target), a protective stop, e-stop or stopped
program (the watchdog's included) halts the arm at once (a real arm brakes), and the
joint speed is capped at the model's limit.
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

__all__ = ["FakeRTDEControl", "FakeRTDEReceive", "FakeURController", "WatchdogStop"]

log = logging.getLogger(__name__)

#: [s, real time] how long ur_rtde waits for a command's 'done' before it gives up
#: (UR_EXECUTION_TIMEOUT in ur_rtde's source): the wait of a command that never arrived
_EXECUTION_TIMEOUT = 300.0


@dataclass(frozen=True)
class WatchdogStop:
    """The controller's RTDE watchdog stopped the program: at clock time ``t``, ``period``
    [s] after the last command package arrived (``last_input``); the arm stopped at ``q``
    [rad], moving at ``qd`` [rad/s] just before."""

    t: float
    last_input: float
    period: float
    q: tuple[float, ...]
    qd: tuple[float, ...]


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
    link), for deadline tests. The RTDE watchdog runs on the clock (controller time): see
    the module doc and :attr:`watchdog_stops`.
    """

    def __init__(
        self,
        clock: Clock,
        *,
        model: str = "ur5e",
        q0: Sequence[float] = (0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0),
        connect_delay: float = 0.0,
        controller_version: tuple[int, int, int, int] = (5, 15, 0, 12345),
    ) -> None:
        self.clock = clock
        self.model = model
        self.limits = urmodel.joint_limits(model)
        self.connect_delay = connect_delay
        self.command_delay = 0.0
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
        # the RTDE watchdog of the running program: period [s] (None: not armed) and the
        # clock time of the last command package that reached the controller
        self._watchdog: float | None = None
        self._last_input = clock.now()
        self._watchdog_stops: list[WatchdogStop] = []
        #: commands sent by the driver are lost on the way (see :meth:`drop_commands`)
        self.commands_lost = False
        self.robot_mode = 7
        self.safety_mode = 1
        self.safety_status_bits = 1
        self.runtime_state = 2
        self.refusing = False
        self.frozen = False
        self.ik_fails = False
        self.safety_refuses = False
        self.not_found: set[str] = set()
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
        """Runtime state 1 (stopped): the control script is gone (its RTDE watchdog with
        it); the arm halts."""
        with self._lock:
            self._halt()
            self.runtime_state, self._watchdog = 1, None

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
            if rt != states.RUNTIME_PLAYING:  # the program ended: its watchdog goes with it
                self._watchdog = None
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
        """Every open interface loses its connection (isConnected False, getters go stale).
        The controller's program runs on with its last command (a servo target, a moveJ)
        until its RTDE watchdog, if armed, stops it."""
        with self._lock:
            self._snapshot = self._read()
            self._session += 1

    def drop_commands(self, on: bool = True) -> None:
        """While on, nothing the driver sends reaches the controller (a link cut one way;
        state data still arrives): real-time commands (servoJ, speedJ, kickWatchdog)
        return True without effect, the others wait for a 'done' that never comes (real
        time, up to ur_rtde's 300 s; :meth:`release_blocked_calls` ends the wait) and
        return False. The RTDE watchdog, if armed, then stops the program."""
        with self._lock:
            self._advance()
            self.commands_lost = on

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
    def watchdog_stops(self) -> list[WatchdogStop]:
        """Every stop of the program by its RTDE watchdog up to the clock's now, oldest first."""
        with self._lock:
            self._advance()
            return list(self._watchdog_stops)

    @property
    def faulted(self) -> bool:
        return self.safety_mode != 1 or self.runtime_state != 2 or self.robot_mode != 7

    def _halt(self) -> None:
        self._advance()
        self._mode, self._profile, self._queue = "idle", None, []
        self._qd = np.zeros(6)

    def _advance(self) -> None:
        """Bring q, qd up to the clock's now (lazy integration), stopping the program at
        the moment its RTDE watchdog expired if it did meanwhile. Call under the lock."""
        now = self.clock.now()
        if self._watchdog is not None and self.runtime_state == states.RUNTIME_PLAYING:
            expiry = self._last_input + self._watchdog
            if now > expiry:
                self._advance_to(max(expiry, self._t_last))
                self._watchdog_stop(expiry)
        self._advance_to(now)

    def _advance_to(self, t: float) -> None:
        """Integrate the motion from the last update to clock time ``t``."""
        if self._mode in ("move", "stop"):
            assert self._profile is not None
            self._q, self._qd = self._profile.at(t)
            if t >= self._profile.t0 + self._profile.duration() - 1e-9:
                self._qd = np.zeros(6)
                if self._queue and self._mode == "move":
                    q1, v, a = self._queue.pop(0)
                    self._start_profile(q1, v, a, self._profile.t0 + self._profile.duration())
                    self._advance_to(t)
                    return
                self._mode, self._profile = "idle", None
        elif self._mode in ("servo", "speed"):  # the script streams the last target / speed on
            dt = t - self._t_last
            if dt > 0:
                vmax = np.array([lim.velocity for lim in self.limits])
                if self._mode == "servo":
                    step = np.clip(self._servo_target - self._q, -vmax * dt, vmax * dt)
                else:
                    step = np.clip(self._servo_speed, -vmax, vmax) * dt
                self._q = self._q + step
                self._qd = step / dt
        self._t_last = max(self._t_last, t)

    def _watchdog_stop(self, t: float) -> None:
        """The RTDE watchdog expired at clock time ``t``: the program stops, the arm halts
        (fake simplification: at once), the watchdog is removed with the program."""
        assert self._watchdog is not None
        self._watchdog_stops.append(WatchdogStop(t, self._last_input, self._watchdog,
                                                tuple(float(x) for x in self._q), tuple(float(x) for x in self._qd)))
        log.info("fake UR: no command for %.3f s (RTDE watchdog): program stopped", self._watchdog)
        self._mode, self._profile, self._queue = "idle", None, []
        self._qd = np.zeros(6)
        self.runtime_state, self._watchdog = 1, None

    def _command_arrived(self) -> None:
        """A command package reached the controller: it feeds the RTDE watchdog."""
        self._advance()  # the watchdog may have expired before this package arrived
        self._last_input = self.clock.now()

    def _start_script(self) -> None:
        """What a new ``RTDEControlInterface`` does (doc 4.1): upload its script and start
        it, replacing a program that ran (and its watchdog); ur_rtde raises when the
        program cannot start (doc 4.3)."""
        with self._lock:
            self._advance()
            self._watchdog = None
            if self.runtime_state == states.RUNTIME_PLAYING:
                return
            if self.robot_mode != states.ROBOT_MODE_RUNNING or self.safety_mode not in (1, 2):
                raise RuntimeError("ur_rtde: Failed to start control script, before timeout of 5 seconds")
            self.runtime_state = states.RUNTIME_PLAYING

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
        try:
            controller._start_script()
        except RuntimeError:
            self.disconnect()  # ur_rtde's constructor closes its connections as it raises
            raise

    # -- helpers
    def _send(self, *, realtime: bool = False) -> bool | None:
        """ur_rtde's ``sendCommand`` up to the script acting on the command, after an
        injected ``command_delay``. True: the command reached a program that takes it
        (apply it). False: what ur_rtde returns when it sends nothing (not connected,
        program stopped, a safety stop), or, for a command lost on the way
        (:meth:`FakeURController.drop_commands`), after waiting for its 'done'. None: a
        real-time command lost on the way (ur_rtde returns True; nothing happens). Every
        package that arrives feeds the RTDE watchdog, also one the script then refuses
        (ur_rtde sends its clear command then)."""
        ctrl = self._ctrl
        ctrl._block(ctrl.command_delay)
        if not self.isConnected():
            return False
        with ctrl._lock:
            lost = ctrl.commands_lost
            if lost:
                ctrl._advance()
            else:
                ctrl._command_arrived()
            refused = ctrl.faulted
        if refused:  # ur_rtde reads the state first: no wait
            return False
        if lost:
            if realtime:
                return None
            ctrl._block(_EXECUTION_TIMEOUT)
            return False
        return True

    def _arrived(self) -> None:
        """A query command (IK, FK, safety limits) reaches the controller: it feeds the
        RTDE watchdog like any other command package."""
        if self.isConnected():
            with self._ctrl._lock:
                if not self._ctrl.commands_lost:
                    self._ctrl._command_arrived()

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
        if not self._send():
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
        """Stream a joint target; the arm tracks it at its speed limit and holds it (the
        script servos to the last target until another command or a program stop)."""
        sent = self._send(realtime=True)
        if sent is None:
            return True
        if not sent or not self._ctrl.joints_within_limits(q):
            return False
        with self._ctrl._lock:
            self._ctrl._advance()
            self._ctrl._mode = "servo"
            self._ctrl._servo_target = np.array(q, dtype=float)
        return True

    def speedJ(self, qd: Sequence[float], acceleration: float = 0.5, time: float = 0.0) -> bool:
        """Joint speeds [rad/s], kept until another command or a program stop."""
        sent = self._send(realtime=True)
        if sent is None:
            return True
        if not sent:
            return False
        with self._ctrl._lock:
            self._ctrl._advance()
            self._ctrl._mode = "speed"
            self._ctrl._servo_speed = np.array(qd, dtype=float)
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
        if not self._send():
            return
        self._decelerate(a)
        if not asynchronous:
            self._wait_motion()

    def stopL(self, a: float = 10.0, asynchronous: bool = False) -> None:
        self.stopJ(a, asynchronous)

    def servoStop(self, a: float = 10.0) -> bool:
        if not self._send():
            return False
        self._decelerate(a)
        return True

    def speedStop(self, a: float = 10.0) -> bool:
        return self.servoStop(a)

    def triggerProtectiveStop(self) -> bool:
        if not self._send():
            return False
        self._ctrl.protective_stop()
        return True

    # -- status
    def isProgramRunning(self) -> bool:
        return self.isConnected() and self._ctrl.runtime_state == 2

    def isSteady(self) -> bool:
        """A command in ur_rtde: False when it cannot be sent (program stopped, ...)."""
        if not self._send():
            return False
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
        self._arrived()
        q = self._ctrl.inverse_kinematics(x, list(qnear) or None)
        if q is None:
            raise RuntimeError("getInverseKinematics: no solution found")
        return [float(v) for v in q]

    def getInverseKinematicsHasSolution(self, x: Sequence[float], qnear: Sequence[float] = (), max_position_error: float = 1e-10, max_orientation_error: float = 1e-10) -> bool:
        self._arrived()
        return self._ctrl.inverse_kinematics(x, list(qnear) or None) is not None

    def getForwardKinematics(self, q: Sequence[float] = (), tcp_offset: Sequence[float] = ()) -> list[float]:
        self._arrived()
        with self._ctrl._lock:
            self._ctrl._advance()
            qq = list(q) if q else list(self._ctrl._q)
        return urmodel.matrix_to_pose(urmodel.forward_kinematics(qq, self._ctrl.model))

    def isJointsWithinSafetyLimits(self, q: Sequence[float]) -> bool:
        self._arrived()
        return self._ctrl.joints_within_limits(q)

    def isPoseWithinSafetyLimits(self, pose: Sequence[float]) -> bool:
        self._arrived()
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
        """Arm the program's RTDE watchdog: no command package for ``1 / min_frequency``
        s of clock time stops the program (the script's
        ``rtde_set_watchdog("input_int_register_0", f, "stop")``). ValueError for a
        frequency that is not a positive finite number (the fake's own check)."""
        if not (math.isfinite(min_frequency) and min_frequency > 0):
            raise ValueError(f"setWatchdog: min_frequency must be a positive finite number, got {min_frequency}")
        if not self._send():
            return False
        with self._ctrl._lock:
            self._ctrl._watchdog = 1.0 / min_frequency
        return True

    def kickWatchdog(self) -> bool:
        """A real-time command package: it feeds the watchdog when it arrives."""
        return self._send(realtime=True) is not False

    def setTcp(self, pose: Sequence[float]) -> bool:
        return self._send() is True

    def setPayload(self, mass: float, cog: Sequence[float] = ()) -> bool:
        return self._send() is True

    def stopScript(self) -> None:
        if self._send():
            self._ctrl.stop_program()

    def reuploadScript(self) -> bool:
        """Upload and start the script again (a new program: no watchdog)."""
        if not self.isConnected():
            return False
        with self._ctrl._lock:
            self._ctrl._advance()
            self._ctrl.runtime_state, self._ctrl._watchdog = states.RUNTIME_PLAYING, None
        return True

