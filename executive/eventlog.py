"""The run's event log: JSON lines, one record per line, flushed as written.

Every record is a JSON object with at least ``event`` (the record type) and ``seq``
(0, 1, 2, ... in write order); records written during a run also carry ``t``, the clock
time [s] of the backend, counted from its start (sim time in sim, wall-clock seconds on
the robot). Record types written by the runner:

======================  ===================================================================
``run_start``           mission path + sha256, config path + sha256, backend, seed, argv,
                        versions (python, mmexec, py_trees), rate_hz, number of requests
``request_start``       request index (1-based), of, the request mapping, mission sha256,
                        ``nodes``: every node path of the fresh tree, in tree order
``node_status``         path, old, new (py_trees status names), t
``skill_*`` / ``recovery_*`` / ``report`` ...   events emitted by the tree and skills
                        (``node`` path, ``t``, and event fields)
``mission_reload``      ``--watch``: ok, mission sha256, problems (list of lines)
``halt``                why the runner halted the tree (``interrupt``, ``timeout``); for an
                        interrupt the ``signal`` (``SIGINT``, ``SIGTERM``, ``SIGHUP``)
``halt_abandoned``      the tree was still stopping: reason (a second signal, the wall limit)
``request_end``         index, outcome (``success``, ``failure``, ``timeout``,
                        ``interrupted``, ``error``), duration [clock s], recoveries,
                        attempts, reason, failure_kind, failure_node
``run_end``             outcome (``ok``, ``failed``, ``interrupted``, ``error``), requests,
                        succeeded, failed, duration [clock s], exit_code; ``signal`` when
                        a signal ended the run
======================  ===================================================================

Each record is one line handed to the kernel with ``os.write`` (no user-space buffer),
so a crash or a signal loses at most the record being written; :func:`read_log` skips a
truncated last line.

A log is never shared or silently replaced: :meth:`EventLog.open` creates the file
exclusively (``O_EXCL``; with ``overwrite`` an existing regular file is truncated, but
only once its lock is held), never follows a symbolic link (``O_NOFOLLOW``), refuses
anything but a regular file, and holds an exclusive ``flock`` until :meth:`EventLog.close`,
so a second writer is refused (:class:`LogInUseError`). A write that fails (a full disk:
``ENOSPC``; a file size limit: ``EFBIG``) cuts the file back to its last complete record,
so every line stays valid JSON; the log then stops writing (:attr:`EventLog.error` holds
the error, later records are only counted in :attr:`EventLog.dropped`) and its owner
decides what to do (the runner stops the robot and ends the run).
"""

from __future__ import annotations

import enum
import errno
import fcntl
import json
import logging
import math
import os
import stat
from collections.abc import Callable, Iterator
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Self

__all__ = [
    "EventLog",
    "LogExistsError",
    "LogFormatError",
    "LogInUseError",
    "LogOpenError",
    "read_log",
    "to_jsonable",
]

log = logging.getLogger(__name__)


class LogFormatError(ValueError):
    """An event log line that is not a JSON object (other than a truncated last line)."""


def to_jsonable(value: Any) -> Any:
    """Convert ``value`` into plain JSON types: enums by value/name, numpy arrays and
    scalars to lists / numbers, tuples and sets to lists, non-finite floats to strings,
    anything else to ``str``."""
    if value is None or isinstance(value, (bool, int, str)):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else str(value)
    if isinstance(value, dict):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, set, frozenset)):
        items = sorted(value, key=str) if isinstance(value, (set, frozenset)) else value
        return [to_jsonable(v) for v in items]
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, enum.Enum):
        return value.value if isinstance(value.value, (str, int, float)) else value.name
    tolist = getattr(value, "tolist", None)
    if callable(tolist):
        return to_jsonable(tolist())
    return str(value)


class LogOpenError(Exception):
    """The event log file cannot be opened for this run: ``str(e)`` is ``PATH: reason``,
    one line; :attr:`path`, :attr:`reason` and :attr:`errno` (None when no system call
    failed) separately."""

    def __init__(self, path: Path, reason: str, err: int | None = None) -> None:
        super().__init__(f"{path}: {reason}")
        self.path = path
        self.reason = reason
        self.errno = err


