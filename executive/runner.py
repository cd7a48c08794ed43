"""The runner: build the backend, load the mission, serve requests one at a time.

For each request the runner instantiates a fresh tree from the mission, ticks it at
``rate_hz`` of clock time (``robot.spin(1 / rate_hz)`` between ticks: the sim steps
physics, the robot sleeps to the period boundary, the mock advances its clock) until it
succeeds or fails, and records everything in the event log. A failed or given-up request
does not stop the queue. The runner itself never sleeps and never reads the wall clock
for timing, except to bound how long a signalled stop may take.

Stopping (the safety contract): SIGINT (Ctrl-C), SIGTERM (``timeout``, systemd,
``docker stop``) and SIGHUP (a closed ssh session) all call :meth:`Runner.interrupt`
(from :meth:`Runner.run`'s handlers, installed in the main thread; a signal the process
inherited as ignored, e.g. SIGHUP under ``nohup``, stays ignored). The running tree is
asked to halt; the runner keeps ticking until it has stopped (every running skill
cancelled, the hardware left safe), bounded by :attr:`RunOptions.halt_wall_limit`
seconds of wall time, after which it calls ``robot.safe_stop()``. A second signal skips
the wait. Then it closes the robot (which stops it again), writes ``request_end`` and
``run_end`` and returns 128 + the signal number: 130 (SIGINT), 143 (SIGTERM), 129 (SIGHUP).
A signal while the robot's devices come up ends the bring-up at once (the backend
builder closes what it had opened; ``mmexec.drivers.robot.BringUpInterrupted``): one line
``mmexec: interrupted`` (naming SIGTERM / SIGHUP) on ``err``, ``run_end`` with outcome
``interrupted`` and the signal, and the same exit code.
On a wall clock the wait between ticks (``robot.spin``) is cut short by the signal, so
a slow ``rate_hz`` does not delay the halt, and while a signalled tree stops the runner
ticks at least every :data:`HALT_TICK` seconds.

A failed event-log write (disk full) ends the run the same way (the tree halted, the
robot stopped and closed), with one line on ``err`` and exit code 1: a run is never
left going without its record.

Exit codes of :meth:`Runner.run`: 0 every request succeeded, 1 any failed (or the log
failed), 128 + signal interrupted. Bad input (config, mission, requests, an event log
path that exists or cannot be created) raises
:class:`~mmexec.config.yamlload.InputError` from :meth:`Runner.prepare` or
:meth:`Runner.run` (the CLI turns it into exit code 2).
"""

from __future__ import annotations

import errno
import hashlib
import logging
import os
import platform
import shutil
import signal
import sys
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from typing import Any, TextIO

import py_trees

from mmexec.config.yamlload import InputError, Mark, Problem, read_file
from mmexec.drivers.interfaces import Robot
from mmexec.executive.config import (
    MAX_RATE_HZ,
    MIN_RATE_HZ,
    LoadedConfig,
    build_robot,
    load_config,
    load_skill_modules,
)
from mmexec.executive.eventlog import EventLog, LogExistsError, LogOpenError
from mmexec.executive.textsafe import printable
from mmexec.skills.base import REGISTRY, SkillRegistry

__all__ = [
    "EXIT_FAILED",
    "EXIT_INPUT",
    "EXIT_INTERRUPTED",
    "EXIT_OK",
    "HALT_SIGNALS",
    "HALT_TICK",
    "SEED_RANGE",
    "ArgMark",
    "BackendStartError",
    "Progress",
    "Request",
    "RequestResult",
    "RunOptions",
    "Runner",
    "default_log_path",
]

log = logging.getLogger(__name__)

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_INPUT = 2
EXIT_INTERRUPTED = 130  # SIGINT; any halting signal exits 128 + its number

#: Signals that halt a run (the safety contract in the module doc).
HALT_SIGNALS: tuple[signal.Signals, ...] = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
#: [wall s] longest wait between ticks while a signalled tree stops on a wall clock.
HALT_TICK = 0.05
#: default log names tried (``-1``, ``-2``, ...) when one is taken
_DEFAULT_LOG_ATTEMPTS = 100

Status = py_trees.common.Status


#: ``--seed`` values: what numpy and pybullet accept as a seed (an unsigned 32-bit integer).
SEED_RANGE = (0, 2**32 - 1)


