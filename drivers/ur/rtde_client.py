"""A small RTDE client in pure Python: our codec over a socket, a deadline on every read.

It runs where ur_rtde cannot be trusted to return: ur_rtde 1.6.5's constructors hold the
GIL with no deadline of their own (docs/protocols.md 4.3), so before any of them is
called the arm adapter checks here that the controller answers the RTDE handshake
within ``connect_timeout`` (:func:`probe`), and ``mmexec hw ping ur`` reads the
controller's state and link quality with it (:class:`RTDESession`, :func:`link_quality`).

Errors are one line, ``HOST:PORT: reason``: :class:`RTDEUnreachable` when no connection
could be opened (refused, no route, unknown host, connect timeout), :class:`RTDEClientError`
when the peer was reached but did not answer as an RTDE server should (silence, bytes
that are not RTDE, ``NOT_FOUND`` variables, a refused request, a closed connection).
Deadlines are on ``time.monotonic()`` (a link property, not mission time).
"""

from __future__ import annotations

import itertools
import logging
import math
import socket
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Self

from mmexec.drivers.ur import rtde_codec as codec
from mmexec.drivers.ur.rtde_codec import PackageType

__all__ = [
    "LinkStats",
    "RTDEClientError",
    "RTDESession",
    "RTDEUnreachable",
    "Snapshot",
    "link_quality",
    "probe",
]

log = logging.getLogger(__name__)


class RTDEClientError(RuntimeError):
    """The RTDE peer did not answer as expected. ``str()`` is one line naming host:port;
    ``detail`` is the reason alone."""

    def __init__(self, where: str, detail: str) -> None:
        super().__init__(f"{where}: {detail}")
        self.where = where
        self.detail = detail


class RTDEUnreachable(RTDEClientError):
    """No connection could be opened at all (refused, no route, bad name, connect timeout)."""


@dataclass(frozen=True)
class Snapshot:
    """One data package: the controller's version and the recipe's values by name."""

    version: codec.ControllerVersion
    values: dict[str, Any]


@dataclass(frozen=True)
class LinkStats:
    """Link quality over a stream of data packages.

    ``frames`` received; ``lost``: frames the controller's timestamps show were never
    received (a gap of k periods is k - 1 lost); ``late``: frames delivered more than
    ``late_after`` seconds behind the best-delivered one (arrival minus controller
    timestamp, compared with its minimum over the stream)."""

    frames: int
    lost: int
    late: int
    duration: float

    @property
    def ratio(self) -> float:
        """Lost plus late frames over the frames the controller sent (0 when none)."""
        expected = self.frames + self.lost
        return (self.lost + self.late) / expected if expected else 0.0

    def __str__(self) -> str:
        return (f"{self.frames} frames, {self.lost} lost, {self.late} late over {self.duration:.1f} s "
                f"({100.0 * self.ratio:.1f} %)")


def link_quality(stamps: Sequence[float], arrivals: Sequence[float], period: float, late_after: float) -> LinkStats:
    """:class:`LinkStats` of frames with controller ``stamps`` [s] received at ``arrivals``
    [s, local monotonic], streamed every ``period`` [s]. Pure function."""
    if len(stamps) != len(arrivals):
        raise ValueError(f"{len(stamps)} stamps but {len(arrivals)} arrival times")
    if not period > 0:
        raise ValueError(f"period must be > 0 s, got {period}")
    lost = 0
    for a, b in itertools.pairwise(stamps):
        steps = round((b - a) / period)
        lost += max(0, steps - 1)
    late = 0
    if stamps:
        delays = [t - s for s, t in zip(stamps, arrivals)]
        best = min(delays)
        late = sum(1 for d in delays if d - best > late_after)
    duration = arrivals[-1] - arrivals[0] if arrivals else 0.0
    return LinkStats(len(stamps), lost, late, duration)


