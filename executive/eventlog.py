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
``halt``                why the runner halted the tree (``interrupt``, ``timeout``)
``request_end``         index, outcome (``success``, ``failure``, ``timeout``,
                        ``interrupted``), duration [clock s], recoveries, attempts,
                        reason, failure_kind, failure_node
``run_end``             outcome (``ok``, ``failed``, ``interrupted``, ``error``), requests,
                        succeeded, failed, duration [clock s], exit_code
======================  ===================================================================

Each record is written with one ``write`` call on a line-buffered file and then flushed,
so a crash or Ctrl-C loses at most the record being written; :func:`read_log` skips a
truncated last line.
"""

from __future__ import annotations

import enum
import json
import logging
import math
import os
from collections.abc import Callable, Iterator
from datetime import UTC, datetime
from pathlib import Path
from typing import IO, Any, Self

__all__ = ["EventLog", "LogFormatError", "read_log", "to_jsonable"]

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


class EventLog:
    """Append-only JSON-lines writer.

    ``clock`` (a callable returning clock seconds) stamps each record with ``t`` unless
    the record has one. ``path=None`` keeps records only in :attr:`records` (tests,
    ``mmexec validate``). Every record is also kept in memory when ``keep`` is True.
    Use as a context manager or call :meth:`close`.
    """

    def __init__(self, path: str | Path | None, *, clock: Callable[[], float] | None = None,
                 keep: bool = False) -> None:
        self.path = Path(path) if path is not None else None
        self.clock = clock
        self.keep = keep or path is None
        self.records: list[dict[str, Any]] = []
        self._fh: IO[str] | None = None
        self._seq = 0
        self._listeners: list[Callable[[dict[str, Any]], None]] = []

    def open(self) -> Self:
        """Create (truncate) the file. Raises OSError if it cannot be created."""
        if self.path is not None and self._fh is None:
            if self.path.parent and not self.path.parent.exists():
                self.path.parent.mkdir(parents=True, exist_ok=True)
            # line-buffered; the handle lives as long as this log (closed by close()/__exit__),
            # so it cannot be a with block here: EventLog itself is the context manager
            self._fh = open(self.path, "w", encoding="utf-8", buffering=1)  # noqa: SIM115
        return self

    def __enter__(self) -> Self:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def closed(self) -> bool:
        return self._fh is None

    def add_listener(self, fn: Callable[[dict[str, Any]], None]) -> None:
        """Call ``fn(record)`` after each record is written (e.g. live counters)."""
        self._listeners.append(fn)

    def write(self, event: str, **fields: Any) -> dict[str, Any]:
        """Write one record and flush it. Returns the record as written."""
        record: dict[str, Any] = {"event": event, "seq": self._seq}
        if "t" not in fields and self.clock is not None:
            record["t"] = self.clock()
        record.update(fields)
        record = to_jsonable(record)
        self._seq += 1
        if self._fh is not None:
            self._fh.write(json.dumps(record, separators=(",", ":"), allow_nan=False) + "\n")
            self._fh.flush()
        if self.keep:
            self.records.append(record)
        for fn in self._listeners:
            fn(record)
        return record

    def emit(self, event: str, **fields: Any) -> None:
        """:class:`~mmexec.executive.context.ExecContext` event sink (same as :meth:`write`)."""
        self.write(event, **fields)

    def sync(self) -> None:
        """Flush and fsync (the runner calls this at the end of a run and on interrupt)."""
        if self._fh is not None:
            self._fh.flush()
            try:
                os.fsync(self._fh.fileno())
            except OSError as e:  # e.g. a pipe or /dev/stdout: flushing is all there is
                log.debug("fsync of %s not possible: %s", self.path, e)

    def close(self) -> None:
        if self._fh is not None:
            self.sync()
            self._fh.close()
            self._fh = None

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