class LogExistsError(LogOpenError):
    """The path already exists and replacing it was not asked for (``overwrite``)."""


class LogInUseError(LogOpenError):
    """Another process holds the lock of this log (it is writing it)."""


def _open_exclusive(path: Path, *, overwrite: bool) -> int:
    """Open ``path`` for writing a new log: a file descriptor holding an exclusive
    ``flock``, at offset 0 of an empty regular file. Raises :class:`LogOpenError`."""
    parent = path.parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise LogOpenError(path, f"cannot create its folder {parent}: {e.strerror or e}", e.errno) from None
    # O_NONBLOCK: opening a FIFO must not wait for a reader (it is refused below)
    flags = os.O_WRONLY | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC
    if not overwrite:
        flags |= os.O_EXCL  # also refuses a symlink, dangling or not, without following it
    try:
        fd = os.open(path, flags, 0o644)
    except FileExistsError:
        if path.is_symlink():
            raise LogOpenError(path, "is a symbolic link (an event log is never written through one)",
                               errno.EEXIST) from None
        if path.is_dir():
            raise LogOpenError(path, "is a directory, expected an event log file", errno.EISDIR) from None
        if not path.is_file():
            raise LogOpenError(path, "is not a regular file", errno.EEXIST) from None
        raise LogExistsError(path, "already exists", errno.EEXIST) from None
    except IsADirectoryError:
        raise LogOpenError(path, "is a directory, expected an event log file", errno.EISDIR) from None
    except OSError as e:
        if e.errno == errno.ELOOP:
            raise LogOpenError(path, "is a symbolic link (an event log is never written through one)",
                               e.errno) from None
        if e.errno == errno.ENXIO:  # a FIFO nobody reads
            raise LogOpenError(path, "is not a regular file", e.errno) from None
        raise LogOpenError(path, f"cannot open for writing: {e.strerror or e}", e.errno) from None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise LogOpenError(path, "is not a regular file")
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise LogInUseError(path, "is in use: another process holds its lock (another run writing it?)",
                                errno.EWOULDBLOCK) from None
        os.ftruncate(fd, 0)  # only now: a log in use by another writer is left untouched
        os.set_blocking(fd, True)
    except LogOpenError:
        os.close(fd)
        raise
    except OSError as e:
        os.close(fd)
        raise LogOpenError(path, f"cannot prepare for writing: {e.strerror or e}", e.errno) from None
    return fd


