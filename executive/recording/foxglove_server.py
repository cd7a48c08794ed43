"""A live Foxglove WebSocket server (``--foxglove [HOST:PORT]``), built on foxglove-sdk.

The server advertises every channel of
:data:`~mmexec.executive.recording.channels.CHANNELS` and sends a channel's messages only
while a client subscribes to it; pose, scan and camera are read for it at the ``serve:``
section's wall-clock rates (``pose_hz``, ``scan_hz``, ``camera_hz``), like the console's
streams. It advertises the ``time`` capability and sends the robot's clock (sim time in
sim) every tick, so Foxglove's clock follows the run. The map, the path and the tree are
sent once when they change; a client subscribing later gets the latest one at the next
tick. The server is read-only (no client publishing, parameters or services) and has no
authentication: bound to anything but loopback it warns that anyone who reaches the port
sees the robot's streams.

Foxglove's protocol is the ``foxglove.websocket.v1`` one; foxglove-sdk 0.30 names its
WebSocket subprotocol ``foxglove.sdk.v1`` (the same messages) and refuses a client that
offers only the old name (a client may offer both).
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any

import foxglove
from foxglove.websocket import Capability, ChannelView, Client

from mmexec.config.yamlload import InputError
from mmexec.executive.recording.channels import (
    CAMERA,
    CHANNELS,
    MAP,
    PATH,
    POSE,
    SCAN,
    TF,
    TREE,
    ChannelSpec,
)
from mmexec.executive.runner import ArgMark
from mmexec.executive.serve.server import BindAddress
from mmexec.executive.serve.settings import ServeSettings

__all__ = ["DEFAULT_FOXGLOVE", "FoxgloveServer"]

log = logging.getLogger(__name__)

#: Where ``--foxglove`` listens when no address is given (the API of ``mmexec serve``
#: has 8765).
DEFAULT_FOXGLOVE = "127.0.0.1:8766"
#: Channels whose latest message a late subscriber gets.
_LATCHED = (MAP, PATH, TREE)
#: The channels that carry each costly stream topic.
_CARRIERS = {"pose": (POSE, TF), "scan": (SCAN, TF), "camera": (CAMERA, TF)}


class FoxgloveServer:
    """A :class:`~mmexec.executive.recording.channels.ChannelOutput` serving the channels
    to Foxglove clients at ``addr`` (see the module doc). :meth:`start` before the run,
    :meth:`close` after; the tick thread writes, the server's threads only tell it about
    subscriptions."""

    def __init__(self, addr: BindAddress, settings: ServeSettings | None = None, *, name: str = "mmexec") -> None:
        self.addr = addr
        self.settings = settings if settings is not None else ServeSettings()
        self.name = name
        self.server: Any = None
        self._context = foxglove.Context()
        self._channels: dict[str, foxglove.Channel] = {}
        self._latest: dict[str, tuple[bytes, int]] = {}
        self._lock = threading.Lock()
        self._resend: set[str] = set()  # latched topics a client just subscribed to
        self._due: dict[str, float] = {}

    @property
    def port(self) -> int:
        return int(self.server.port) if self.server is not None else self.addr.port

    def start(self, channels: tuple[ChannelSpec, ...] = CHANNELS) -> None:
        """Listen and advertise ``channels``; InputError (at ``--foxglove``) when the
        address cannot be used."""
        for spec in channels:
            schema = foxglove.Schema(name=spec.schema_name, encoding=spec.schema_encoding, data=spec.schema_data)
            self._channels[spec.topic] = foxglove.Channel(spec.topic, schema=schema,
                                                          message_encoding=spec.message_encoding,
                                                          context=self._context)
        try:
            self.server = foxglove.start_server(name=self.name, host=self.addr.host, port=self.addr.port,
                                                capabilities=[Capability.Time], server_listener=self,
                                                context=self._context)
        except RuntimeError as e:
            raise InputError.at(ArgMark("--foxglove", 0, 0),
                                f"cannot listen on {self.addr.host}:{self.addr.port}: {e}") from None
        if not self.addr.loopback:
            log.warning("the Foxglove server on %s:%d has no authentication: anyone who reaches it sees the "
                        "robot's streams", self.addr.host, self.port)

    def url(self) -> str:
        host = f"[{self.addr.host}]" if ":" in self.addr.host else self.addr.host
        return f"ws://{host}:{self.port}"

    # ServerListener (server threads)
    def on_subscribe(self, client: Client, channel: ChannelView) -> None:
        if channel.topic in _LATCHED:
            with self._lock:
                self._resend.add(channel.topic)

    def on_unsubscribe(self, client: Client, channel: ChannelView) -> None:
        """Nothing to undo: a channel nobody subscribes to is not sent."""

    # ChannelOutput (tick thread)
    def write(self, topic: str, data: bytes, log_time: int) -> None:
        if topic in _LATCHED:
            self._latest[topic] = (data, log_time)
        channel = self._channels[topic]
        if channel.has_sinks():
            channel.log(data, log_time=log_time)

    def takes(self, topic: str, t: float) -> bool:
        if not any(self._channels[c].has_sinks() for c in _CARRIERS[topic]):
            return False
        s = self.settings
        hz = {"pose": s.pose_hz, "scan": s.scan_hz, "camera": s.camera_hz}[topic]
        now = time.monotonic()
        if now < self._due.get(topic, 0.0):
            return False
        self._due[topic] = now + 1.0 / hz
        return True

    def tick(self, log_time: int) -> None:
        if self.server is None:
            return
        self.server.broadcast_time(log_time)
        with self._lock:
            resend, self._resend = self._resend, set()
        for topic in sorted(resend):
            if topic in self._latest:
                data, at = self._latest[topic]
                self._channels[topic].log(data, log_time=at)

    def close(self) -> None:
        """Stop serving (idempotent)."""
        server, self.server = self.server, None
        if server is not None:
            server.stop()
