"""ur_rtde in a child process: the interfaces live there, the parent calls them with deadlines.

Why a process (docs/protocols.md 4.3, and measured with ur_rtde 1.6.5): the
constructors of ``RTDEReceiveInterface`` / ``RTDEControlInterface`` hold the Python GIL
while they wait for the controller, with no deadline of their own. A controller that
accepts the TCP connection and then never answers, or answers bytes that are not RTDE,
freezes the whole interpreter: no other thread runs, so no watchdog thread can give up
on the call, and Ctrl-C is never handled (the Python-level handler needs the GIL). The
methods do release the GIL, but an ur_rtde object can only be used in the process that
made it. So every ur_rtde object of one connection lives in a host process
(``python -m mmexec.drivers.ur.rtde_host``); the parent sends each call over a socket
pair and waits for the answer with a deadline (``Connection.poll`` releases the GIL). A
call that overruns its deadline gets the host killed (SIGKILL), which closes its
connections to the controller, and raises :class:`RTDEHostError`.

The child ignores SIGINT, SIGHUP and SIGTERM (a terminal's Ctrl-C or hang-up reaches
the whole process group, systemd's stop every process of the unit; the parent decides
when the arm stops and stops it through the host, then closes the host),
dies with the parent thread that started it (Linux ``PR_SET_PDEATHSIG``: SIGKILL, so a
crashed parent leaves no host behind), and leaves with ``os._exit`` on ``quit`` or when
the parent's end closes, without running ur_rtde destructors (which can abort the
process or wait forever, doc 4.3). What ur_rtde prints (asio errors after a lost
connection) is logged by the parent at INFO on this module's logger, not written to the
terminal.

Cost: a call is one round trip of a pickled request (about 25 us per round trip measured
on the development machine); :func:`call_all` batches many getters into one.
"""

from __future__ import annotations

import argparse
import builtins
import functools
import logging
import os
import signal
import socket
import subprocess
import sys
import threading
import traceback
from collections.abc import Callable, Mapping, Sequence
from multiprocessing.connection import Connection
from typing import IO, Any

__all__ = [
    "QUIT_GRACE",
    "VENDOR_CLASSES",
    "RTDEHost",
    "RTDEHostError",
    "RTDEHostTimeout",
    "RemoteInterface",
    "call_all",
    "main",
]

log = logging.getLogger(__name__)

#: the ur_rtde classes a host may construct: module -> class names
VENDOR_CLASSES: dict[str, tuple[str, ...]] = {
    "rtde_receive": ("RTDEReceiveInterface",),
    "rtde_control": ("RTDEControlInterface",),
    "rtde_io": ("RTDEIOInterface",),
}
#: [s] how long the host is given to leave after ``quit`` before it is killed
QUIT_GRACE = 1.0
#: exceptions raised again in the parent as themselves (the rest become RTDEHostError)
_PASS_THROUGH = (RuntimeError, TypeError, ValueError, AttributeError, IndexError, KeyError)


class RTDEHostError(RuntimeError):
    """The ur_rtde host process could not start, overran a deadline (and was killed), or is gone."""


class RTDEHostTimeout(RTDEHostError):
    """A call overran its deadline; the host was killed. ``what`` names the call."""

    def __init__(self, message: str, what: str) -> None:
        super().__init__(message)
        self.what = what