class EventLog:
    """Append-only JSON-lines writer.

    ``clock`` (a callable returning clock seconds) stamps each record with ``t`` unless
    the record has one. ``path=None`` keeps records only in :attr:`records` (tests,
    ``mmexec validate``). Every record is also kept in memory when ``keep`` is True.
    ``overwrite``: replace an existing regular file (never a symlink, never a log another
    process holds). Use as a context manager or call :meth:`close`.

    Writing never raises: the first failed write is kept in :attr:`error` (the file is cut
    back to its last complete record) and later records are not written but counted in
    :attr:`dropped`; listeners and :attr:`records` still get every record.
    """

    def __init__(self, path: str | Path | None, *, clock: Callable[[], float] | None = None,
                 keep: bool = False, overwrite: bool = False) -> None:
        self.path = Path(path) if path is not None else None
        self.clock = clock
        self.keep = keep or path is None
        self.overwrite = overwrite
        self.records: list[dict[str, Any]] = []
        #: the OSError of the first failed write (or final fsync); None while all is well
        self.error: OSError | None = None
        #: records not written because of :attr:`error`
        self.dropped = 0
        self._fd: int | None = None
        self._size = 0  # bytes of complete records in the file
        self._seq = 0
        self._listeners: list[Callable[[dict[str, Any]], None]] = []

    def open(self) -> Self:
        """Create the file (see the module doc), creating missing parent folders.
        Raises :class:`LogOpenError` (:class:`LogExistsError`, :class:`LogInUseError`)."""
        if self.path is not None and self._fd is None:
            self._fd = _open_exclusive(self.path, overwrite=self.overwrite)
            self._size = 0
        return self

    def __enter__(self) -> Self:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def closed(self) -> bool:
        return self._fd is None

    def add_listener(self, fn: Callable[[dict[str, Any]], None]) -> None:
        """Call ``fn(record)`` after each record is written (e.g. live counters)."""
        self._listeners.append(fn)

    def write(self, event: str, **fields: Any) -> dict[str, Any]:
        """Write one record (one line, handed to the kernel at once). Returns the record.
        Never raises for I/O: see :attr:`error`."""
        record: dict[str, Any] = {"event": event, "seq": self._seq}
        if "t" not in fields and self.clock is not None:
            record["t"] = self.clock()
        record.update(fields)
        record = to_jsonable(record)
        self._seq += 1
        if self._fd is not None:
            self._append((json.dumps(record, separators=(",", ":"), allow_nan=False) + "\n").encode("utf-8"))
        if self.keep:
            self.records.append(record)
        for fn in self._listeners:
            fn(record)
        return record

    def emit(self, event: str, **fields: Any) -> None:
        """:class:`~mmexec.executive.context.ExecContext` event sink (same as :meth:`write`)."""
        self.write(event, **fields)

    @staticmethod
    def _write_some(fd: int, data: bytes) -> int:
        """One ``write(2)``: the number of bytes the kernel took (tests inject faults here)."""
        return os.write(fd, data)

    def _append(self, line: bytes) -> None:
        assert self._fd is not None
        if self.error is not None:
            self.dropped += 1
            return
        view = memoryview(line)
        try:
            while view:
                n = self._write_some(self._fd, view)
                if n <= 0:
                    raise OSError(errno.EIO, "write(2) took no bytes")
                view = view[n:]
        except OSError as e:
            self._failed(e)
            return
        self._size += len(line)

    def _failed(self, e: OSError) -> None:
        """Keep the first write error; cut a partly written record off the file."""
        self.error = e
        self.dropped += 1
        assert self._fd is not None
        try:
            os.ftruncate(self._fd, self._size)  # frees space, so it works on a full disk too
        except OSError as te:  # the reader still skips a truncated last line
            log.warning("%s: could not remove a partly written record: %s", self.path, te)
        log.debug("%s: write failed after %d bytes: %s", self.path, self._size, e)

    def sync(self) -> None:
        """fsync the file (the runner calls this at the end of a run); an error is kept in
        :attr:`error` like a failed write."""
        if self._fd is not None:
            try:
                os.fsync(self._fd)
            except OSError as e:
                if self.error is None:
                    self.error = e
                log.warning("%s: fsync failed: %s", self.path, e)

    def close(self) -> None:
        """fsync, release the lock and close. Idempotent."""
        if self._fd is not None:
            self.sync()
            fd, self._fd = self._fd, None
            os.close(fd)  # releases the flock

    @staticmethod
    def wall_time() -> str:
        """Current UTC date-time (ISO 8601) for the ``run_start`` record; identity only,
        never used for timing."""
        return datetime.now(UTC).isoformat(timespec="seconds")


def read_log(path: str | Path) -> list[dict[str, Any]]:
    """Read every record of an event log. A truncated last line (the process died while
    writing it) is skipped; any other bad line raises :class:`LogFormatError` naming
    ``FILE:LINE``. OSError propagates."""
    return list(iter_log(path))


def iter_log(path: str | Path) -> Iterator[dict[str, Any]]:
    p = Path(path)
    with open(p, "rb") as fh:
        data = fh.read()
    lines = data.split(b"\n")
    complete = data.endswith(b"\n")
    for i, raw in enumerate(lines, start=1):
        if not raw.strip():
            continue
        last = i == len(lines) and not complete
        try:
            rec = json.loads(raw.decode("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as e:
            if last:
                log.warning("%s:%d: skipping a truncated last record", p, i)
                return
            raise LogFormatError(f"{p}:{i}: not a JSON event record ({e})") from None
        if not isinstance(rec, dict) or "event" not in rec:
            raise LogFormatError(f"{p}:{i}: not an event record (expected a JSON object with 'event')")
        yield rec
