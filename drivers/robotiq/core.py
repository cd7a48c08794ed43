"""Link-independent core of the Robotiq 2F-85 driver: I/O thread, goals, grasp tracking.

:class:`RobotiqDevice` holds everything the Modbus RTU device (:mod:`.device`) and the URCap
socket device (:mod:`.urcap`) share: an I/O thread that writes queued commands and polls
the status, the activation / move / stop / automatic-release goals advanced from that
thread, fault handling, and the translation of gOBJ into :class:`GraspState` (with
``DROPPED`` when an object that was held is lost). Subclasses only implement the link:
``_connect``, ``_disconnect``, ``_write_command`` and ``_read_status``.

Threading: after :meth:`RobotiqDevice.open` only the I/O thread touches the link; callers
queue commands and read snapshots under one lock, so no public call blocks on I/O (except
``open`` and ``close``, which are setup and shutdown, never ticks).

Goal deadlines (activation, moves, stops) and state stamps read the injected
:class:`~mmexec.drivers.interfaces.Clock` (the wall clock on the robot); only the link's own
reply deadlines, which bound a wait on a port, are wall time.

A move that fails because the link failed (no answer, corrupt frames, e-stop, port lost) is
abandoned, but the gripper may still be going to its position: when the link answers again
(by itself, or through :meth:`RobotiqDevice.reconnect`), the first command written is a stop
(rGTO = 0, as :meth:`RobotiqDevice.stop`), provided the gripper reports a move in effect
(gACT = 1 and gGTO = 1: a reset or power-cycled gripper gets nothing, since rACT = 1 would
start an activation). So the fingers do not finish a move the caller has given up on.

A move asked for while activation runs (the :meth:`RobotiqDevice.activate` goal, or a gripper
reporting gSTA = 1) is not refused: its goal waits, nothing written, and the I/O thread
starts it once gSTA = 3; it fails with one line if the activation fails or has not finished
by the activation deadline. So a mission can close the gripper right after bring-up.
"""

from __future__ import annotations

import abc
import collections
import enum
import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Self, TypeVar

from mmexec.drivers.interfaces import (
    Clock,
    Goal,
    GoalState,
    GraspState,
    GripperState,
    MonotonicClock,
)
from mmexec.drivers.robotiq import codec
from mmexec.drivers.robotiq.codec import Command, Status
from mmexec.drivers.robotiq.errors import (
    EmergencyStopped,
    RobotiqCorruptFrame,
    RobotiqError,
    RobotiqLinkError,
    RobotiqLinkLost,
    RobotiqNotReady,
    RobotiqTimeout,
    fault_error,
)

__all__ = ["DeviceSettings", "LinkState", "LinkStats", "RobotiqDevice"]

log = logging.getLogger(__name__)

_T = TypeVar("_T")


class _Closing(Exception):
    """Raised inside the I/O thread's exchange once :meth:`RobotiqDevice.close` asked the
    thread to end (never escapes the thread)."""



class LinkState(enum.Enum):
    """Connection state of a device."""

    CLOSED = "closed"          # not opened yet, or closed
    CONNECTED = "connected"    # answering
    NO_ANSWER = "no_answer"    # open, but the last exchanges failed (timeouts / corrupt frames)
    ESTOP = "estop"            # URCap only: the robot is emergency-stopped
    LOST = "lost"              # the port or socket went away; close() and open() again


@dataclass(frozen=True)
class DeviceSettings:
    """Behaviour common to both links.

    ``poll_period`` [s] between status polls; ``max_failures`` consecutive failed exchanges
    before running goals fail (single glitches are retried); ``max_force`` [N] cap on the
    grip force whatever a caller asks (20..235); ``activation_timeout`` [s] for gSTA to reach
    3; ``move_margin`` [s] added to a move's expected duration before it fails as stuck.
    """

    poll_period: float = 0.02
    max_failures: int = 3
    max_force: float = codec.FORCE_MAX
    activation_timeout: float = 10.0
    move_margin: float = 2.0

    def __post_init__(self) -> None:
        if not self.poll_period > 0:
            raise ValueError(f"poll_period must be > 0 s, got {self.poll_period}")
        if self.max_failures < 1:
            raise ValueError(f"max_failures must be >= 1, got {self.max_failures}")
        if not codec.FORCE_MIN <= self.max_force <= codec.FORCE_MAX:
            raise ValueError(f"max_force {self.max_force} N outside "
                             f"{codec.FORCE_MIN:g}..{codec.FORCE_MAX:g} N")
        if not self.activation_timeout > 0 or not self.move_margin > 0:
            raise ValueError("activation_timeout and move_margin must be > 0 s")