class ArgMark(Mark):
    """Where a command-line value came from, printed as ``--request #2`` (``line`` is the
    occurrence number; ``line`` 0 prints the name alone)."""

    __slots__ = ()

    def __str__(self) -> str:
        return f"{self.file} #{self.line}" if self.line else self.file


class BackendStartError(RuntimeError):
    """The configured backend could not be built or connected (not an input error)."""


class _Wake(BaseException):
    """Raised by the runner's signal handlers inside :meth:`Runner._spin` only, to end
    the wait between ticks at once (a BaseException so no skill code can catch it)."""


@dataclass(frozen=True)
class Request:
    """One request: its fields (strings from the command line, typed values from a
    requests file) and where it came from, for error messages."""

    fields: Mapping[str, Any]
    mark: Mark


@dataclass
class RunOptions:
    """What ``mmexec run`` was asked to do.

    ``rate_hz`` overrides the config's tick rate; ``request_timeout`` [clock s] halts a
    request that runs longer (outcome ``timeout``); ``halt_wall_limit`` [wall s] bounds
    how long a signalled stop may take before ``robot.safe_stop()``; ``overwrite``
    replaces an existing ``log_path`` (otherwise an existing path is an input error).
    """

    mission: Path
    config: Path
    requests: list[Request] = field(default_factory=list)
    params: dict[str, Any] = field(default_factory=dict)
    seed: int | None = None
    log_path: Path | None = None
    overwrite: bool = False
    rate_hz: float | None = None
    watch: bool = False
    gui: bool = False
    record: Path | None = None
    request_timeout: float | None = None
    halt_wall_limit: float = 5.0
    argv: list[str] = field(default_factory=list)
    recovery_enabled: bool = True


@dataclass
class RequestResult:
    """Outcome of one request: ``success``, ``failure``, ``timeout``, ``interrupted`` or
    ``error`` (an exception escaped the tree); ``duration`` in clock seconds."""

    index: int
    request: dict[str, Any]
    outcome: str
    duration: float
    recoveries: int = 0
    skill_failures: int = 0
    reason: str = ""
    failure_kind: str = ""
    failure_node: str = ""

    @property
    def ok(self) -> bool:
        return self.outcome == "success"


def default_log_path(mission: Path, attempt: int = 0) -> Path:
    """``mmexec-logs/<mission stem>-<UTC date-time to the ms>-<pid>.jsonl`` under the
    current directory, e.g. ``fetch_item-20250301T141503.042Z-81234.jsonl``: two runs
    started in the same millisecond are different processes. ``attempt`` N > 0 appends
    ``-N`` (the runner's next try when one process starts two runs in one millisecond)."""
    now = datetime.now(UTC)
    stamp = f"{now:%Y%m%dT%H%M%S}.{now.microsecond // 1000:03d}Z"
    suffix = f"-{attempt}" if attempt else ""
    return Path("mmexec-logs") / f"{mission.stem}-{stamp}-{os.getpid()}{suffix}.jsonl"


def _describe(e: OSError) -> str:
    """``No space left on device (ENOSPC)`` for an OSError with an errno."""
    name = errno.errorcode.get(e.errno or 0, "")
    return f"{e.strerror or e}" + (f" ({name})" if name else "")


def _signal_name(signum: int) -> str:
    try:
        return signal.Signals(signum).name
    except ValueError:
        return f"signal {signum}"


