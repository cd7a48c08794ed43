"""Robotiq 2F-85 wired through a UR arm: the Robotiq URCap's text server on TCP 63352.

Requests are ASCII lines: ``SET VAR n [VAR n ...]`` answered ``ack``; ``GET VAR`` answered
``VAR n``, or ``VAR ?`` while the robot is emergency-stopped. Writable: ACT, GTO, ATR,
ARD, POS, SPE, FOR (the Modbus fields, 0..255); read-only: STA (gSTA), PRE (gPR), OBJ
(gOBJ), FLT (gFLT); ``GET POS`` reads the measured position (as ur_rtde uses it).

:class:`RobotiqURCap` gives the same goals and grasp semantics as the Modbus device
(:class:`~mmexec.drivers.robotiq.core.RobotiqDevice`): a command is one ``SET`` line with
GTO last, a status poll is seven ``GET`` lines. Every socket wait has a deadline
(``reply_timeout`` per answer, ``connect_timeout`` to connect); a ``?`` answer puts the
device in the ESTOP link state and fails running goals with a clear reason.
"""

from __future__ import annotations

import logging
import socket
import time
from dataclasses import dataclass

from mmexec.drivers.interfaces import Clock
from mmexec.drivers.robotiq.codec import Command, Status
from mmexec.drivers.robotiq.core import DeviceSettings, RobotiqDevice
from mmexec.drivers.robotiq.errors import (
    EmergencyStopped,
    RobotiqCorruptFrame,
    RobotiqLinkLost,
    RobotiqPortUnavailable,
    RobotiqTimeout,
)

__all__ = ["URCAP_PORT", "RobotiqURCap", "URCapSettings", "encode_set", "parse_get_reply"]

log = logging.getLogger(__name__)

URCAP_PORT = 63352
_STATUS_VARS = ("ACT", "GTO", "STA", "OBJ", "FLT", "PRE", "POS")


@dataclass(frozen=True)
class URCapSettings:
    """``host`` of the UR controller, ``port`` 63352; ``connect_timeout`` and
    ``reply_timeout`` [s] bound every socket wait."""

    host: str
    port: int = URCAP_PORT
    connect_timeout: float = 2.0
    reply_timeout: float = 0.5

    def __post_init__(self) -> None:
        if not 0 < self.port < 65536:
            raise ValueError(f"port {self.port} outside 1..65535")
        if not self.connect_timeout > 0 or not self.reply_timeout > 0:
            raise ValueError("connect_timeout and reply_timeout must be > 0 s")


def encode_set(cmd: Command) -> bytes:
    """The ``SET`` line writing every field of ``cmd`` (GTO last, so the target, speed and
    force are in place before the go bit)."""
    return (f"SET ACT {int(cmd.rACT)} ATR {int(cmd.rATR)} ARD {int(cmd.rARD)} POS {cmd.rPR} "
            f"SPE {cmd.rSP} FOR {cmd.rFR} GTO {int(cmd.rGTO)}\n").encode("ascii")


def parse_get_reply(var: str, line: str) -> int | None:
    """Value of a ``GET var`` answer; None for ``?`` (e-stop). ValueError if malformed."""
    words = line.split()
    if len(words) != 2 or words[0] != var:
        raise ValueError(f"expected '{var} <int>', got {line!r}")
    if words[1] == "?":
        return None
    value = int(words[1])
    if not 0 <= value <= 255:
        raise ValueError(f"{var} value {value} outside 0..255")
    return value


class RobotiqURCap(RobotiqDevice):
    """A 2F-85 behind a UR controller's URCap. Construction does no I/O: call :meth:`open`."""

    def __init__(self, link: URCapSettings, settings: DeviceSettings | None = None,
                 clock: Clock | None = None) -> None:
        super().__init__(settings, clock)
        self.link = link
        self._sock: socket.socket | None = None
        self._rx = bytearray()

    @property
    def _addr(self) -> str:
        return f"{self.link.host}:{self.link.port}"

    @property
    def where(self) -> str:
        return f"robotiq urcap {self._addr}"

    def _connect(self) -> None:
        try:
            sock = socket.create_connection((self.link.host, self.link.port),
                                            timeout=self.link.connect_timeout)
        except ConnectionRefusedError as e:
            raise RobotiqPortUnavailable(self._addr, "robotiq urcap: connection refused (is "
                                         "the Robotiq URCap installed and the controller "
                                         "on?)") from e
        except TimeoutError as e:
            raise RobotiqPortUnavailable(self._addr, "robotiq urcap: no answer within the "
                                         f"deadline ({self.link.connect_timeout:g} s to "
                                         "connect)") from e
        except OSError as e:
            raise RobotiqPortUnavailable(self._addr, f"robotiq urcap: cannot connect ({e})") \
                from e
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._sock = sock
        self._rx.clear()

    def _disconnect(self) -> None:
        sock, self._sock = self._sock, None
        if sock is not None:
            try:
                sock.close()
            except OSError as e:
                log.debug("%s: close: %s", self.where, e)

    def request(self, line: bytes) -> str:
        """Send one request line, return the answer line (without newline) within
        ``reply_timeout``; raises RobotiqTimeout / RobotiqLinkLost."""
        sock = self._sock
        if sock is None:
            raise RobotiqLinkLost(self._addr, "robotiq urcap: not connected (call open() first)")
        deadline = time.monotonic() + self.link.reply_timeout
        try:
            sock.settimeout(self.link.reply_timeout)
            sock.sendall(line)
            while b"\n" not in self._rx:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise TimeoutError
                sock.settimeout(remaining)
                chunk = sock.recv(4096)
                if not chunk:
                    raise RobotiqLinkLost(self._addr, "robotiq urcap: link lost (connection "
                                          "closed by the controller)")
                self._rx += chunk
        except TimeoutError as e:
            self._rx.clear()
            raise RobotiqTimeout(self._addr, "robotiq urcap: no answer within the deadline "
                                 f"({self.link.reply_timeout * 1000:.0f} ms) to "
                                 f"{line.decode().strip()!r}") from e
        except OSError as e:
            raise RobotiqLinkLost(self._addr, f"robotiq urcap: link lost ({e})") from e
        answer, _, rest = bytes(self._rx).partition(b"\n")
        self._rx[:] = rest
        return answer.decode("ascii", "replace").strip()

    def _write_command(self, cmd: Command) -> None:
        answer = self.request(encode_set(cmd))
        if answer != "ack":
            raise RobotiqCorruptFrame(self._addr, f"robotiq urcap: expected 'ack', got {answer!r}")

    def _read_status(self) -> Status:
        values: dict[str, int] = {}
        for var in _STATUS_VARS:
            self._check_closing()
            answer = self.request(f"GET {var}\n".encode("ascii"))
            try:
                v = parse_get_reply(var, answer)
            except ValueError as e:
                raise RobotiqCorruptFrame(self._addr, f"robotiq urcap: corrupt answer ({e})") \
                    from e
            if v is None:
                raise EmergencyStopped(f"{self.where}: the robot is emergency-stopped "
                                       f"(URCap answered '{var} ?')")
            values[var] = v
        try:
            return Status(bool(values["ACT"]), bool(values["GTO"]), values["STA"], values["OBJ"],
                          values["FLT"], 0, values["PRE"], values["POS"], 0)
        except ValueError as e:
            raise RobotiqCorruptFrame(self._addr, f"robotiq urcap: impossible status ({e})") \
                from e