@dataclass(frozen=True)
class LinkStats:
    """Exchanges with the gripper since :meth:`RobotiqDevice.open`: ``exchanges`` tried
    (command writes and status reads), of which ``lost`` got no (complete) answer before the
    deadline and ``corrupt`` a bad frame; ``reads`` status reads that succeeded."""

    exchanges: int = 0
    lost: int = 0
    corrupt: int = 0
    reads: int = 0

    @property
    def failure_rate(self) -> float:
        """Fraction of the exchanges that were lost or corrupt (0 when none were tried)."""
        return (self.lost + self.corrupt) / self.exchanges if self.exchanges else 0.0


@dataclass
class _Track:
    """A goal the I/O thread advances: its kind, the command it waits on, its deadline."""

    goal: Goal
    kind: str          # "activate" | "pending" | "move" | "release" | "stop" | "reset"
    seq: int           # the goal's condition applies to readings taken after write #seq
    command: Command
    deadline: float    # clock seconds (self.clock)
    after: Goal | None = None  # "pending": the activation the move waits for (None: gSTA = 1)


class RobotiqDevice(abc.ABC):
    """A Robotiq 2F-85 on some link. Construction does no I/O; call :meth:`open`.

    Raw units here (0..255); :class:`mmexec.drivers.robotiq.gripper.RobotiqGripper` speaks SI.
    """

    def __init__(self, settings: DeviceSettings | None = None, clock: Clock | None = None) -> None:
        self.settings = settings or DeviceSettings()
        self.clock: Clock = clock or MonotonicClock()
        self._lock = threading.Lock()
        self._queue: collections.deque[Command] = collections.deque()
        self._tracks: list[_Track] = []
        self._seq = 0                    # commands written so far
        self._queued_seq = 0             # commands queued so far
        self._last_cmd: Command | None = None  # last command queued
        self._status: Status | None = None
        self._status_seq = -1
        self._stamp = 0.0
        self._link_state = LinkState.CLOSED
        self._link_error: RobotiqError | None = None
        self._failures = 0
        self._held = False
        self._dropped = False
        self._move_cmd: Command | None = None
        self._move_seq = 0
        # a move failed with the link: stop the fingers once it answers again (until written)
        self._stop_on_recovery = False
        self._recovery_stop: Command | None = None
        self._thread: threading.Thread | None = None
        self._stop_evt = threading.Event()
        self._stats = LinkStats()

    # ------------------------------------------------------------------ link (subclasses)
    @property
    @abc.abstractmethod
    def where(self) -> str:
        """Device and port for messages, e.g. ``robotiq /dev/ttyUSB0``."""

    @abc.abstractmethod
    def _connect(self) -> None:
        """Open the link; raise a RobotiqLinkError naming the port on failure."""

    @abc.abstractmethod
    def _disconnect(self) -> None:
        """Close the link (never raises)."""

    @abc.abstractmethod
    def _write_command(self, cmd: Command) -> None:
        """Write the robot output bytes; raise RobotiqLinkError / EmergencyStopped."""

    @abc.abstractmethod
    def _read_status(self) -> Status:
        """Read the robot input bytes; raise RobotiqLinkError / EmergencyStopped."""

    # ------------------------------------------------------------------ lifecycle
    @property
    def link_state(self) -> LinkState:
        with self._lock:
            return self._link_state

    @property
    def link_error(self) -> RobotiqError | None:
        """Why the link is not CONNECTED (None while it is, or before :meth:`open`)."""
        with self._lock:
            return self._link_error

    def open(self) -> Status:
        """Connect, read the status once (the gripper must answer), start the I/O thread.

        Returns the first status. Raises a :class:`RobotiqLinkError` (no such port,
        permission, no answer, corrupt frame) naming device and port. Blocking: call it at
        setup, never from a tick.
        """
        if self._thread is not None:
            raise RobotiqNotReady(f"{self.where}: already open (call close() first)")
        self._connect()
        self._stop_evt.clear()
        with self._lock:
            self._stats = LinkStats()
        try:
            status = self._counted(self._read_status)
        except (RobotiqError, OSError):
            self._disconnect()
            raise
        with self._lock:
            self._queue.clear()
            self._tracks.clear()
            self._last_cmd = None
            self._accept(status)
            self._link_state = LinkState.CONNECTED
            self._link_error = None
            self._failures = 0
            self._stop_abandoned_move(status)
        self._thread = threading.Thread(target=self._run, name=f"{self.where}-io", daemon=True)
        self._thread.start()
        log.info("%s: open, status %s", self.where, status)
        return status

    def close(self) -> None:
        """Stop the I/O thread and release the link.

        A move still running is stopped (rGTO = 0) first; an idle gripper is left unchanged
        (a held object stays held). Unfinished goals fail with "driver closed".
        """
        thread, self._thread = self._thread, None
        self._stop_evt.set()
        if thread is not None:
            thread.join(timeout=5.0)
        with self._lock:
            moving = self._recovery_stop is not None or any(
                t.kind in ("move", "release") and not t.goal.done() for t in self._tracks)
            stop = self._stop_command() if moving and self._link_state is LinkState.CONNECTED \
                else None
            tracks, self._tracks = self._tracks, []
            self._queue.clear()
            self._link_state = LinkState.CLOSED
        if stop is not None:
            try:
                self._write_command(stop)
            except (RobotiqError, OSError) as e:
                log.warning("%s: could not stop the fingers on close: %s", self.where, e)
        for t in tracks:
            t.goal.fail(f"{self.where}: driver closed")
        self._disconnect()

    def reconnect(self) -> Status:
        """:meth:`close` then :meth:`open` (after an unplug, once the device is back)."""
        self.close()
        return self.open()

    def __enter__(self) -> Self:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ snapshots
    def status(self) -> Status | None:
        """Latest raw status (None before :meth:`open`). Never blocks on I/O."""
        with self._lock:
            return self._status

    def state(self) -> GripperState:
        """Latest state in SI units: width [m], grasp, stamp [clock s], fault text."""
        with self._lock:
            st = self._status
            if st is None:
                raise RobotiqNotReady(f"{self.where}: no status yet: call open() first")
            return GripperState(codec.position_to_width(st.gPO), self._grasp(st), self._stamp,
                                self._fault_text(st))

    def _fault_text(self, st: Status) -> str:
        if self._link_state in (LinkState.NO_ANSWER, LinkState.LOST, LinkState.ESTOP) \
                and self._link_error is not None:
            return str(self._link_error)
        if st.gFLT:
            e = fault_error(st.gFLT, self.where)
            return f"{e.info.name} (0x{st.gFLT:02X})"
        return ""

    def _grasp(self, st: Status) -> GraspState:
        if self._dropped:
            return GraspState.DROPPED
        if st.gSTA == 1:
            return GraspState.MOVING
        if st.gSTA != 3 or not st.gGTO:
            return GraspState.AT_POSITION
        return (GraspState.MOVING, GraspState.CONTACT_OPENING, GraspState.CONTACT_CLOSING,
                GraspState.AT_POSITION)[st.gOBJ]

    # ------------------------------------------------------------------ commands
    def _require_link(self) -> Status:
        if self._link_state is LinkState.CLOSED or self._status is None:
            raise RobotiqNotReady(f"{self.where}: not connected: call open() first")
        if self._link_state is LinkState.LOST:
            raise RobotiqNotReady(f"{self.where}: link lost ({self._link_error}): "
                                  "reconnect the device and call reconnect()")
        if self._link_state is LinkState.ESTOP:
            raise RobotiqNotReady(f"{self.where}: the robot is emergency-stopped: "
                                  "release the e-stop first")
        if self._link_state is LinkState.NO_ANSWER:
            raise RobotiqNotReady(f"{self.where}: the gripper is not answering "
                                  f"({self._link_error}): check the cable and power")
        return self._status

    def _enqueue(self, cmd: Command) -> int:
        """Queue ``cmd``; returns the write number after which it is in effect."""
        self._queue.append(cmd)
        self._queued_seq += 1
        self._last_cmd = cmd
        return self._queued_seq

    def _stop_command(self) -> Command:
        last = self._last_cmd or Command(rACT=True)
        return Command(rACT=True, rGTO=False, rPR=last.rPR, rSP=last.rSP, rFR=last.rFR)

    def _supersede(self, kinds: tuple[str, ...], reason: str) -> None:
        for t in self._tracks:
            if t.kind in kinds:
                t.goal.mark_cancelled(reason)
        self._tracks = [t for t in self._tracks if not t.goal.done()]

    def activate(self, *, force_reset: bool = False) -> Goal:
        """Activation as a Goal: reset (all bytes 0), then rACT = 1, until gSTA = 3.

        The reset also clears faults: a major fault needs this rising edge on rACT. If the
        gripper is already activated without a fault, the goal succeeds at once and nothing
        is written (a held object stays held) unless ``force_reset``. The fingers travel
        fully during activation; the goal fails after ``settings.activation_timeout`` s.
        """
        with self._lock:
            st = self._require_link()
            if st.activated and st.gFLT == 0 and not force_reset and not any(
                    t.kind == "release" for t in self._tracks):
                return Goal.finished("robotiq.activate", self._state_locked())
            self._supersede(("activate", "pending", "move", "release", "stop"),
                             "superseded by activate()")
            self._enqueue(Command())
            seq = self._enqueue(Command(rACT=True))
            goal = Goal("robotiq.activate", on_cancel=self._on_cancel)
            self._held = self._dropped = False
            self._tracks.append(_Track(goal, "activate", seq, Command(rACT=True),
                                       self.clock.now() + self.settings.activation_timeout))
            return goal

    def _ready_for_motion(self, st: Status) -> None:
        if st.gFLT and st.gFLT != 0x05:
            e = fault_error(st.gFLT, self.where)
            raise RobotiqNotReady(f"{e} (before moving)")
        if not st.activated:
            raise RobotiqNotReady(f"{self.where}: gripper not activated (gSTA={st.gSTA}): "
                                  "call activate() first")

    def move_raw(self, position: int, speed: int = 255, force: int = 0) -> Goal:
        """Go to ``position`` (0 open .. 255 closed) at ``speed`` and ``force`` (0..255).

        The force is capped at ``settings.max_force`` whatever is asked. The goal succeeds
        when gPR echoes the request and gOBJ != 0; its result is the :class:`GripperState`
        then (``grasp`` tells whether an object stopped the fingers). It fails with the
        named fault if the gripper reports one, or if the link fails. While activation runs
        (an :meth:`activate` goal, or gSTA = 1) the goal waits, nothing written, and starts
        once gSTA = 3; it fails if the activation fails or is not done by its deadline.
        Raises :class:`RobotiqNotReady` when the gripper cannot move now (not activated
        and not activating, faulted, link down). A running or waiting move is cancelled
        ("superseded").
        """
        for name, v in (("position", position), ("speed", speed), ("force", force)):
            if not isinstance(v, int) or not 0 <= v <= 255:
                raise ValueError(f"{self.where}: {name}={v!r} must be an int in 0..255")
        force = min(force, codec.force_to_raw(self.settings.max_force))
        cmd = Command(rACT=True, rGTO=True, rPR=position, rSP=speed, rFR=force)
        with self._lock:
            st = self._require_link()
            activation = next((t for t in self._tracks if t.kind == "activate"), None)
            waits = activation is not None or (st.gSTA == 1 and st.gACT)
            if not waits:
                self._ready_for_motion(st)
            self._supersede(("pending", "move", "stop"), "superseded by a new move")
            goal = Goal("robotiq.move", on_cancel=self._on_cancel)
            if activation is not None:
                self._tracks.append(_Track(goal, "pending", activation.seq, cmd,
                                           activation.deadline, after=activation.goal))
            elif waits:
                self._tracks.append(_Track(goal, "pending", self._queued_seq, cmd,
                                           self.clock.now() + self.settings.activation_timeout))
            else:
                self._tracks.append(self._start_move(goal, cmd, st))
            return goal

    def _start_move(self, goal: Goal, cmd: Command, st: Status) -> _Track:
        """Queue the write of move ``cmd`` (lock held); the track that follows it."""
        last = self._last_cmd
        if last is not None and last.rGTO and last.rPR == cmd.rPR:
            # a gripper stopped on an object only moves again for a new position, a
            # higher force or rGTO toggled 0 then 1 (docs/protocols.md 3.3)
            self._enqueue(self._stop_command())
        seq = self._enqueue(cmd)
        self._move_cmd, self._move_seq = cmd, seq
        self._held = self._dropped = False
        stroke = abs(cmd.rPR - st.gPO) / 255 * codec.STROKE
        duration = stroke / codec.raw_to_speed(cmd.rSP)
        return _Track(goal, "move", seq, cmd,
                      self.clock.now() + 2 * duration + self.settings.move_margin)

    def stop(self) -> None:
        """Stop the fingers where they are (rGTO = 0); running moves end CANCELLED. Never
        blocks; a closed or lost link is ignored (nothing is moving through it)."""
        with self._lock:
            if self._link_state in (LinkState.CLOSED, LinkState.LOST):
                return
            self._supersede(("pending",), "cancelled: stopped before the move started")
            self._stop_locked()

    def _stop_locked(self) -> None:
        seq = self._enqueue(self._stop_command())
        for t in self._tracks:
            if t.kind == "move" and not t.goal.done():
                t.kind, t.seq, t.command = "stop", seq, self._last_cmd or Command()
                t.deadline = self.clock.now() + self.settings.move_margin

    def auto_release(self, *, closing: bool = False) -> Goal:
        """Automatic (emergency) release: slow motion to the mechanical stop, opening
        unless ``closing`` (rARD; direction unconfirmed for the 2F-85). Succeeds at gFLT
        0x0F "automatic release completed"; the gripper then needs :meth:`activate`."""
        with self._lock:
            st = self._require_link()
            if not st.gACT:
                raise RobotiqNotReady(f"{self.where}: automatic release needs rACT = 1: "
                                      "call activate() first")
            self._supersede(("pending", "move", "stop", "release"),
                            "superseded by auto_release()")
            cmd = Command(rACT=True, rATR=True, rARD=closing)
            seq = self._enqueue(cmd)
            self._held = self._dropped = False
            goal = Goal("robotiq.auto_release", on_cancel=self._on_cancel)
            self._tracks.append(_Track(goal, "release", seq, cmd, self.clock.now()
                                       + 2 * codec.STROKE / codec.SPEED_MIN
                                       + self.settings.move_margin))
            return goal

    def _on_cancel(self, goal: Goal) -> None:
        with self._lock:
            track = next((t for t in self._tracks if t.goal is goal), None)
            if track is None:
                goal.mark_cancelled("cancelled")
                return
            if track.kind == "pending":
                # nothing was written for it: done at once
                self._tracks.remove(track)
                goal.mark_cancelled("cancelled before the move started")
                return
            if track.kind == "activate":
                # stop the activation with a reset; done once the gripper reports gSTA = 0
                track.seq = self._enqueue(Command())
                track.command = Command()
                track.kind = "reset"
            elif track.kind == "release":
                # the automatic release overrides everything but rACT: it cannot be stopped
                # short of a reset, which is what cancelling it does
                track.seq = self._enqueue(Command())
                track.command = Command()
                track.kind = "reset"
            else:
                track.seq = self._enqueue(self._stop_command())
                track.command = self._last_cmd or Command()
                track.kind = "stop"
            track.deadline = self.clock.now() + self.settings.move_margin

    def _state_locked(self) -> GripperState:
        st = self._status or Status()
        return GripperState(codec.position_to_width(st.gPO), self._grasp(st), self._stamp,
                            self._fault_text(st))

    # ------------------------------------------------------------------ I/O thread
    def _run(self) -> None:
        try:
            self._loop()
        except Exception as e:
            log.exception("%s: I/O thread failed", self.where)
            err = RobotiqLinkLost(self.where, f"I/O thread failed: {type(e).__name__}: {e}")
            self._on_link_problem(LinkState.LOST, err, fail_now=True)

    def _loop(self) -> None:
        period = self.settings.poll_period
        while not self._stop_evt.is_set():
            with self._lock:
                cmd = self._queue[0] if self._queue else None
            try:
                if cmd is not None:
                    self._counted(self._write_command, cmd)
                    with self._lock:
                        self._queue.popleft()
                        self._seq += 1
                        self._on_written(cmd)
                status = self._counted(self._read_status)
            except _Closing:
                return  # close() takes it from here (and stops a running move)
            except EmergencyStopped as e:
                self._on_link_problem(LinkState.ESTOP, e, fail_now=True)
            except RobotiqLinkLost as e:
                self._on_link_problem(LinkState.LOST, e, fail_now=True)
                log.error("%s", e)
                return
            except RobotiqLinkError as e:
                self._on_link_problem(LinkState.NO_ANSWER, e, fail_now=False)
            else:
                with self._lock:
                    self._accept(status)
                    self._advance(status)
            if self._queue:
                continue  # the link itself spaces requests; send queued commands promptly
            self._stop_evt.wait(period)

    def _check_closing(self) -> None:
        """For links whose one exchange is several round trips (the URCap's status read):
        call between them, so :meth:`close` waits for one round trip, not all of them."""
        if self._stop_evt.is_set():
            raise _Closing

    def link_stats(self) -> LinkStats:
        """Exchange counts since :meth:`open` (link quality). Never blocks on I/O."""
        with self._lock:
            return self._stats

    def _counted(self, exchange: Callable[..., _T], *args: Any) -> _T:
        """Run one exchange with the gripper, counting it (and how it failed) in the stats."""
        lost = corrupt = read = 0
        try:
            result = exchange(*args)
            read = int(isinstance(result, Status))
            return result
        except RobotiqTimeout:
            lost = 1
            raise
        except RobotiqCorruptFrame:
            corrupt = 1
            raise
        finally:
            with self._lock:
                st = self._stats
                self._stats = LinkStats(st.exchanges + 1, st.lost + lost, st.corrupt + corrupt,
                                        st.reads + read)

    def _on_written(self, cmd: Command) -> None:
        if self._move_cmd is not None and cmd is self._move_cmd:
            self._held = self._dropped = False
        if cmd is self._recovery_stop:
            self._stop_on_recovery = False
            self._recovery_stop = None

    def _stop_abandoned_move(self, status: Status) -> None:
        """The link answers again after a move failed with it (lock held): queue a stop
        first, unless the gripper reports no move in effect (see the module docstring)."""
        if not self._stop_on_recovery or self._recovery_stop is not None:
            return
        if not (status.gACT and status.gGTO):
            self._stop_on_recovery = False  # reset, power-cycled or already stopped
            return
        last = self._last_cmd or self._move_cmd or Command(rACT=True)  # after reconnect(): None
        self._recovery_stop = Command(rACT=True, rGTO=False, rPR=last.rPR, rSP=last.rSP,
                                      rFR=last.rFR)
        self._enqueue(self._recovery_stop)
        log.warning("%s: answering again after a failed move: stopping the fingers (rGTO = 0) "
                    "so they do not finish it", self.where)

    def _on_link_problem(self, state: LinkState, err: RobotiqError, *, fail_now: bool) -> None:
        with self._lock:
            self._failures += 1
            if not fail_now and self._failures < self.settings.max_failures:
                log.debug("%s: retrying after %s", self.where, err)
                return
            if self._link_state is not state:
                log.warning("%s", err)
            self._link_state = state
            self._link_error = err
            msg = str(err) if fail_now else f"{err} ({self._failures} tries)"
            if any(t.kind in ("move", "stop") and not t.goal.done() for t in self._tracks):
                self._stop_on_recovery = True
            for t in self._tracks:
                t.goal.fail(msg)
            self._tracks.clear()
            self._queue.clear()
            self._recovery_stop = None  # dropped with the queue; queued again on recovery

    def _accept(self, status: Status) -> None:
        """Record a fresh status (lock held)."""
        self._status = status
        self._status_seq = self._seq
        self._stamp = self.clock.now()
        self._failures = 0
        if self._link_state in (LinkState.NO_ANSWER, LinkState.ESTOP):
            log.info("%s: answering again", self.where)
            self._link_state = LinkState.CONNECTED
            self._link_error = None
            self._stop_abandoned_move(status)
        mc = self._move_cmd
        if (mc is not None and self._seq >= self._move_seq and status.gPR == mc.rPR
                and status.gSTA == 3 and status.gGTO):
            if status.gOBJ in (1, 2):
                self._held = True
            elif self._held:
                log.warning("%s: object lost (gOBJ=%d after contact)", self.where, status.gOBJ)
                self._held = False
                self._dropped = True

    def _advance(self, st: Status) -> None:
        """Advance the goals with a fresh status (lock held)."""
        now = self.clock.now()
        keep: list[_Track] = []
        for t in self._tracks:
            if t.goal.done():
                continue
            if self._seq < t.seq:  # the command is not written yet
                keep.append(t)
                continue
            if t.kind == "activate":
                if st.gFLT and st.gFLT != 0x05:
                    t.goal.fail(str(fault_error(st.gFLT, self.where)))
                elif st.gSTA == 3:
                    t.goal.succeed(self._state_locked())
                elif now > t.deadline:
                    t.goal.fail(f"{self.where}: activation did not finish within "
                                f"{self.settings.activation_timeout:g} s (gSTA={st.gSTA})")
                else:
                    keep.append(t)
            elif t.kind == "pending":
                after = t.after
                if after is not None and after.done() and after.state is not GoalState.SUCCEEDED:
                    why = after.reason.removeprefix(f"{self.where}: ")
                    t.goal.fail(f"{self.where}: move not started: activation "
                                f"{after.state.value}: {why}")
                elif st.gFLT and st.gFLT != 0x05:
                    t.goal.fail(f"{fault_error(st.gFLT, self.where)} (before moving)")
                elif st.gSTA == 3 and st.gACT and (after is None or after.done()):
                    keep.append(self._start_move(t.goal, t.command, st))
                elif now > t.deadline:
                    t.goal.fail(f"{self.where}: move not started: activation did not finish "
                                f"within {self.settings.activation_timeout:g} s (gSTA={st.gSTA})")
                else:
                    keep.append(t)
            elif t.kind == "move":
                if st.gFLT and st.gFLT != 0x05:
                    t.goal.fail(str(fault_error(st.gFLT, self.where)))
                elif st.gSTA != 3 or not st.gACT:
                    t.goal.fail(f"{self.where}: gripper no longer activated (gSTA={st.gSTA}): "
                                "call activate() first")
                elif st.gGTO and st.gPR == t.command.rPR and st.gOBJ != 0:
                    t.goal.succeed(self._state_locked())
                elif now > t.deadline:
                    self._stop_locked()
                    t.goal.fail(f"{self.where}: move to {t.command.rPR} did not finish in time "
                                f"(gPO={st.gPO}, gOBJ={st.gOBJ})")
                else:
                    keep.append(t)
            elif t.kind == "release":
                if st.gFLT == 0x0F:
                    t.goal.succeed(self._state_locked())
                elif st.gFLT not in (0, 0x0B):
                    t.goal.fail(str(fault_error(st.gFLT, self.where)))
                elif now > t.deadline:
                    t.goal.fail(f"{self.where}: automatic release did not finish in time")
                else:
                    keep.append(t)
            elif t.kind == "stop":
                if not st.gGTO:
                    t.goal.mark_cancelled("cancelled: fingers stopped")
                elif now > t.deadline:
                    t.goal.fail(f"{self.where}: the gripper did not acknowledge the stop")
                else:
                    keep.append(t)
            elif t.kind == "reset":
                if not st.gACT and st.gSTA == 0:
                    t.goal.mark_cancelled("cancelled: gripper reset")
                elif now > t.deadline:
                    t.goal.fail(f"{self.where}: the gripper did not acknowledge the reset")
                else:
                    keep.append(t)
        self._tracks = keep