class RTDEHost:
    """Parent side of one host process. ``label`` names the controller in messages.

    No I/O in ``__init__``; :meth:`start` spawns the process. Calls are serialised (one
    request in flight); :meth:`kill` may be called from any thread and makes the call in
    flight, and every later one, raise :class:`RTDEHostError` at once."""

    def __init__(self, label: str) -> None:
        self.label = label
        self._proc: subprocess.Popen[bytes] | None = None
        self._conn: Connection | None = None
        self._lock = threading.Lock()
        self._dead = ""

    @property
    def running(self) -> bool:
        return self._proc is not None and self._proc.poll() is None and not self._dead

    @property
    def pid(self) -> int | None:
        return self._proc.pid if self._proc is not None else None

    def start(self, timeout: float) -> None:
        """Spawn the host and wait (at most ``timeout`` s) until it is ready."""
        if self._proc is not None:
            raise RTDEHostError(f"ur_rtde host for {self.label} already started")
        if self._dead:
            raise RTDEHostError(f"ur_rtde host for {self.label}: {self._dead}")
        parent_end, child_end = socket.socketpair()
        try:
            self._proc = subprocess.Popen(
                [sys.executable, "-m", "mmexec.drivers.ur.rtde_host", "--fd", str(child_end.fileno()),
                 "--parent", str(os.getpid())],
                pass_fds=[child_end.fileno()], stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
            )
        except OSError as e:
            parent_end.close()
            raise RTDEHostError(f"cannot start the ur_rtde host for {self.label}: {e.strerror or e}") from None
        finally:
            child_end.close()
        self._conn = Connection(parent_end.detach())
        if self._dead:  # killed while it was being spawned
            self._proc.kill()
        assert self._proc.stdout is not None
        threading.Thread(target=_forward_output, args=(self._proc.stdout, self.label),
                         name=f"ur-rtde-host-log-{self.label}", daemon=True).start()
        self._exchange(None, "start the ur_rtde host process", timeout)

    def construct(self, module: str, cls: str, args: Sequence[Any], *, timeout: float,
                  call_timeout: float, method_timeouts: Mapping[str, float] | None = None) -> RemoteInterface:
        """``module.cls(*args)`` in the host within ``timeout`` s; its methods then get
        ``call_timeout`` s each, or what ``method_timeouts`` gives them by name."""
        if cls not in VENDOR_CLASSES.get(module, ()):
            raise ValueError(f"{module}.{cls} is not a ur_rtde interface the host constructs")
        handle = self._exchange(("new", module, cls, tuple(args)), f"{cls}()", timeout)
        return RemoteInterface(self, int(handle), cls, call_timeout, method_timeouts)

    def call(self, handle: int, method: str, *args: Any, timeout: float) -> Any:
        """``interface.method(*args)`` in the host within ``timeout`` s."""
        return self._exchange(("call", handle, method, args), method, timeout)

    def call_many(self, calls: Sequence[tuple[int, str, tuple[Any, ...]]], timeout: float) -> list[Any]:
        """Several calls in one round trip (stops at the first that raises)."""
        what = "+".join(dict.fromkeys(m for _, m, _ in calls))
        result: list[Any] = self._exchange(("batch", tuple(calls)), what, timeout)
        return result

    def kill(self, reason: str = "killed") -> None:
        """SIGKILL the host now (thread-safe); its connections to the controller close."""
        self._dead = self._dead or reason
        proc = self._proc
        if proc is not None and proc.poll() is None:
            proc.kill()

    def close(self, timeout: float = QUIT_GRACE) -> None:
        """Ask the host to quit; kill it if it has not left within ``timeout`` s. Idempotent."""
        proc, conn = self._proc, self._conn
        if proc is None:
            return
        if not self._dead and proc.poll() is None and self._lock.acquire(timeout=timeout):
            try:
                assert conn is not None
                conn.send(("quit",))
            except OSError as e:
                log.debug("ur_rtde host for %s: quit: %s", self.label, e)
            finally:
                self._lock.release()
        self._dead = self._dead or "closed"
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            log.warning("ur_rtde host for %s did not quit within %.1f s; killing it", self.label, timeout)
            proc.kill()
            proc.wait()
        if conn is not None:
            conn.close()

    # -- internals
    def _exchange(self, request: tuple[Any, ...] | None, what: str, timeout: float) -> Any:
        """Send ``request`` (None: only read, for the ready message) and return the answer."""
        if self._dead:
            raise RTDEHostError(f"ur_rtde host for {self.label} is gone ({self._dead})")
        if self._conn is None:
            raise RTDEHostError(f"ur_rtde host for {self.label} not started: call start() first")
        with self._lock:
            conn = self._conn
            try:
                if request is not None:
                    conn.send(request)
                ready = conn.poll(max(0.0, timeout))
                reply = conn.recv() if ready else None
            except (OSError, EOFError):
                reply = None
                ready = True
            if reply is None:
                reason = (f"ur_rtde {what} did not return within {timeout:.2f} s" if not ready
                          else f"ur_rtde host for {self.label} exited ({self._describe_exit()})")
                if self._dead and self._dead != "closed":
                    reason = f"ur_rtde {what}: {self._dead}"
                self.kill(reason)
                if not ready:
                    raise RTDEHostTimeout(reason, what)
                raise RTDEHostError(reason)
        status, value, *rest = reply
        if status == "ok":
            return value
        message = rest[0] if rest else ""
        exc_type = getattr(builtins, value, None)
        if isinstance(exc_type, type) and issubclass(exc_type, _PASS_THROUGH):
            raise exc_type(message)
        raise RTDEHostError(f"ur_rtde {what}: {value}: {message}")

    def _describe_exit(self) -> str:
        proc = self._proc
        if proc is None:
            return "not started"
        try:
            code = proc.wait(0.2)
        except subprocess.TimeoutExpired:
            return "its connection closed"
        if code >= 0:
            return f"status {code}"
        try:
            return f"killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"killed by signal {-code}"


