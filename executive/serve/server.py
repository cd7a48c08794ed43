"""``mmexec serve MISSION --config CONFIG [--bind HOST:PORT]``: run the service.

The tick loop runs in the main thread, exactly as ``mmexec run`` (its clock, its
signal handlers and safety contract, its event log); uvicorn serves the API from a
second thread on a socket opened before anything starts (a port in use is one located
line, exit 2). Bound to anything but loopback, every call needs the token, from the
config's ``serve.token_file`` or made at start and printed once.
"""

from __future__ import annotations

import ipaddress
import logging
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TextIO

import uvicorn

from mmexec.config.yamlload import InputError
from mmexec.executive.runner import ArgMark, RunOptions
from mmexec.executive.serve.app import create_app
from mmexec.executive.serve.service import ServeRunner, Service
from mmexec.executive.serve.settings import load_token

__all__ = ["DEFAULT_BIND", "BindAddress", "ServerThread", "open_socket", "parse_bind", "serve"]

log = logging.getLogger(__name__)

DEFAULT_BIND = "127.0.0.1:8765"
#: [wall s] how long the HTTP server may take to start, and to stop
SERVER_START_LIMIT = 10.0
SERVER_STOP_LIMIT = 5.0


@dataclass(frozen=True)
class BindAddress:
    """Where the API listens. ``loopback``: only this machine can connect (no token)."""

    host: str
    port: int

    @property
    def loopback(self) -> bool:
        if self.host == "localhost":
            return True
        try:
            return ipaddress.ip_address(self.host).is_loopback
        except ValueError:
            return False  # a host name: it may resolve to anything

    def url(self, port: int | None = None) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port if port is None else port}"


def parse_bind(text: str, option: str = "--bind", example: str = DEFAULT_BIND) -> BindAddress:
    """``HOST:PORT`` (``[::1]:8765`` for IPv6); port 0 picks a free one. InputError
    located at ``option`` (``--foxglove`` uses it too)."""
    mark = ArgMark(option, 0, 0)
    host, sep, port = text.rpartition(":")
    host = host[1:-1] if host.startswith("[") and host.endswith("]") else host
    if not sep or not host or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise InputError.at(mark, f"expected HOST:PORT with a port in 0..65535, e.g. {example}, got {text!r}")
    return BindAddress(host, int(port))


def open_socket(addr: BindAddress) -> socket.socket:
    """A listening TCP socket at ``addr``; InputError (located at ``--bind``) when the
    address cannot be used (in use, not this machine's, no permission)."""
    mark = ArgMark("--bind", 0, 0)
    try:
        infos = socket.getaddrinfo(addr.host, addr.port, type=socket.SOCK_STREAM)
    except socket.gaierror as e:
        raise InputError.at(mark, f"cannot resolve {addr.host!r}: {e.strerror}") from None
    family, _, _, _, sockaddr = infos[0]
    sock = socket.socket(family, socket.SOCK_STREAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(sockaddr)
        sock.listen(128)
    except OSError as e:
        sock.close()
        raise InputError.at(mark, f"cannot listen on {addr.host}:{addr.port}: {e.strerror or e}") from None
    sock.set_inheritable(False)
    return sock


class ServerThread:
    """uvicorn serving ``app`` on ``sock`` from a daemon thread (no signal handlers of
    its own: the main thread's tick loop owns the signals)."""

    def __init__(self, app: Any, sock: socket.socket) -> None:
        config = uvicorn.Config(app, log_config=None, log_level="warning", access_log=False, lifespan="off")
        self.server = uvicorn.Server(config)
        self.sock = sock
        self.thread = threading.Thread(target=self.server.run, kwargs={"sockets": [sock]},
                                       name="mmexec-serve-http", daemon=True)

    def start(self) -> None:
        """Start and wait until it serves; RuntimeError when it could not start."""
        self.thread.start()
        deadline = time.monotonic() + SERVER_START_LIMIT
        while not self.server.started:
            if not self.thread.is_alive() or time.monotonic() > deadline:
                raise RuntimeError("the HTTP server did not start (see the log above)")
            time.sleep(0.01)

    def stop(self) -> None:
        self.server.should_exit = True
        self.thread.join(SERVER_STOP_LIMIT)
        if self.thread.is_alive():
            log.warning("the HTTP server was still stopping after %g s", SERVER_STOP_LIMIT)


def serve(options: RunOptions, bind: str, *, out: TextIO, err: TextIO,
          check: Callable[[ServeRunner], None] | None = None,
          made: Callable[[ServeRunner], None] | None = None) -> int:
    """Load everything (InputError on bad input), listen, then run the executive until
    it is stopped (the API's stop, or a signal). ``made`` is told the runner once built,
    ``check`` checks it once prepared (the CLI's ``--param`` check). Returns the exit
    code: 0 stopped, 128 + signal, 1 a failed event log."""
    addr = parse_bind(bind)
    service = Service()
    runner = ServeRunner(options, service, out=out, err=err)
    if made is not None:
        made(runner)
    runner.prepare()
    if check is not None:
        check(runner)
    assert runner.config is not None
    token, from_file = (None, False) if addr.loopback else load_token(
        service.settings, runner.config.path, runner.config.mark("serve"))
    sock = open_socket(addr)
    server = ServerThread(create_app(service, token=token), sock)
    try:
        server.start()
        port = sock.getsockname()[1]
        url = addr.url(port)
        runner.say(f"mmexec serve: {getattr(runner.mission, 'name', '')} on backend {runner.config.backend!r}: "
                   f"{url}/api/status, stream {url.replace('http', 'ws', 1)}/api/stream, API description {url}/docs, "
                   f"console {url}/console/")
        if token is not None:
            where = runner.config.path.parent / str(service.settings.token_file) if from_file else token
            runner.say(f"token: {where} (every call needs 'Authorization: Bearer TOKEN')")
        return runner.run()
    finally:
        server.stop()
        sock.close()