def _versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for dist in ("mmexec", "py_trees", "pybullet"):
        try:
            out[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            out[dist] = "not installed"
    return out


def _file_sha256(paths: Sequence[Path | str]) -> str:
    h = hashlib.sha256()
    for p in paths:
        try:  # never waits on a FIFO or reads /dev/zero the file was replaced by
            h.update(read_file(p))
        except InputError as e:  # a deleted or unreadable include is a change too; the reload reports it
            h.update(f"<unreadable {e}>".encode())
    return h.hexdigest()


class Progress:
    """A single updating status line on a terminal (nothing when ``stream`` is not a
    TTY). Redraws at most every ``interval`` wall seconds."""

    def __init__(self, stream: TextIO, *, enabled: bool | None = None, interval: float = 0.1) -> None:
        self.stream = stream
        self.enabled = stream.isatty() if enabled is None else enabled
        self.interval = interval
        self._last = -1e9
        self._shown = False

    def update(self, text: str, *, force: bool = False) -> None:
        if not self.enabled:
            return
        now = time.monotonic()
        if not force and now - self._last < self.interval:
            return
        self._last = now
        width = shutil.get_terminal_size((100, 20)).columns
        text = printable(text)  # node paths come from user files
        if len(text) >= width:
            text = text[: max(10, width - 2)] + "…"
        self._shown = self._draw("\r" + text + "\x1b[K")

    def clear(self) -> None:
        if self.enabled and self._shown:
            self._shown = not self._draw("\r\x1b[K")

    def _draw(self, text: str) -> bool:
        """Write ``text``; a terminal that went away (a closed ssh session) turns the
        status line off instead of ending the run. Returns whether it was drawn."""
        try:
            self.stream.write(text)
            self.stream.flush()
        except OSError as e:
            log.debug("status line off: %s", e)
            self.enabled = False
            return False
        return True


class Runner:
    """Serves a queue of requests with one mission on one backend (see the module doc).

    ``out`` receives one line per request and the final summary; ``err`` receives
    reload problems; ``progress`` draws the live status line (default: on ``out`` when
    it is a terminal). Construct, then :meth:`prepare` (loads and checks all input,
    raising InputError), then :meth:`run`.
    """

    def __init__(
        self,
        options: RunOptions,
        *,
        out: TextIO | None = None,
        err: TextIO | None = None,
        progress: Progress | None = None,
        registry: SkillRegistry = REGISTRY,
        robot_factory: Callable[[LoadedConfig], Robot] | None = None,
    ) -> None:
        self.options = options
        self.out = out if out is not None else sys.stdout
        self.err = err if err is not None else sys.stderr
        self.progress = progress if progress is not None else Progress(self.out)
        self.registry = registry
        self.robot_factory = robot_factory
        self.results: list[RequestResult] = []
        self.config: LoadedConfig | None = None
        self.mission: Any = None
        self.robot: Robot | None = None
        self.log: EventLog | None = None
        self.log_path: Path | None = None
        self._requests: list[dict[str, Any]] = []
        self._interrupts = 0
        #: the first halting signal received (SIGINT for :meth:`interrupt` without one)
        self.signal: int | None = None
        self._waiting = False  # in the wait between ticks, where a signal may end it
        self._dead_streams: set[int] = set()  # id() of consoles that went away
        self._lock = threading.RLock()  # reentrant: the signal handler runs in the main thread
        self._mission_digest = ""
        self._rejected_digest = ""
        self._recoveries = 0
        self._skill_failures = 0
        self._log_listeners: list[Callable[[dict[str, Any]], None]] = []
        #: the run's shared skill world (``ExecContext.world``); set entries before :meth:`run`,
        #: e.g. the operator channel of ``ask_operator`` (:data:`mmexec.skills.operator.OPERATOR_KEY`)
        self.world: dict[str, Any] = {}
        self._tick_hooks: list[Callable[[Robot, float], None]] = []
        self._halt_request = ""  # why the running request is to be halted (see halt_request)
        self._stop_requested = False
        self._served = self._succeeded = 0

    def add_log_listener(self, fn: Callable[[dict[str, Any]], None]) -> None:
        """Call ``fn(record)`` after each event-log record is written (live displays, tests)."""
        self._log_listeners.append(fn)

    def add_tick_hook(self, fn: Callable[[Robot, float], None]) -> None:
        """Call ``fn(robot, period)`` in the tick thread before every tick of a request
        (commands from other threads, live streams, pacing a stepped clock while an
        operator prompt waits). It must return promptly: the tick loop waits for it."""
        self._tick_hooks.append(fn)

    def halt_request(self, reason: str) -> None:
        """Halt the running request (outcome ``cancelled`` with ``reason``); the queue goes
        on. Safe from another thread; nothing happens between requests."""
        with self._lock:
            self._halt_request = reason

    def request_stop(self) -> None:
        """End the run in order: halt the running request (outcome ``cancelled``), serve no
        more, close the robot; ``run_end`` outcome ``stopped``, exit code 0. Thread-safe."""
        with self._lock:
            self._stop_requested = True
            if not self._halt_request:
                self._halt_request = "the service was stopped"

    @property
    def stop_requested(self) -> bool:
        return self._stop_requested

    def _next_request(self, served: int) -> tuple[int, dict[str, Any]] | None:
        """The next request to serve, as (index, fields), or None when there is none left.
        ``served`` requests were served so far. Here: the validated list, in order."""
        return (served + 1, self._requests[served]) if served < len(self._requests) else None

    def _total(self) -> int | None:
        """How many requests the run serves (``of`` in ``request_start``); None: open-ended."""
        return len(self._requests)

    def _request_tags(self, index: int) -> dict[str, Any]:
        """More fields for request ``index``'s ``request_start`` and ``request_end`` records
        (a service adds the request's ``id``). Here: none."""
        return {}

    def _end_queue(self) -> None:
        """Called once after the last request, before ``run_end`` (a service drops what is
        still queued). Here: nothing."""

    def _record(self, result: RequestResult, total: int | None) -> None:
        """Keep the result of a served request and print its line."""
        self._served += 1
        self._succeeded += result.ok
        self.results.append(result)
        self._print_result(result, total)

    # ------------------------------------------------------------------ input

    def prepare(self) -> None:
        """Load the config and its skill modules, the mission, and check every request.
        Raises InputError (all problems found) on bad input."""
        from mmexec.executive.compiler import load_mission

        opts = self.options
        self.config = load_config(opts.config)
        load_skill_modules(self.config, self.registry)
        self.mission = load_mission(opts.mission, registry=self.registry, roots=self._roots())
        self._mission_digest = _file_sha256(self._mission_files())
        self._requests = self._validate_requests(self.mission)
        if opts.rate_hz is not None and not MIN_RATE_HZ <= opts.rate_hz <= MAX_RATE_HZ:  # NaN too
            raise InputError.at(Mark("--rate", 1, 1),
                                f"expected a tick rate in [{MIN_RATE_HZ:g}, {MAX_RATE_HZ:g}] Hz, got {opts.rate_hz:g}")

    def _validate_requests(self, mission: Any) -> list[dict[str, Any]]:
        reqs = self.options.requests or [Request({}, ArgMark("mmexec run (no --request given)", 0, 0))]
        problems: list[Problem] = []
        out: list[dict[str, Any]] = []
        for i, req in enumerate(reqs, start=1):
            try:
                out.append(dict(mission.validate_request(dict(req.fields))))
            except ValueError as e:
                problems.append(Problem(req.mark, f"request {i}: {e}"))
        if problems:
            raise InputError(problems)
        return out

    def _mission_files(self) -> list[Path]:
        files = list(getattr(self.mission, "files", None) or [self.options.mission])
        return [Path(f) for f in files]

    # ------------------------------------------------------------------ control

    def interrupt(self, signum: int = signal.SIGINT) -> None:
        """Ask the run to stop (the signal handlers call it; safe from a signal or another
        thread). The first call halts the running tree and fixes the exit code at 128 +
        ``signum``; a second one stops waiting for the tree."""
        with self._lock:
            self._interrupts += 1
            if self.signal is None:
                self.signal = int(signum)

    @property
    def interrupted(self) -> bool:
        return self._interrupts > 0

    def _wake(self) -> None:
        """End the wait between ticks now, if the main thread is in it (signal context)."""
        if self._waiting:
            self._waiting = False
            raise _Wake

    def _on_halt_signal(self, signum: int, frame: object) -> None:
        self.interrupt(signum)
        self._wake()

    def _on_alarm(self, signum: int, frame: object) -> None:
        self._wake()

    def _install_signals(self, *, alarm: bool = False) -> Callable[[], None]:
        """Handlers for :data:`HALT_SIGNALS`, or with ``alarm`` for SIGALRM, which only
        ends a wait (see :meth:`_spin`); returns the function restoring the previous
        ones. Signals can only be handled in the main thread: elsewhere nothing is done."""
        if threading.current_thread() is not threading.main_thread():
            return lambda: None
        previous: dict[int, Any] = {}
        if alarm:
            previous[signal.SIGALRM] = signal.signal(signal.SIGALRM, self._on_alarm)
        else:
            for sig in HALT_SIGNALS:
                if signal.getsignal(sig) is signal.SIG_IGN:  # e.g. SIGHUP under nohup: the user's choice
                    continue
                previous[sig] = signal.signal(sig, self._on_halt_signal)

        def restore() -> None:
            for sig, old in previous.items():
                signal.signal(sig, old if old is not None else signal.SIG_DFL)

        return restore

    def _spin(self, robot: Robot, period: float, seen: int, ending: bool) -> None:
        """``robot.spin(period)`` between ticks. On a wall clock the wait ends early when a
        halting signal arrives (one not yet ``seen`` skips it), and, once the run is
        ``ending`` (a signalled or log-failure halt), after :data:`HALT_TICK` at most, by
        a SIGALRM. On a stepped clock the spin costs no wall time and runs in full."""
        if robot.clock.stepped or threading.current_thread() is not threading.main_thread():
            robot.spin(period)
            return
        timer = ending and period > HALT_TICK
        try:
            try:
                self._waiting = True  # from here on a signal raises _Wake: no window is lost
                if self._interrupts > seen:
                    return
                if timer:
                    signal.setitimer(signal.ITIMER_REAL, HALT_TICK)
                robot.spin(period)
            finally:
                self._waiting = False  # a _Wake can come up to here, and is caught just below
        except _Wake:
            log.debug("wait between ticks cut short")
        finally:
            if timer:
                signal.setitimer(signal.ITIMER_REAL, 0.0)

    # ------------------------------------------------------------------ run

    def run(self) -> int:
        """Serve every request; returns the exit code (0, 1, or 128 + the halting signal's
        number). Call :meth:`prepare` first. An event log path that cannot be used raises
        InputError before anything starts; backend start-up errors propagate (after
        closing the log)."""
        if self.mission is None or self.config is None:
            self.prepare()
        assert self.config is not None
        opts = self.options
        self.log = self._open_log()
        restore_alarm: Callable[[], None] = lambda: None
        restore = self._install_signals()
        exit_code = EXIT_FAILED
        outcome = "error"
        try:
            try:
                if self.robot_factory is not None:
                    self.robot = self.robot_factory(self.config)
                else:
                    self.robot = build_robot(self.config, seed=opts.seed,
                                             options={"gui": opts.gui, "record": opts.record})
            except InputError:
                raise
            except Exception as e:  # any driver start-up failure, reported in one line
                raise BackendStartError(f"backend {self.config.backend!r} failed to start: "
                                        f"{type(e).__name__}: {e}") from e
            robot = self.robot
            if not robot.clock.stepped:  # the timer that bounds waits while a signalled tree stops
                restore_alarm = self._install_signals(alarm=True)
            self.log.clock = robot.clock.now
            self.log.add_listener(self._count_events)
            for fn in self._log_listeners:
                self.log.add_listener(fn)
            rate = opts.rate_hz if opts.rate_hz is not None else self.config.config.rate_hz
            self.log.write(
                "run_start",
                started=EventLog.wall_time(),
                mission=str(opts.mission),
                mission_sha256=self.mission.sha256,
                mission_name=getattr(self.mission, "name", ""),
                config=str(self.config.path),
                config_sha256=self.config.sha256,
                backend=self.config.backend,
                seed=opts.seed,
                rate_hz=rate,
                recovery_enabled=opts.recovery_enabled,
                requests=len(self._requests),
                argv=list(opts.argv),
                versions=_versions(),
                pid=os.getpid(),
            )
            from mmexec.executive.context import ExecContext

            ctx = ExecContext(robot=robot, clock=robot.clock, registry=self.registry, emit=self.log.emit,
                              world=self.world, profile=dict(self.config.config.profile),
                              recovery_enabled=opts.recovery_enabled)
            while not (self.interrupted or self._stop_requested or self.log.error is not None):
                if self._served > 0 and opts.watch:
                    self._maybe_reload(self._served)
                nxt = self._next_request(self._served)
                if nxt is None:
                    break
                total = self._total()
                self._record(self._serve(ctx, nxt[0], total, nxt[1], 1.0 / rate), total)
            self._end_queue()
            total = self._total()
            n = total if total is not None else self._served
            ok = self._succeeded
            failed = self._served - ok
            extra: dict[str, Any] = {}
            if self.log.error is not None:
                exit_code, outcome = EXIT_FAILED, "error"
            elif self.interrupted:
                signum = self.signal if self.signal is not None else signal.SIGINT
                exit_code, outcome = 128 + signum, "interrupted"
                extra["signal"] = _signal_name(signum)
            elif self._stop_requested:
                exit_code, outcome = EXIT_OK, "stopped"
            elif failed == 0 and self._served == n:
                exit_code, outcome = EXIT_OK, "ok"
            else:
                exit_code, outcome = EXIT_FAILED, "failed"
            self.log.write("run_end", outcome=outcome, requests=n, served=self._served, succeeded=ok,
                           failed=failed, duration=robot.clock.now(), exit_code=exit_code, **extra)
            if self.log.error is not None:  # also a failure of this very last record
                exit_code = EXIT_FAILED
                robot.safe_stop()
                self._say(f"mmexec: event log {self.log_path}: {_describe(self.log.error)}; "
                          "the robot was stopped and the run ended", self.err)
            self._print_summary(n, ok, failed, outcome)
            return exit_code
        except BaseException as e:
            if isinstance(e, KeyboardInterrupt) and self.robot is None and self.signal is not None:
                # a halting signal ended the device bring-up (the builder closed what it
                # had opened): an interrupted run, 128 + the signal, like one during ticks
                exit_code = 128 + self.signal
                name = _signal_name(self.signal)
                if self.log is not None and not self.log.closed:
                    self.log.write("run_end", outcome="interrupted", signal=name, served=self._served,
                                   exit_code=exit_code)
                self._say("mmexec: interrupted" + ("" if self.signal == signal.SIGINT else f" ({name})"), self.err)
                return exit_code
            if self.log is not None and not self.log.closed:
                # the exit code the command will return for this exception (cli.main)
                code = (EXIT_INPUT if isinstance(e, InputError)
                        else EXIT_INTERRUPTED if isinstance(e, KeyboardInterrupt) else EXIT_FAILED)
                self.log.write("run_end", outcome="error", error=f"{type(e).__name__}: {e}",
                               served=self._served, exit_code=code)
            raise
        finally:
            self.progress.clear()
            try:
                if self.robot is not None:
                    self.robot.close()
            finally:
                if self.log is not None:
                    self.log.close()
                restore_alarm()
                restore()

    def _open_log(self) -> EventLog:
        """The run's event log, open (see :class:`EventLog`), at ``--log`` or a new default
        path (:attr:`log_path`); a path that cannot be used is an InputError located at it."""
        opts = self.options
        attempt = 0
        while True:
            path = self.log_path = opts.log_path if opts.log_path is not None else default_log_path(
                opts.mission, attempt)
            try:
                return EventLog(path, overwrite=opts.overwrite).open()
            except LogExistsError as e:
                if opts.log_path is None and attempt < _DEFAULT_LOG_ATTEMPTS:
                    attempt += 1  # this process started another run in the same millisecond
                    continue
                raise InputError.at(Mark(str(path), 1, 1), f"{self._log_option()}: {e.reason}; "
                                                           "pass --overwrite to replace it") from None
            except LogOpenError as e:
                raise InputError.at(Mark(str(path), 1, 1), f"{self._log_option()}: {e.reason}") from None

    def _log_option(self) -> str:
        return "--log" if self.options.log_path is not None else "event log"

    def _count_events(self, record: dict[str, Any]) -> None:
        ev = record.get("event")
        if ev == "recovery_attempt":
            self._recoveries += 1
        elif ev in ("skill_failure", "skill_failed"):
            self._skill_failures += 1
        elif ev == "report":
            self.progress.clear()
            level = record.get("level", "info")
            self._say(f"  {'' if level == 'info' else level + ': '}{record.get('message', '')}")

    def _serve(self, ctx: Any, index: int, total: int | None, request: dict[str, Any],
               period: float) -> RequestResult:
        assert self.robot is not None and self.log is not None
        robot, elog, opts = self.robot, self.log, self.options
        self._recoveries = self._skill_failures = 0
        with self._lock:
            if not self._stop_requested:
                self._halt_request = ""  # a halt asked for between requests concerns none
        tree = self.mission.instantiate(ctx, request, params=opts.params or None)
        t0 = robot.clock.now()
        elog.write("request_start", index=index, of=total, **self._request_tags(index), request=request,
                   mission_sha256=self.mission.sha256, nodes=[path for path, _ in tree.snapshot()])

        def on_status(path: str, old: Any, new: Any) -> None:
            elog.write("node_status", path=path, old=old, new=new)

        tree.add_status_listener(on_status)
        halt_reason = ""
        wall_deadline = 0.0
        seen_interrupts = 0
        status = Status.RUNNING
        try:
            while True:
                for hook in self._tick_hooks:
                    hook(robot, period)
                if self._interrupts > seen_interrupts:
                    seen_interrupts = self._interrupts
                    if halt_reason != "interrupt":
                        halt_reason = "interrupt"
                        if not tree.halting:
                            tree.request_halt()
                        wall_deadline = time.monotonic() + opts.halt_wall_limit
                        elog.write("halt", reason="interrupt", signal=_signal_name(self.signal or signal.SIGINT),
                                   index=index)
                    if seen_interrupts >= 2:
                        elog.write("halt_abandoned", reason="second interrupt", index=index)
                        robot.safe_stop()
                        break
                elif elog.error is not None and halt_reason not in ("interrupt", "log_failure"):
                    halt_reason = "log_failure"  # no record can be written any more: stop
                    if not tree.halting:
                        tree.request_halt()
                    wall_deadline = time.monotonic() + opts.halt_wall_limit
                elif (opts.request_timeout is not None and not halt_reason
                      and robot.clock.now() - t0 > opts.request_timeout):
                    halt_reason = "timeout"
                    tree.request_halt()
                    wall_deadline = time.monotonic() + opts.halt_wall_limit
                    elog.write("halt", reason="timeout", index=index, limit=opts.request_timeout)
                elif self._halt_request and not halt_reason:
                    halt_reason = "cancel"
                    tree.request_halt()
                    wall_deadline = time.monotonic() + opts.halt_wall_limit
                    elog.write("halt", reason="cancel", index=index, detail=self._halt_request)
                status = tree.tick()
                self.progress.update(
                    f"[{index}{'' if total is None else f'/{total}'}] {robot.clock.now() - t0:7.1f} s  "
                    f"{'stopping ' if halt_reason else ''}{tree.tip_path() or '-'}"
                )
                if halt_reason:
                    if tree.stopped:
                        break
                    if time.monotonic() > wall_deadline:
                        elog.write("halt_abandoned", reason=f"tree still stopping after {opts.halt_wall_limit:g} s",
                                   index=index)
                        robot.safe_stop()
                        break
                elif status in (Status.SUCCESS, Status.FAILURE):
                    break
                self._spin(robot, period, seen_interrupts, ending=halt_reason in ("interrupt", "log_failure"))
        except Exception as e:  # a bug in a skill or node: this request ends, the queue goes on
            log.error("request %d: %s", index, e, exc_info=log.isEnabledFor(logging.DEBUG))
            robot.safe_stop()
            result = RequestResult(index, request, "error", robot.clock.now() - t0, self._recoveries,
                                   self._skill_failures, reason=f"{type(e).__name__}: {e}")
            self._end(result)
            return result
        bb = tree.blackboard()
        if halt_reason == "log_failure":
            robot.safe_stop()
            outcome = "error"
        elif halt_reason == "interrupt":
            outcome = "interrupted"
        elif halt_reason == "timeout":
            outcome = "timeout"
        elif halt_reason == "cancel":
            outcome = "cancelled"
        else:
            outcome = "success" if status is Status.SUCCESS else "failure"
        reason, kind, node = "", "", ""
        if outcome == "timeout":
            reason, kind = f"request took longer than {opts.request_timeout:g} s", "timeout"
        elif outcome == "interrupted":
            signum = self.signal if self.signal is not None else signal.SIGINT
            reason = "interrupted (Ctrl-C)" if signum == signal.SIGINT else f"interrupted ({_signal_name(signum)})"
            kind = "cancelled"
        elif outcome == "cancelled":
            reason, kind = self._halt_request, "cancelled"
        elif outcome == "error":
            reason = f"event log write failed: {_describe(elog.error)}" if elog.error is not None else ""
        elif outcome == "failure":
            reason = str(bb.get("last_failure", "") or "")
            kind = str(bb.get("last_failure_kind", "") or "")
            node = str(bb.get("last_failure_node", "") or "")
        result = RequestResult(index, request, outcome, robot.clock.now() - t0, self._recoveries,
                               self._skill_failures, reason, kind, node)
        self._end(result)
        return result

    def _end(self, r: RequestResult) -> None:
        assert self.log is not None
        self.log.write("request_end", index=r.index, **self._request_tags(r.index), request=r.request,
                       outcome=r.outcome, duration=r.duration,
                       recoveries=r.recoveries, skill_failures=r.skill_failures, reason=r.reason,
                       failure_kind=r.failure_kind, failure_node=r.failure_node)

    def _maybe_reload(self, next_index: int) -> None:
        """``--watch``: reload the mission if any of its files changed (between requests)."""
        from mmexec.executive.compiler import load_mission

        assert self.log is not None
        digest = _file_sha256(self._mission_files())
        if digest == self._mission_digest or digest == self._rejected_digest:
            return
        self.progress.clear()
        try:
            mission = load_mission(self.options.mission, registry=self.registry, roots=self._roots())
            remaining = self._validate_with(mission, next_index)
        except InputError as e:
            self._rejected_digest = digest
            lines = [str(p) for p in e.problems]
            self.log.write("mission_reload", ok=False, problems=lines)
            self._say(f"mmexec: {self.options.mission} changed but has errors; still running the previous version:",
                      self.err)
            for line in lines:
                self._say(line, self.err)
            return
        self.mission = mission
        self._mission_digest = _file_sha256(self._mission_files())
        self._rejected_digest = ""
        self._requests[next_index:] = remaining
        self.log.write("mission_reload", ok=True, mission_sha256=mission.sha256)
        self._say(f"mmexec: reloaded {self.options.mission} (sha256 {mission.sha256[:12]})")

    def _roots(self) -> tuple[Path, ...]:
        """The config's ``roots:`` (more folders the mission's includes may come from)."""
        return self.config.roots if self.config is not None else ()

    def _validate_with(self, mission: Any, start: int) -> list[dict[str, Any]]:
        reqs = self.options.requests or [Request({}, ArgMark("mmexec run (no --request given)", 0, 0))]
        problems: list[Problem] = []
        out: list[dict[str, Any]] = []
        for i in range(start, len(reqs)):
            try:
                out.append(dict(mission.validate_request(dict(reqs[i].fields))))
            except ValueError as e:
                problems.append(Problem(reqs[i].mark, f"request {i + 1}: {e}"))
        if problems:
            raise InputError(problems)
        return out

    # ------------------------------------------------------------------ output

    def _print_result(self, r: RequestResult, total: int | None) -> None:
        self.progress.clear()
        req = ", ".join(f"{k}={v}" for k, v in r.request.items()) or "-"
        rec = f", {r.recoveries} recover{'y' if r.recoveries == 1 else 'ies'}" if r.recoveries else ""
        of = "" if total is None else f"/{total}"
        line = f"request {r.index}{of} ({req}): {r.outcome} after {r.duration:.1f} s{rec}"
        if r.reason:
            line += f": {r.reason}" + (f" [{r.failure_node}]" if r.failure_node else "")
        self._say(line)

    def _print_summary(self, n: int, ok: int, failed: int, outcome: str) -> None:
        extra = f", {n - ok - failed} not served" if ok + failed < n else ""
        self._say(f"{ok}/{n} requests succeeded, {failed} failed{extra} ({outcome}); log: {self.log_path}")

    def _say(self, line: str, stream: TextIO | None = None) -> None:
        """Write one line of user-facing output (the run's console, not logging). A
        console that went away (a closed ssh session: EIO; a closed pipe: EPIPE) is
        written no more; the run goes on and its event log keeps the record."""
        s = stream if stream is not None else self.out
        if id(s) in self._dead_streams:
            return
        try:
            s.write(printable(line) + "\n")  # report messages, requests and reasons are user text
            s.flush()
        except OSError as e:
            self._dead_streams.add(id(s))
            log.debug("console output off: %s", e)