class RemoteInterface:
    """Stands in for one ur_rtde interface living in a host: ``iface.getActualQ()`` runs
    there with the interface's call deadline, and raises what ur_rtde raised."""

    def __init__(self, host: RTDEHost, handle: int, name: str, timeout: float,
                 method_timeouts: Mapping[str, float] | None = None) -> None:
        self.host, self.handle, self.name, self.timeout = host, handle, name, timeout
        self.method_timeouts = dict(method_timeouts or {})

    def __getattr__(self, method: str) -> Callable[..., Any]:
        if method.startswith("_"):
            raise AttributeError(method)
        timeout = self.method_timeouts.get(method, self.timeout)
        return functools.partial(self.host.call, self.handle, method, timeout=timeout)

    def __repr__(self) -> str:
        return f"<{self.name} in ur_rtde host pid {self.host.pid} for {self.host.label}>"


def call_all(calls: Sequence[tuple[Any, str]]) -> list[Any]:
    """``[obj.method() for obj, method in calls]``, in one round trip when every object is
    a :class:`RemoteInterface` of the same host (e.g. the arm's per-cycle state read)."""
    hosts = {obj.host for obj, _ in calls if isinstance(obj, RemoteInterface)}
    if len(hosts) == 1 and all(isinstance(obj, RemoteInterface) for obj, _ in calls):
        (host,) = hosts
        timeout = max(obj.timeout for obj, _ in calls)
        return host.call_many([(obj.handle, m, ()) for obj, m in calls], timeout)
    return [getattr(obj, m)() for obj, m in calls]


def _forward_output(stream: IO[bytes], label: str) -> None:
    """Log what ur_rtde prints in the host (parent thread; ends when the host exits)."""
    with stream:
        for raw in iter(stream.readline, b""):
            line = raw.decode("utf-8", "replace").rstrip()
            if line:
                log.info("ur_rtde host for %s: %s", label, line)


# --------------------------------------------------------------------------- child side


def _die_with_parent(parent: int) -> None:
    """SIGKILL this process when the parent thread that started it ends (Linux)."""
    if sys.platform.startswith("linux"):
        import ctypes

        pr_set_pdeathsig = 1
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(pr_set_pdeathsig, int(signal.SIGKILL), 0, 0, 0) != 0:
            log.warning("prctl(PR_SET_PDEATHSIG) failed: %s", os.strerror(ctypes.get_errno()))
    if os.getppid() != parent:  # the parent ended before the line above took effect
        os._exit(1)


def _serve(conn: Connection) -> None:
    objects: dict[int, Any] = {}
    conn.send(("ok", os.getpid()))
    while True:
        try:
            request = conn.recv()
        except (EOFError, OSError):
            return
        op = request[0]
        if op == "quit":
            return
        try:
            if op == "new":
                _, module, cls, args = request
                if cls not in VENDOR_CLASSES.get(module, ()):
                    raise ValueError(f"{module}.{cls} is not a ur_rtde interface")
                objects[len(objects) + 1] = getattr(__import__(module), cls)(*args)
                value: Any = len(objects)
            elif op == "call":
                _, handle, method, args = request
                value = getattr(objects[handle], method)(*args)
            elif op == "batch":
                value = [getattr(objects[h], m)(*a) for h, m, a in request[1]]
            else:
                raise ValueError(f"unknown request {op!r}")
        except Exception as e:  # noqa: BLE001 - every vendor error goes back to the caller, which raises it
            conn.send(("err", type(e).__name__, " ".join(str(e).split())))
        else:
            conn.send(("ok", value))


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the host process (started by :meth:`RTDEHost.start`); never returns."""
    ap = argparse.ArgumentParser(prog="python -m mmexec.drivers.ur.rtde_host", description=__doc__.splitlines()[0])
    ap.add_argument("--fd", type=int, required=True, help="inherited socket to the parent")
    ap.add_argument("--parent", type=int, required=True, help="pid of the parent process")
    args = ap.parse_args(argv)
    for sig in (signal.SIGINT, signal.SIGHUP, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)
    logging.basicConfig(level=logging.WARNING, format="rtde_host: %(message)s")
    _die_with_parent(args.parent)
    status = 0
    try:
        _serve(Connection(args.fd))
    except BaseException:  # noqa: BLE001 - reported (the parent logs it), then the process ends
        traceback.print_exc()
        status = 1
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)  # no ur_rtde destructors: the parent disconnected explicitly (doc 4.3)


if __name__ == "__main__":
    raise SystemExit(main())