class RTDESession:
    """One RTDE connection driven step by step; every answer is awaited at most
    ``timeout`` seconds, and never past ``deadline`` (``time.monotonic()``) if given.
    A wait the deadline ended is reported as ``no answer within DEADLINE_TEXT`` when
    ``deadline_text`` is given (e.g. "5.0 s", the budget the deadline came from), with
    the time that was left otherwise.

    No I/O in ``__init__``. :meth:`abort` (from any thread) ends a wait at once."""

    def __init__(self, host: str, port: int, timeout: float, *, deadline: float | None = None,
                 deadline_text: str = "") -> None:
        if not (math.isfinite(timeout) and timeout > 0):
            raise ValueError(f"timeout must be a number of seconds > 0, got {timeout}")
        self.host, self.port, self.timeout, self.deadline = host, port, timeout, deadline
        self.deadline_text = deadline_text
        self.where = f"{host}:{port}"
        self._sock: socket.socket | None = None
        self._buf = b""
        self._recipes: dict[int, list[str]] = {}
        self._names: list[str] = []
        self._aborted = threading.Event()
        self.messages: list[codec.TextMessage] = []

    # -- lifecycle
    def open(self) -> codec.ControllerVersion:
        """Connect, agree on protocol version 2 and return the controller's version."""
        timeout = self._left(self.timeout)
        try:
            sock = socket.create_connection((self.host, self.port), timeout=timeout)
        except ConnectionRefusedError:
            raise RTDEUnreachable(self.where, "connection refused (is the controller on and RTDE enabled?)") from None
        except TimeoutError:
            raise RTDEUnreachable(self.where, f"cannot connect within {timeout:.1f} s (is the host up?)") from None
        except OSError as e:
            raise RTDEUnreachable(self.where, str(e.strerror or e)) from None
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._sock = sock
        if self._aborted.is_set():
            self.close()
            raise RTDEClientError(self.where, "aborted")
        if not codec.decode_accepted(self._request(codec.encode_request_protocol_version(2),
                                                   PackageType.REQUEST_PROTOCOL_VERSION)):
            raise RTDEClientError(self.where, "controller refused RTDE protocol version 2")
        return self._decode(codec.decode_controller_version,
                            self._request(codec.encode_get_controller_version(), PackageType.GET_URCONTROL_VERSION))

    def setup_outputs(self, frequency: float, variables: Sequence[str]) -> None:
        """Ask for an output recipe; NOT_FOUND names and a refusal raise."""
        payload = self._request(codec.encode_setup_outputs(frequency, variables),
                                PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS)
        rid, types = self._decode(codec.decode_setup_reply, payload)
        missing = [n for n, t in zip(variables, types) if t == codec.NOT_FOUND]
        if missing:
            raise RTDEClientError(self.where, f"controller answered NOT_FOUND for {', '.join(missing)}")
        if rid == 0 or len(types) != len(variables):
            raise RTDEClientError(self.where, f"controller refused the output recipe at {frequency:g} Hz")
        self._recipes = {rid: types}
        self._names = list(variables)

    def start(self) -> None:
        """Start streaming data packages."""
        if not self._decode(codec.decode_accepted,
                            self._request(codec.encode_start(), PackageType.CONTROL_PACKAGE_START)):
            raise RTDEClientError(self.where, "controller refused to start streaming")

    def read(self) -> tuple[float, dict[str, Any]]:
        """The next data package: its local arrival time [s, monotonic] and values by name."""
        payload = self._receive(PackageType.DATA_PACKAGE)
        arrival = time.monotonic()
        _, values = self._decode(codec.decode_data, payload, self._recipes)
        return arrival, dict(zip(self._names, values))

    def pause(self) -> None:
        """Ask the controller to stop streaming and wait for its answer."""
        self._request(codec.encode_pause(), PackageType.CONTROL_PACKAGE_PAUSE)

    def abort(self) -> None:
        """End any wait now (thread-safe): the waiting call raises ``aborted``."""
        self._aborted.set()
        sock = self._sock
        if sock is not None:
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError as e:  # not connected (any more): no wait to end
                log.debug("%s: abort: %s", self.where, e)

    def close(self) -> None:
        sock, self._sock = self._sock, None
        if sock is not None:
            sock.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- internals
    def _left(self, step: float) -> float:
        if self.deadline is None:
            return step
        left = self.deadline - time.monotonic()
        if left <= 0:
            raise RTDEClientError(self.where, f"no answer within {self.deadline_text or 'the deadline'}")
        return min(step, left)

    def _decode(self, fn: Any, *args: Any) -> Any:
        try:
            return fn(*args)
        except codec.RTDECodecError as e:
            raise RTDEClientError(self.where, f"corrupt RTDE reply ({e})") from None

    def _request(self, frame: bytes, expect: int) -> bytes:
        assert self._sock is not None, "open() first"
        try:
            self._sock.sendall(frame)
        except OSError as e:
            raise RTDEClientError(self.where, str(e.strerror or e)) from None
        return self._receive(expect)

    def _receive(self, expect: int) -> bytes:
        """Payload of the next package of type ``expect`` (others are skipped; text
        messages are kept in :attr:`messages`)."""
        assert self._sock is not None, "open() first"
        wait = self._left(self.timeout)
        end = time.monotonic() + wait
        within = self.deadline_text if self.deadline_text and wait < self.timeout else f"{wait:.1f} s"
        while True:
            try:
                packages, rest = codec.split_packages(self._buf, strict=True)
            except codec.RTDECodecError as e:
                raise RTDEClientError(self.where, f"corrupt RTDE reply ({e}): not an RTDE server?") from None
            for i, p in enumerate(packages):
                if p.type == PackageType.TEXT_MESSAGE:
                    self.messages.append(self._decode(codec.decode_text_message, p.payload))
                elif p.type == expect:
                    self._buf = b"".join(codec.encode_package(q.type, q.payload) for q in packages[i + 1:]) + rest
                    return p.payload
            self._buf = rest
            left = end - time.monotonic()
            if left <= 0:
                got = f"; {len(self._buf)} bytes of an incomplete package" if self._buf else ""
                said = f"; controller said: {self.messages[-1].message}" if self.messages else ""
                raise RTDEClientError(self.where, f"no answer within {within} (waiting for '{chr(expect)}'{got}{said})")
            self._sock.settimeout(left)
            try:
                chunk = self._sock.recv(65536)
            except TimeoutError:
                continue
            except OSError as e:
                raise RTDEClientError(self.where, str(e.strerror or e)) from None
            if self._aborted.is_set():
                raise RTDEClientError(self.where, "aborted")
            if not chunk:
                raise RTDEClientError(self.where, "controller closed the connection")
            self._buf += chunk


def probe(session: RTDESession, variables: Sequence[str], *, frequency: float = 10.0) -> Snapshot:
    """One short RTDE exchange on ``session`` (V, v, O, S, one U, P), which is closed
    afterwards: the controller's version and one sample of ``variables``. Another thread
    may :meth:`RTDESession.abort` the session meanwhile. Raises :class:`RTDEClientError`."""
    with session as s:
        version = s.open()
        s.setup_outputs(frequency, variables)
        s.start()
        _, values = s.read()
        s.pause()
    return Snapshot(version, values)
