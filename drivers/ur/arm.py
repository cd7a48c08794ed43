"""UR e-series arm as an :class:`~mmexec.drivers.interfaces.Arm`, through ur_rtde.

Threading: every ur_rtde call (constructors, moves, reads, stops, disconnect) is made
from one dedicated worker thread, ``ur-rtde-<host>``; the tick thread only posts commands
and reads a cache, so nothing here blocks a tick. Each call has a deadline
(``connect_timeout`` for the whole connect, ``command_timeout`` for everything else): a
call that overruns it fails the running goal with ``connection lost: ur_rtde <call> did
not return within ...`` as soon as the goal is next polled, and the link is torn down.

Processes: the ur_rtde objects themselves live in a host process
(:mod:`mmexec.drivers.ur.rtde_host`), because ur_rtde's constructors hold the GIL with no
deadline: in this process a controller that accepts TCP and never answers (or answers
garbage) froze every thread and made Ctrl-C do nothing. Before the host is asked to
construct anything, a pure-Python RTDE handshake (:mod:`mmexec.drivers.ur.rtde_client`)
must succeed within the same ``connect_timeout``: it names the precise reason (refused,
silent, not RTDE, ``NOT_FOUND``) in one line, and the host bounds what remains (a
controller that answers the check and then stalls ur_rtde; the dashboard and script
ports the control interface also uses). So :meth:`URArm.open` fails within
``connect_timeout`` plus a fraction of a second, and a signal handler runs at once.

Motion: :meth:`URArm.follow` streams ``servoJ`` at ``frequency`` [Hz] along the
trajectory, linearly interpolated in clock time from the current position (one servo
target per worker cycle; no moveJ path blending, so timing follows the trajectory
exactly); :meth:`URArm.move_to` sends one asynchronous ``moveJ``. Cancelling decelerates
(``servoStop`` / ``stopJ`` at ``stop_deceleration``) and the goal becomes CANCELLED once
every joint speed is below ``rest_speed``.

Lost link: at connect the driver arms the controller's RTDE watchdog
(``setWatchdog(watchdog_frequency)``; ur_rtde's script then stops the program, and the
arm, when no command package arrives for ``1 / watchdog_frequency`` s) and feeds it in
every worker cycle (``kickWatchdog()`` when the cycle sends no other command). So the arm
stops within that period of the last command that got through, however the link broke:
closed, stalled, the host process killed, or this process gone. A cancelled motion must
come to rest within :meth:`URArmConfig.stop_deadline`, derived from the model's joint
speed limits and ``stop_deceleration`` unless ``stop_timeout`` is set.

Faults (checked every worker cycle, each fails the running goal with this reason prefix):
``connection lost`` (``isConnected()`` False, a call raised, or the controller timestamp
did not advance for ``stale_timeout`` clock seconds), ``protective stop``, ``emergency
stop``, ``safeguard stop``, ``safety fault``, ``program stopped``, ``robot not running``.
After a connection loss call :meth:`URArm.reconnect`; safety faults clear by themselves
once the controller reports normal again (after the operator unlocks it on the pendant).

Frames: joint angles are the same for ROS and the controller. :meth:`URArm.tcp_pose`
returns ``T_baselink_tool0`` in the ROS ``base_link`` of the arm (REP-103), converted from
the controller's ``base`` frame (``base`` = ``base_link`` rotated pi about z).
:attr:`URArm.mount` is the arm's ``base_link`` in the robot's ``base_link``.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mmexec.drivers.interfaces import (
    Arm,
    CapabilityError,
    Clock,
    Goal,
    GoalState,
    JointLimit,
    JointState,
    JointTrajectory,
    MonotonicClock,
)
from mmexec.drivers.ur import model as urmodel
from mmexec.drivers.ur.rtde_client import RTDEClientError, RTDESession, probe
from mmexec.drivers.ur.rtde_host import QUIT_GRACE, RTDEHost, RTDEHostTimeout, call_all
from mmexec.drivers.ur.states import ROBOT_MODES, RUNTIME_STATES, SAFETY_MODES, running_fault

__all__ = [
    "DISCONNECT_ALLOWANCE",
    "RECEIVE_VARIABLES",
    "ROBOT_MODES",
    "RTDE_PORT",
    "RUNTIME_STATES",
    "SAFETY_MODES",
    "STOP_MARGIN",
    "WATCHDOG_FREQUENCY_RANGE",
    "URArm",
    "URArmConfig",
    "URConnectionError",
    "URStatus",
]

log = logging.getLogger(__name__)

RTDE_PORT = 30004

#: The RTDE output recipe the adapter asks for (a small recipe keeps the 500 Hz link cheap).
RECEIVE_VARIABLES: tuple[str, ...] = (
    "timestamp",
    "actual_q",
    "actual_qd",
    "actual_current",
    "actual_TCP_pose",
    "robot_mode",
    "safety_mode",
    "safety_status_bits",
    "runtime_state",
    "robot_status_bits",
)

#: [s] added to ``command_timeout`` for ``disconnect()``: ur_rtde 1.6.5's takes 0.5 s
#: even on a healthy link (measured against the RTDE stub)
DISCONNECT_ALLOWANCE = 1.0
#: [s] :meth:`URArm.open` waits this long past the connect deadline for the worker's own
#: reason (every step of a connect ends by that deadline)
_REASON_GRACE = 0.25
#: ur_rtde error texts that concern another port of the controller than RTDE's
_VENDOR_PORTS = (("dashboard", 29999), ("script", 30003))
#: [Hz] allowed ``watchdog_frequency``: at 1 Hz an arm on a lost link runs on for up to 1 s;
#: above 50 Hz (20 ms) a worker cycle delayed by the machine (a GC pause, a loaded core)
#: would stop the controller's program on a healthy link
WATCHDOG_FREQUENCY_RANGE = (1.0, 50.0)
#: the derived stop deadline is this many times the braking time of the model's fastest
#: joint from its speed limit, plus ``command_timeout`` for the stop command to arrive
STOP_MARGIN = 1.25


class URConnectionError(CapabilityError):
    """Connecting to the controller failed or timed out (one-line message naming host:port).

    ``detail`` is the reason without the ``host:port:`` prefix."""

    def __init__(self, message: str, detail: str = "") -> None:
        super().__init__(message)
        self.detail = detail or message



@dataclass(frozen=True)
class URArmConfig:
    """Parameters of :class:`URArm`. Times in seconds, angles rad, rates Hz.

    ``stale_timeout`` is measured on the injected clock; ``connect_timeout`` and
    ``command_timeout`` are link deadlines on ``time.monotonic()``.

    ``watchdog_frequency`` [Hz] arms the controller's RTDE watchdog at bring-up
    (``setWatchdog``): the control script is stopped, and the arm with it, when no command
    from the driver arrives for ``1 / watchdog_frequency`` s; the worker kicks it every
    cycle, so it must be at most ``frequency / 2`` and within
    :data:`WATCHDOG_FREQUENCY_RANGE`. ``stop_timeout`` [s]: how long a cancelled motion
    may take to come to rest; unset, it is derived from the model
    (:meth:`stop_deadline`); set, it must cover the braking time (:meth:`braking_time`).
    """

    host: str
    model: str = "ur5e"
    frequency: float = 500.0
    connect_timeout: float = 5.0
    command_timeout: float = 0.5
    stale_timeout: float = 0.1
    move_acceleration: float = 1.4
    acceleration_limit: float = math.inf
    stop_deceleration: float = 2.0
    stop_timeout: float | None = None
    watchdog_frequency: float = 10.0
    settle_timeout: float = 1.0
    goal_tolerance: float = 0.01
    rest_speed: float = 0.01
    servo_lookahead: float = 0.1
    servo_gain: float = 300.0
    mount: tuple[float, ...] = field(default=tuple(np.eye(4).ravel()))

    def __post_init__(self) -> None:
        if self.model not in urmodel.MODELS:
            raise ValueError(f"unknown UR model {self.model!r} (known: {', '.join(urmodel.MODELS)})")
        for name in ("frequency", "connect_timeout", "command_timeout", "stale_timeout", "stop_deceleration",
                     "settle_timeout", "goal_tolerance", "rest_speed", "move_acceleration", "watchdog_frequency"):
            value = getattr(self, name)
            if not (value > 0 and math.isfinite(value)):
                raise ValueError(f"URArmConfig.{name} must be > 0 and finite, got {value}")
        lo, hi = WATCHDOG_FREQUENCY_RANGE
        if not lo <= self.watchdog_frequency <= hi:
            raise ValueError(f"URArmConfig.watchdog_frequency must be within [{lo:g}, {hi:g}] Hz, "
                             f"got {self.watchdog_frequency:g}")
        if self.watchdog_frequency > self.frequency / 2:
            raise ValueError(f"URArmConfig.watchdog_frequency {self.watchdog_frequency:g} Hz needs frequency >= "
                             f"{2 * self.watchdog_frequency:g} Hz (the watchdog is kicked once per cycle, at least "
                             f"twice per watchdog period), got {self.frequency:g} Hz")
        if self.stop_timeout is not None:
            if not (self.stop_timeout > 0 and math.isfinite(self.stop_timeout)):
                raise ValueError(f"URArmConfig.stop_timeout must be > 0 and finite, got {self.stop_timeout}")
            if self.stop_timeout < self.braking_time():
                raise ValueError(
                    f"URArmConfig.stop_timeout {self.stop_timeout:g} s is shorter than braking the {self.model}'s "
                    f"fastest joint from its speed limit ({self._top_speed():.3f} rad/s at stop_deceleration "
                    f"{self.stop_deceleration:g} rad/s^2: {self.braking_time():.2f} s); raise it, or leave it unset "
                    f"to derive it ({self._derived_stop_deadline():.2f} s)")
        if len(self.mount) != 16:
            raise ValueError("URArmConfig.mount must hold a row-major 4x4 transform (16 values)")

    def _top_speed(self) -> float:
        return max(lim.velocity for lim in urmodel.joint_limits(self.model))

    def braking_time(self) -> float:
        """[s] braking the model's fastest joint from its speed limit at
        ``stop_deceleration`` (UR5e: pi / 2 = 1.57 s; UR3e wrists 2 pi rad/s: 3.14 s)."""
        return self._top_speed() / self.stop_deceleration

    def _derived_stop_deadline(self) -> float:
        return STOP_MARGIN * self.braking_time() + self.command_timeout

    def stop_deadline(self) -> float:
        """[s] how long after a stop command a cancelled motion may take to come to rest
        before its goal fails: ``stop_timeout`` if set, otherwise :data:`STOP_MARGIN`
        times :meth:`braking_time` plus ``command_timeout`` (defaults: UR5e 2.46 s, UR3e
        4.43 s)."""
        return self.stop_timeout if self.stop_timeout is not None else self._derived_stop_deadline()


@dataclass(frozen=True)
class URStatus:
    """Controller status from the last read (``stamp`` clock s); ``fault`` is "" when fine."""

    connected: bool
    robot_mode: int
    safety_mode: int
    runtime_state: int
    fault: str
    stamp: float


ControlFactory = Callable[[str, float], Any]
ReceiveFactory = Callable[[str, float], Any]


@dataclass
class _Motion:
    goal: Goal
    kind: str                      # "servo" | "move"
    target: np.ndarray             # final joint vector [rad]
    times: tuple[float, ...] = ()  # servo: waypoint times from start, incl. 0
    points: np.ndarray | None = None
    speed: float = 0.0             # move: leading-joint speed [rad/s]
    expected: float = 0.0          # s of clock time the motion should take
    t0: float = 0.0
    phase: str = "start"           # start | run | settle | stopping
    t_phase: float = 0.0
    last_cmd: np.ndarray | None = None


class _Stalled(Exception):
    """A ur_rtde call overran its deadline (raised in the worker once it returns).

    ``result`` is what the late call returned (e.g. an interface to disconnect)."""

    def __init__(self, reason: str, result: Any = None) -> None:
        super().__init__(reason)
        self.result = result


class URArm(Arm):
    """UR e-series arm adapter. Construction does no I/O: call :meth:`open` (blocking,
    bounded, for setup) or :meth:`connect` (returns a Goal). Always :meth:`close`."""

    def __init__(
        self,
        config: URArmConfig,
        *,
        clock: Clock | None = None,
        control_factory: ControlFactory | None = None,
        receive_factory: ReceiveFactory | None = None,
    ) -> None:
        self.config = config
        self.clock: Clock = clock if clock is not None else MonotonicClock()
        self._control_factory = control_factory or self._default_control
        self._receive_factory = receive_factory or self._default_receive
        self._limits = urmodel.joint_limits(config.model, config.acceleration_limit)
        self._stop_deadline = config.stop_deadline()
        self._mount = np.array(config.mount, dtype=float).reshape(4, 4)
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._commands: list[tuple[Any, ...]] = []
        self._thread: threading.Thread | None = None
        self._shutdown = False
        # tick-side view (under _lock)
        self._state = JointState(urmodel.JOINT_NAMES, (0.0,) * 6, (0.0,) * 6, (0.0,) * 6, self.clock.now())
        self._have_state = False
        self._tcp_pose: list[float] = [0.0] * 6
        self._status = URStatus(False, 0, 0, 0, "not connected", self.clock.now())
        self._busy: Goal | None = None
        self._watched: list[Goal] = []
        self._inflight: tuple[str, float, float] | None = None  # name, deadline, timeout
        self._stalled = ""
        # the connect in progress and what it may block on (under _lock: open() and
        # close() abort them from the calling thread)
        self._connecting: Goal | None = None
        self._preflight: RTDESession | None = None
        self._host: RTDEHost | None = None
        # worker-only
        self._connect_deadline = 0.0
        self._ctl: Any = None
        self._rcv: Any = None
        self._link_lost = "not connected"
        self._motion: _Motion | None = None
        self._last_ts: float | None = None
        self._last_fresh = 0.0
        self._fed = False  # a command went to the controller in this worker cycle

    # ------------------------------------------------------------------ default factories
    def _default_receive(self, host: str, frequency: float) -> Any:
        """Pre-flight RTDE handshake in Python, then ``RTDEReceiveInterface`` in the host
        process (worker thread; both within the connect deadline)."""
        budget = self.config.connect_timeout
        session = RTDESession(host, RTDE_PORT, budget, deadline=self._connect_deadline, deadline_text=f"{budget:.1f} s")
        with self._lock:
            self._preflight = session
        try:
            probe(session, RECEIVE_VARIABLES)
        except RTDEClientError as e:
            raise URConnectionError(str(e), e.detail) from None
        finally:
            with self._lock:
                self._preflight = None
        return self._vendor("rtde_receive", "RTDEReceiveInterface", host, frequency, list(RECEIVE_VARIABLES))

    def _default_control(self, host: str, frequency: float) -> Any:
        """``RTDEControlInterface`` in the host process (after :meth:`_default_receive`)."""
        return self._vendor("rtde_control", "RTDEControlInterface", host, frequency)

    def _vendor(self, module: str, cls: str, *args: Any) -> Any:
        """Construct a ur_rtde interface in this connection's host process (started on
        first use) within what is left of the connect deadline."""
        with self._lock:
            rtde_host = self._host
            if rtde_host is None:
                rtde_host = self._host = RTDEHost(self.config.host)
                fresh = True
            else:
                fresh = False
        try:
            if fresh:
                rtde_host.start(self._connect_left())
            return rtde_host.construct(module, cls, args, timeout=self._connect_left(),
                                       call_timeout=self.config.command_timeout,
                                       method_timeouts={"disconnect": self._disconnect_timeout})
        except RTDEHostTimeout as e:  # its deadline was what was left: name the whole budget
            detail = (f"cannot connect: ur_rtde {e.what} did not return by the connect deadline "
                      f"(connect_timeout {self.config.connect_timeout:.1f} s)")
            raise URConnectionError(detail, detail) from None

    @property
    def _disconnect_timeout(self) -> float:
        return self.config.command_timeout + DISCONNECT_ALLOWANCE

    def _connect_left(self) -> float:
        """Seconds left before the connect deadline (worker thread)."""
        return max(0.0, self._connect_deadline - time.monotonic())

    # ------------------------------------------------------------------ Arm API
    @property
    def joint_names(self) -> tuple[str, ...]:
        return urmodel.JOINT_NAMES

    @property
    def limits(self) -> tuple[JointLimit, ...]:
        return self._limits

    @property
    def mount(self) -> np.ndarray:
        """``T_base_armbase``: the arm's ROS ``base_link`` in the robot's ``base_link``."""
        return self._mount.copy()

    def state(self) -> JointState:
        """Latest joint state (positions rad, velocities rad/s, currents A). Never blocks."""
        self._check_stall()
        with self._lock:
            return self._state

    def status(self) -> URStatus:
        """Latest controller status. Never blocks."""
        self._check_stall()
        with self._lock:
            return self._status

    def tcp_pose(self) -> np.ndarray:
        """``T_baselink_tool0`` (4x4, ROS ``base_link`` of the arm) from the last read."""
        with self._lock:
            pose = list(self._tcp_pose)
        return urmodel.T_BASELINK_BASE @ urmodel.pose_to_matrix(pose)

    @property
    def connected(self) -> bool:
        with self._lock:
            return self._status.connected

    def connect(self) -> Goal:
        """Start connecting (constructs both interfaces in the worker) within
        ``connect_timeout``; returns at once."""
        return self._start_connect("connect", time.monotonic() + self.config.connect_timeout)

    def reconnect(self) -> Goal:
        """Drop the current interfaces (if any) and connect again; returns at once."""
        return self._start_connect("reconnect", time.monotonic() + self.config.connect_timeout)

    def _start_connect(self, name: str, deadline: float) -> Goal:
        goal = self._new_goal(name)
        self._post("connect", goal, deadline)
        return goal

    def open(self, timeout: float | None = None) -> None:
        """Connect and wait (bounded) for the result: for setup, not for ticks.

        Returns or raises within ``timeout`` (default ``connect_timeout``) plus 0.25 s,
        whatever the controller does; an exception while waiting (KeyboardInterrupt from
        Ctrl-C) abandons the connect, closes the adapter and propagates. Raises
        :class:`URConnectionError` with a one-line reason naming host and port on failure
        or timeout (the caller closes the adapter).
        """
        limit = timeout if timeout is not None else self.config.connect_timeout
        deadline = time.monotonic() + limit
        goal = self._start_connect("connect", deadline)
        done = threading.Event()
        try:
            while not goal.done():
                left = deadline + _REASON_GRACE - time.monotonic()
                if left <= 0:
                    goal.fail(f"no answer within {limit:.1f} s")
                    break
                done.wait(min(left, 0.01))
        except BaseException:
            goal.fail("interrupted")
            self._unwatch(goal)
            self._abort_connect(goal)
            self.close()
            raise
        if goal.state is not GoalState.SUCCEEDED:
            self._unwatch(goal)
            self._abort_connect(goal)
            raise URConnectionError(f"UR {self.config.host}:{_reason_port(goal.reason)}: {goal.reason}", goal.reason)

    def _abort_connect(self, goal: Goal | None) -> None:
        """End the connect of ``goal`` (None: whichever runs) now, from any thread: the
        pre-flight session is shut down and the host process killed, so the worker's
        blocking step returns at once."""
        with self._lock:
            if self._connecting is None or (goal is not None and self._connecting is not goal):
                return
            session, rtde_host = self._preflight, self._host
        reason = goal.reason if goal is not None and goal.reason else "connect abandoned"
        if session is not None:
            session.abort()
        if rtde_host is not None:
            rtde_host.kill(reason)

    def follow(self, trajectory: JointTrajectory) -> Goal:
        """Stream ``trajectory`` with servoJ; limits are checked before anything is sent."""
        refusal = self._refusal()
        if refusal:
            return Goal.failed("follow", refusal)
        if tuple(trajectory.joint_names) != self.joint_names:
            return Goal.failed("follow", f"trajectory joints {trajectory.joint_names} differ from {self.joint_names}")
        start = np.array(self.state().positions)
        times = (0.0, *trajectory.times)
        points = np.vstack([start, np.array(trajectory.positions, dtype=float)])
        problem = self._check_limits(times, points)
        if problem:
            return Goal.failed("follow", problem)
        goal = self._new_goal("follow", busy=True)
        if goal.done():
            return goal
        self._post("motion", _Motion(goal, "servo", points[-1], times, points, expected=trajectory.duration))
        return goal

    def move_to(self, q: Sequence[float], *, speed_scale: float = 0.5) -> Goal:
        """Asynchronous moveJ to ``q`` [rad] at ``speed_scale`` of the slowest joint limit."""
        if not 0.0 < speed_scale <= 1.0:
            return Goal.failed("move_to", f"speed_scale {speed_scale} outside (0, 1]")
        if len(q) != 6:
            return Goal.failed("move_to", f"expected 6 joint values, got {len(q)}")
        refusal = self._refusal()
        if refusal:
            return Goal.failed("move_to", refusal)
        target = np.array(q, dtype=float)
        start = np.array(self.state().positions)
        for lim, x in zip(self._limits, target):
            if not lim.contains(float(x)):
                return Goal.failed("move_to", f"{lim.name}: {x:.4f} rad outside [{lim.lower:.4f}, {lim.upper:.4f}]")
        speed = speed_scale * min(lim.velocity for lim in self._limits)
        acc = min(self.config.move_acceleration, self.config.acceleration_limit)
        dist = float(np.max(np.abs(target - start)))
        expected = dist / speed + speed / acc
        goal = self._new_goal("move_to", busy=True)
        if goal.done():
            return goal
        self._post("motion", _Motion(goal, "move", target, speed=speed, expected=expected))
        return goal

    def stop(self) -> None:
        """Cancel the running goal (decelerate, hold) and command a stop. Never blocks."""
        with self._lock:
            busy = self._busy
        if busy is not None:
            busy.cancel()
        self._post("stop")

    def close(self, timeout: float | None = None) -> None:
        """Stop the arm (servoStop, stopJ), disconnect both interfaces, end the host
        process, join the worker. A connect still in progress is abandoned at once.

        Blocks at most ``timeout`` s (default: the two stop calls and the two disconnects,
        each with its deadline, the host's exit and 0.5 s, i.e. ``4 * command_timeout +
        3.5``; about 1.2 s on a healthy link, ur_rtde's disconnect taking 0.5 s)."""
        self._abort_connect(None)
        self._post("close")
        t = self._thread
        if t is not None:
            budget = 4 * self.config.command_timeout + 2 * DISCONNECT_ALLOWANCE + QUIT_GRACE + 0.5
            t.join(timeout if timeout is not None else budget)
            if t.is_alive():
                log.warning("UR %s: worker still inside a ur_rtde call after close(); left as daemon", self.config.host)
        self._thread = None

    # ------------------------------------------------------------------ tick-side helpers
    def _refusal(self) -> str:
        self._check_stall()
        with self._lock:
            st = self._status
            busy = self._busy
        if not st.connected:
            return f"arm not connected ({st.fault}): call connect() or reconnect() first"
        if st.fault:
            return f"{st.fault}: clear it on the teach pendant (or reconnect()) first"
        if busy is not None:
            return f"arm busy with {busy.name}: cancel it first"
        return ""

    def _check_limits(self, times: Sequence[float], points: np.ndarray) -> str:
        for k, row in enumerate(points[1:], start=1):
            for lim, x in zip(self._limits, row):
                if not lim.contains(float(x)):
                    return f"{lim.name}: waypoint {k} at {x:.4f} rad outside [{lim.lower:.4f}, {lim.upper:.4f}]"
        vel = np.diff(points, axis=0) / np.diff(np.asarray(times))[:, None]
        for k, seg in enumerate(vel):
            for lim, v in zip(self._limits, seg):
                if abs(v) > lim.velocity * (1 + 1e-6):
                    return f"{lim.name}: segment {k} needs {abs(v):.3f} rad/s, limit {lim.velocity:.3f} rad/s"
        if math.isfinite(self.config.acceleration_limit) and len(vel) > 1:
            mid = (np.asarray(times[2:]) - np.asarray(times[:-2])) / 2.0
            acc = np.diff(vel, axis=0) / mid[:, None]
            for k, row in enumerate(acc):
                for lim, a in zip(self._limits, row):
                    if abs(a) > lim.acceleration * (1 + 1e-6):
                        return f"{lim.name}: waypoint {k + 1} needs {abs(a):.3f} rad/s^2, limit {lim.acceleration:.3f}"
        return ""

    def _new_goal(self, name: str, busy: bool = False) -> Goal:
        goal = Goal(name, on_cancel=self._on_cancel, on_poll=lambda g: self._check_stall())
        with self._lock:
            if busy:
                if self._busy is not None:
                    goal.fail(f"arm busy with {self._busy.name}: cancel it first")
                    return goal
                self._busy = goal
            self._watched.append(goal)
        return goal

    def _unwatch(self, goal: Goal) -> None:
        with self._lock:
            if goal in self._watched:
                self._watched.remove(goal)
            if self._busy is goal:
                self._busy = None

    def _on_cancel(self, goal: Goal) -> None:
        self._post("cancel", goal)

    def _check_stall(self) -> None:
        """Fail watched goals if the worker's current ur_rtde call overran its deadline."""
        with self._lock:
            inflight = self._inflight
            if inflight is None or time.monotonic() <= inflight[1] or self._stalled:
                return
            name, _, timeout = inflight
            self._stalled = f"connection lost: ur_rtde {name} did not return within {timeout:.2f} s"
            reason = self._stalled
            goals, self._watched, self._busy = self._watched, [], None
            self._status = URStatus(False, self._status.robot_mode, self._status.safety_mode,
                                    self._status.runtime_state, reason, self.clock.now())
        log.error("UR %s: %s", self.config.host, reason)
        for g in goals:
            g.fail(reason)

    def _post(self, *cmd: Any) -> None:
        with self._lock:
            if self._shutdown:
                if cmd[0] in ("connect", "motion"):
                    goal = cmd[1].goal if cmd[0] == "motion" else cmd[1]
                    goal.fail("arm driver closed")
                return
            self._commands.append(cmd)
            if cmd[0] == "close":
                self._shutdown = True
            if self._thread is None and cmd[0] != "close":
                self._thread = threading.Thread(target=self._run, name=f"ur-rtde-{self.config.host}", daemon=True)
                self._thread.start()
        self._wake.set()

    # ------------------------------------------------------------------ worker
    def _call(self, name: str, fn: Callable[..., Any], *args: Any, timeout: float | None = None,
              grace: float = 0.0, shown: float | None = None) -> Any:
        """Run one ur_rtde call with a deadline the tick side watches (worker thread only).

        ``grace`` [s]: the tick side waits this much longer, for a call that bounds
        itself by ``timeout`` and then names its own, more precise reason. ``shown`` [s]:
        the deadline the overrun message names (default ``timeout``)."""
        t = timeout if timeout is not None else self.config.command_timeout
        with self._lock:
            self._inflight = (name, time.monotonic() + t + grace, t if shown is None else shown)
        try:
            result = fn(*args)
        finally:
            with self._lock:
                self._inflight = None
                stalled = self._stalled
        if stalled:
            raise _Stalled(stalled, result)
        return result

    def _run(self) -> None:
        period = 1.0 / self.config.frequency
        while True:
            t_cycle = time.monotonic()
            self._fed = False
            with self._lock:
                cmds, self._commands = self._commands, []
                self._wake.clear()
            closing = False
            for cmd in cmds:
                if cmd[0] == "close":
                    closing = True
                    continue
                self._guard(self._handle, cmd)
            if closing:
                self._teardown("arm driver closed")
                return
            if self._rcv is not None:
                self._guard(self._cycle)
            wait = period - (time.monotonic() - t_cycle) if self._rcv is not None else 0.1
            if wait > 0:
                self._wake.wait(wait)

    def _guard(self, fn: Callable[..., None], *args: Any) -> None:
        """Run a worker step; link errors become 'connection lost' for the running goal."""
        try:
            fn(*args)
        except _Stalled as e:
            self._lose_link(str(e))
        except RuntimeError as e:
            self._lose_link(f"connection lost: {_one_line(e)}")

    def _handle(self, cmd: tuple[Any, ...]) -> None:
        kind = cmd[0]
        if kind == "connect":
            self._do_connect(cmd[1], cmd[2])
        elif kind == "motion":
            self._start_motion(cmd[1])
        elif kind == "cancel":
            m = self._motion
            if m is not None and m.goal is cmd[1] and m.phase != "stopping":
                self._begin_stop(m)
        elif kind == "stop" and self._motion is None and self._ctl is not None and not self._link_lost:
            self._command("stopJ", self.config.stop_deceleration, True)

    def _do_connect(self, goal: Goal, deadline: float) -> None:
        self._disconnect_all()
        with self._lock:
            self._stalled = ""
            self._connecting = goal
        self._connect_deadline = deadline
        try:
            self._connect(goal)
        finally:
            with self._lock:
                self._connecting = None

    def _connect_step(self, goal: Goal, name: str, factory: Callable[[str, float], Any]) -> Any:
        if goal.done():  # open() gave up meanwhile: do not go on connecting
            raise _Stalled(goal.reason or "gave up")
        left = self._connect_left()
        if left <= 0:
            detail = f"no answer within {self.config.connect_timeout:.1f} s (before {name})"
            raise URConnectionError(detail, detail)
        return self._call(name, factory, self.config.host, self.config.frequency, timeout=left,
                          grace=_REASON_GRACE, shown=self.config.connect_timeout)

    def _connect(self, goal: Goal) -> None:
        host = self.config.host
        rcv = ctl = None
        try:
            rcv = self._connect_step(goal, "RTDEReceiveInterface()", self._receive_factory)
            ctl = self._connect_step(goal, "RTDEControlInterface()", self._control_factory)
            self._arm_watchdog(goal, rcv, ctl)
        except (RuntimeError, URConnectionError, _Stalled) as e:
            with self._lock:
                self._stalled = ""
            late_result = e.result if isinstance(e, _Stalled) else None
            for late in (ctl, rcv, late_result):
                self._safe_disconnect(late)
            self._close_host()
            with self._lock:
                self._stalled = ""
            if isinstance(e, URConnectionError):
                reason = e.detail
            elif isinstance(e, RuntimeError):
                reason = f"cannot connect: {_one_line(e)}"
            else:
                reason = _one_line(e)
            goal.fail(reason)
            self._unwatch(goal)
            return
        if goal.done():  # gave up waiting (open() timed out): do not keep a late link
            self._safe_disconnect(ctl)
            self._safe_disconnect(rcv)
            self._close_host()
            return
        self._rcv, self._ctl, self._link_lost = rcv, ctl, ""
        self._last_ts = None
        self._last_fresh = self.clock.now()
        self._read()
        log.info("UR %s: connected", host)
        goal.succeed()
        self._unwatch(goal)

    def _arm_watchdog(self, goal: Goal, rcv: Any, ctl: Any) -> None:
        """``setWatchdog(watchdog_frequency)`` on the new control interface (ur_rtde's
        script then calls ``rtde_set_watchdog("input_int_register_0", f, "stop")``): from
        now on the controller stops its program, and the arm, when no command of ours
        arrives for ``1 / f`` s; :meth:`_cycle` kicks it. A controller that refuses fails
        the connect, naming what its state shows."""
        if goal.done():
            raise _Stalled(goal.reason or "gave up")
        wf = self.config.watchdog_frequency
        if self._call("setWatchdog", ctl.setWatchdog, wf):
            return
        fault = running_fault(int(rcv.getRobotMode()), int(rcv.getSafetyMode()), int(rcv.getSafetyStatusBits()),
                              int(rcv.getRuntimeState()))
        detail = f"cannot connect: controller refused setWatchdog({wf:g} Hz): {fault or 'no fault in its state'}"
        raise URConnectionError(detail, detail)

    def _read(self) -> str:
        """Read the receive interface into the cache; return the fault reason ("" if fine)."""
        r, c = self._rcv, self._ctl

        def read_all() -> list[Any]:  # one round trip to the host process
            return call_all([(r, "isConnected"), (c, "isConnected"), (r, "getTimestamp"), (r, "getActualQ"),
                             (r, "getActualQd"), (r, "getActualCurrent"), (r, "getActualTCPPose"),
                             (r, "getRobotMode"), (r, "getSafetyMode"), (r, "getSafetyStatusBits"),
                             (r, "getRuntimeState")])

        r_conn, c_conn, ts, q, qd, cur, tcp, rmode, smode, sbits, rt = self._call("receive getters", read_all)
        conn = r_conn and c_conn
        now = self.clock.now()
        fault = ""
        if not conn:
            fault = f"connection lost: RTDE link to {self.config.host} closed"
        else:
            if ts != self._last_ts:
                self._last_ts, self._last_fresh = ts, now
            elif now - self._last_fresh > self.config.stale_timeout:
                fault = (f"connection lost: no new RTDE data from {self.config.host} for "
                         f"{now - self._last_fresh:.2f} s")
        if not fault:
            fault = running_fault(int(rmode), int(smode), int(sbits), int(rt))
        with self._lock:
            self._state = JointState(urmodel.JOINT_NAMES, tuple(q), tuple(qd), tuple(cur), now)
            self._tcp_pose = list(tcp)
            self._have_state = True
            # a lost link flips ``connected`` in _lose_link, after the running goal failed
            connected = self._status.connected if fault.startswith("connection lost") else True
            self._status = URStatus(connected, int(rmode), int(smode), int(rt), fault, now)
        return fault

    def _cycle(self) -> None:
        fault = self._read()
        if fault.startswith("connection lost"):
            self._lose_link(fault)
            return
        self._step(fault)
        if not self._fed and self._ctl is not None:
            # Feed the controller's RTDE watchdog (armed at connect) in every cycle that sent
            # no command (each command package feeds it, and a second package in the same
            # controller cycle could overwrite the first's registers). The result is not
            # judged: ur_rtde returns False only when it sends nothing (program stopped,
            # protective or emergency stop), states this cycle's read reports as the fault.
            self._call("kickWatchdog", self._ctl.kickWatchdog)

    def _step(self, fault: str) -> None:
        m = self._motion
        if m is None:
            return
        if fault:
            self._finish(m, fail=fault)
            if m.phase != "start":
                self._safe_stop_call(m)
            return
        self._advance(m)

    def _command(self, name: str, *args: Any) -> Any:
        """Call the control interface's ``name(*args)`` (worker thread). Every command
        package updates the register the controller's watchdog watches: this cycle then
        needs no kick."""
        self._fed = True
        return self._call(name, getattr(self._ctl, name), *args)

    def _start_motion(self, m: _Motion) -> None:
        if m.goal.done():
            self._unwatch(m.goal)
            return
        if self._link_lost or self._ctl is None:
            self._finish(m, fail=self._link_lost or "arm not connected")
            return
        self._motion = m
        m.t0 = m.t_phase = self.clock.now()
        if m.kind == "move":
            acc = min(self.config.move_acceleration, self.config.acceleration_limit)
            ok = self._command("moveJ", [float(x) for x in m.target], m.speed, acc, True)
            if not ok:
                self._refused(m, "moveJ")
                return
        m.phase = "run"
        self._advance(m)

    def _advance(self, m: _Motion) -> None:
        now = self.clock.now()
        cfg = self.config
        with self._lock:
            q = np.array(self._state.positions)
            qd = np.array(self._state.velocities)
        at_rest = float(np.max(np.abs(qd))) < cfg.rest_speed
        if m.phase == "stopping":
            if at_rest and (m.kind == "servo" or self._command("isSteady")):
                self._finish(m, cancelled=True)
            elif now - m.t_phase > self._stop_deadline:
                self._finish(m, fail=f"arm did not come to rest within {self._stop_deadline:.2f} s after stopping")
            return
        t = now - m.t0
        err = np.abs(q - m.target)
        reached = float(np.max(err)) < cfg.goal_tolerance and at_rest
        if m.kind == "servo":
            assert m.points is not None
            q_cmd = _sample(m.times, m.points, t)
            if m.last_cmd is not None:  # defence in depth: never step faster than the limits
                vmax = np.array([lim.velocity for lim in self._limits]) * max(now - m.t_phase, 1.0 / cfg.frequency)
                q_cmd = np.clip(q_cmd, m.last_cmd - vmax, m.last_cmd + vmax)
            m.last_cmd, m.t_phase = q_cmd, now
            if reached and t >= m.times[-1]:
                self._command("servoStop", cfg.stop_deceleration)
                self._finish(m)
                return
            ok = self._command("servoJ", [float(x) for x in q_cmd], 0.0, 0.0,
                            1.0 / cfg.frequency, cfg.servo_lookahead, cfg.servo_gain)
            if not ok:
                self._refused(m, "servoJ")
                return
        elif reached:
            self._finish(m)
            return
        if t > m.expected + cfg.settle_timeout:
            j = int(np.argmax(err))
            self._begin_stop(m)
            self._finish(m, fail=f"did not reach the goal within {m.expected + cfg.settle_timeout:.2f} s: "
                                 f"{self.joint_names[j]} off by {err[j]:.4f} rad")

    def _begin_stop(self, m: _Motion) -> None:
        m.phase, m.t_phase = "stopping", self.clock.now()
        self._safe_stop_call(m)

    def _safe_stop_call(self, m: _Motion) -> None:
        if m.kind == "servo":
            self._command("servoStop", self.config.stop_deceleration)
        else:
            self._command("stopJ", self.config.stop_deceleration, True)

    def _finish(self, m: _Motion, *, fail: str = "", cancelled: bool = False) -> None:
        if fail:
            log.warning("UR %s: %s failed: %s", self.config.host, m.goal.name, fail)
            m.goal.fail(fail)
        elif cancelled:
            m.goal.mark_cancelled("cancelled")
        else:
            m.goal.succeed()
        if self._motion is m:
            self._motion = None
        self._unwatch(m.goal)

    def _refused(self, m: _Motion, what: str) -> None:
        """The controller said no: read it again so the goal names the actual cause."""
        fault = self._read()
        if fault.startswith("connection lost"):
            self._lose_link(fault)
            return
        with self._lock:
            st = self._status
        self._finish(m, fail=fault or f"controller refused {what} (safety mode {st.safety_mode}, "
                                      f"runtime state {st.runtime_state})")

    def _lose_link(self, reason: str) -> None:
        if self._link_lost:
            return
        log.error("UR %s: %s", self.config.host, reason)
        self._link_lost = reason
        m = self._motion
        if m is not None:
            self._finish(m, fail=reason)
        with self._lock:
            goals, self._watched = self._watched, []
            self._busy = None
            st = self._status
            self._status = URStatus(False, st.robot_mode, st.safety_mode, st.runtime_state, reason, self.clock.now())
        for g in goals:
            if g.name not in ("connect", "reconnect"):
                g.fail(reason)
        self._disconnect_all()

    def _safe_disconnect(self, iface: Any) -> None:
        if iface is None:
            return
        try:
            self._call("disconnect", iface.disconnect, timeout=self._disconnect_timeout)
        except (RuntimeError, _Stalled) as e:  # doc 4.3: disconnect() may raise "Broken pipe"
            log.info("UR %s: disconnect: %s", self.config.host, _one_line(e))

    def _disconnect_all(self) -> None:
        ctl, rcv = self._ctl, self._rcv
        self._ctl = self._rcv = None
        self._safe_disconnect(ctl)
        self._safe_disconnect(rcv)
        self._close_host()

    def _close_host(self) -> None:
        """End this connection's ur_rtde host process, if any (after the disconnects)."""
        with self._lock:
            rtde_host, self._host = self._host, None
        if rtde_host is not None:
            rtde_host.close()

    def _teardown(self, reason: str) -> None:
        """Leave the arm stopped and disconnected (worker thread, on close)."""
        m = self._motion
        if m is not None:
            self._finish(m, fail=reason)
        ctl = self._ctl
        if ctl is not None and not self._link_lost:
            for name, fn, args in (("servoStop", ctl.servoStop, (self.config.stop_deceleration,)),
                                   ("stopJ", ctl.stopJ, (self.config.stop_deceleration, True))):
                try:
                    self._call(name, fn, *args)
                except (RuntimeError, _Stalled) as e:
                    log.warning("UR %s: %s on close failed: %s", self.config.host, name, _one_line(e))
        self._disconnect_all()
        with self._lock:
            goals, self._watched, self._busy = self._watched, [], None
            self._status = URStatus(False, self._status.robot_mode, self._status.safety_mode,
                                    self._status.runtime_state, "closed", self.clock.now())
        for g in goals:
            g.fail(reason)


def _reason_port(reason: str) -> int:
    """The controller port a connect failure concerns: RTDE's, unless ur_rtde named the
    dashboard server (29999) or the script it uploads (30003)."""
    low = reason.lower()
    for word, port in _VENDOR_PORTS:
        if word in low:
            return port
    return RTDE_PORT


def _sample(times: Sequence[float], points: np.ndarray, t: float) -> np.ndarray:
    """Linear interpolation of ``points`` (rows) at ``t`` within ``times`` (clamped)."""
    if t >= times[-1]:
        return points[-1]
    i = int(np.searchsorted(times, t, side="right"))
    t0, t1 = times[i - 1], times[i]
    a = (t - t0) / (t1 - t0)
    return points[i - 1] + a * (points[i] - points[i - 1])


def _one_line(e: BaseException) -> str:
    return " ".join(str(e).split())
