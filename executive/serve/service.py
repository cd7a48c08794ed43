"""The service behind ``mmexec serve``: a request queue fed while the executive runs.

Threads: the tick loop (:class:`ServeRunner`, a :class:`~mmexec.executive.runner.Runner`)
runs in the main thread, as ``mmexec run`` does, keeping its clock and its signal and
safety contract; the HTTP server runs in another thread and talks to the loop only
through :class:`Service`, whose state is locked and whose commands go through a queue
the loop drains between ticks (and while idle). Only the tick thread touches the robot
and writes the event log; the log stays the canonical record and is written exactly as
``run`` writes it, plus the service's own records:

======================  ===================================================================
``request_queued``      id, request (the validated fields): a request was accepted
``request_dropped``     id, request, reason: it left the queue without being served
                        (cancelled by the API, or the service stopped)
``paused`` / ``resumed``  serving new requests was paused / resumed
``stop``                reason: the API asked the service to stop
======================  ===================================================================

A served request's ``request_start`` / ``request_end`` carry its ``id`` (``index`` counts
the requests served, 1, 2, ..., as in a ``run`` log), so every accepted request ends in
exactly one ``request_end`` or ``request_dropped``.

Streams (:class:`Hub`): every event-log record, tree snapshots, status, robot pose, path,
map, scan, camera frames (JPEG, rate-limited, with marker detections), operator prompts,
the running tree's blackboard, the world model's markers and tracked people, each a JSON
message ``{"type": TOPIC, "data": ...}`` (shapes in docs/console.md).
"""

from __future__ import annotations

import asyncio
import base64
import itertools
import json
import logging
import math
import queue
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

from mmexec.drivers.interfaces import CameraFrame, LaserScan, Robot
from mmexec.executive.eventlog import to_jsonable
from mmexec.executive.runner import RequestResult, Runner, RunOptions
from mmexec.executive.serve.console import ConsoleWorld, mission_json
from mmexec.executive.serve.prompts import PromptBoard
from mmexec.executive.serve.settings import ServeSettings, parse_section
from mmexec.skills.operator import OPERATOR_KEY

__all__ = [
    "TOPICS",
    "WORLD_PATH",
    "CameraSample",
    "ConsoleSink",
    "Hub",
    "QueuedRequest",
    "ServeRunner",
    "Service",
    "ServiceError",
    "StreamSink",
    "Streams",
    "TreeView",
    "console_message",
]

log = logging.getLogger(__name__)

#: Stream topics a WebSocket client may subscribe to.
TOPICS = ("status", "tree", "event", "pose", "path", "map", "scan", "camera", "prompt", "blackboard", "markers",
          "people")
#: ``ctx.world`` key where a navigation skill may publish its current path: a list of
#: [x, y] points in ``map`` [m]; streamed as ``path`` whenever it is replaced.
WORLD_PATH = "nav.path"
#: Event-log records kept for ``GET /api/events`` (the console's log tail on connect).
RECENT_EVENTS = 1000
#: Messages a slow WebSocket client may have waiting before new ones are dropped.
CLIENT_QUEUE = 2000
#: [wall s] longest idle wait on a stepped clock before the loop looks again.
IDLE_WAIT = 0.1
#: JPEG quality of streamed camera frames (0..100).
STREAM_JPEG_QUALITY = 70
#: [wall Hz] how often the status is streamed while nothing else changes it
STATUS_HZ = 2.0
_STICKY = ("status", "map", "pose", "path", "blackboard", "markers", "people", "camera")


class ServiceError(Exception):
    """An API call that cannot be done: ``status`` (HTTP 4xx) and a one-line message."""

    def __init__(self, status: int, message: str) -> None:
        super().__init__(message)
        self.status = status
        self.message = message


@dataclass
class QueuedRequest:
    """A request the service accepted: its ``id`` (1, 2, ... in submission order), the
    validated ``fields``, ``state`` (``queued``, ``running``, then the request's outcome
    or ``dropped``) and ``reason`` (why it failed or was dropped)."""

    id: int
    fields: dict[str, Any]
    state: str = "queued"
    reason: str = ""
    duration: float | None = None

    def to_json(self) -> dict[str, Any]:
        return {"id": self.id, "request": dict(self.fields), "state": self.state, "reason": self.reason,
                "duration": self.duration}


# --------------------------------------------------------------------------- streams


@dataclass(eq=False)
class _Client:
    loop: asyncio.AbstractEventLoop
    topics: frozenset[str]
    queue: asyncio.Queue[str] = field(default_factory=lambda: asyncio.Queue(CLIENT_QUEUE))
    dropped: int = 0

    def offer(self, text: str) -> None:
        """In the client's event loop: queue ``text``, or count it dropped when full."""
        try:
            self.queue.put_nowait(text)
        except asyncio.QueueFull:
            self.dropped += 1


class Hub:
    """Fan-out of stream messages from any thread to WebSocket clients, each with its own
    bounded queue in its event loop (a slow client loses messages, counted in
    ``dropped``, and never slows the tick). The last message of each sticky topic
    (status, map, pose, path) is kept and sent first to a new client; the tick loop sends
    it the current tree (:attr:`joined` counts attachments)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._clients: list[_Client] = []
        self._latest: dict[str, str] = {}
        #: clients attached so far (the tick loop sends a new one the current tree)
        self.joined = 0

    def attach(self, loop: asyncio.AbstractEventLoop, topics: Iterable[str]) -> _Client:
        client = _Client(loop, frozenset(topics))
        with self._lock:
            self._clients.append(client)
            self.joined += 1
            for topic, text in self._latest.items():
                if topic in client.topics:
                    client.offer(text)
        return client

    def detach(self, client: _Client) -> None:
        with self._lock:
            if client in self._clients:
                self._clients.remove(client)

    def wants(self, topic: str) -> bool:
        """Whether any client subscribed to ``topic`` (skip costly messages otherwise)."""
        with self._lock:
            return any(topic in c.topics for c in self._clients)

    def publish(self, topic: str, data: Any) -> None:
        """Send ``{"type": topic, "data": data}`` to the clients of ``topic`` (any thread).
        ``data`` is made plain JSON first (a NaN becomes a string), except event records,
        which the event log made so already."""
        sticky = topic in _STICKY
        if not sticky and not self.wants(topic):
            return  # nobody to tell, nothing to keep: no encoding on the tick thread
        payload = data if topic == "event" else to_jsonable(data)
        text = json.dumps({"type": topic, "data": payload}, separators=(",", ":"), allow_nan=False)
        with self._lock:
            if sticky:
                self._latest[topic] = text
            clients = [c for c in self._clients if topic in c.topics]
        for c in clients:
            try:
                c.loop.call_soon_threadsafe(c.offer, text)
            except RuntimeError as e:  # the client's loop closed under it: it is gone
                log.debug("stream client gone: %s", e)
                self.detach(c)

    @property
    def clients(self) -> int:
        with self._lock:
            return len(self._clients)


class TreeView:
    """The running tree's node statuses, rebuilt from event-log records: ``request_start``
    (every node path) and ``node_status`` (a change). :meth:`snapshot` is the ``tree``
    message."""

    def __init__(self) -> None:
        self.request: int | None = None
        self.order: list[str] = []
        self.status: dict[str, str] = {}
        self.changed: set[str] = set()
        self.t = 0.0

    def feed(self, record: Mapping[str, Any]) -> bool:
        """Take one record; returns whether the tree changed."""
        ev = record.get("event")
        if ev == "request_start":
            self.request = record.get("id", record.get("index"))
            self.order = [str(p) for p in record.get("nodes", [])]
            self.status = dict.fromkeys(self.order, "INVALID")
            self.changed = set(self.order)
        elif ev == "node_status" and record.get("path") in self.status:
            self.status[record["path"]] = str(record.get("new"))
            self.changed.add(record["path"])
        else:
            return False
        self.t = float(record.get("t", self.t))
        return True

    def snapshot(self) -> dict[str, Any]:
        nodes = [{"path": p, "name": p.rsplit("/", 1)[-1], "parent": p.rsplit("/", 1)[0] if "/" in p else None,
                  "status": self.status[p]} for p in self.order]
        snap = {"request": self.request, "t": self.t, "nodes": nodes, "changed": sorted(self.changed)}
        self.changed = set()
        return snap


# --------------------------------------------------------------------------- service state


def prompt_json(prompt: dict[str, Any]) -> dict[str, Any]:
    """A prompt's JSON with ``image_url``, where its image is served (null: none)."""
    has = prompt.get("has_image")
    return {**prompt, "image_url": f"/api/prompts/{prompt['id']}/image" if has else None}


class Service:
    """The queue and state shared by the HTTP thread and the tick loop (see module doc).

    Methods for the HTTP thread validate and answer at once (raising
    :class:`ServiceError`); what the tick loop must do or log goes through the command
    queue it drains with :meth:`commands`.
    """

    def __init__(self, mission: Any = None, settings: ServeSettings | None = None) -> None:
        self.mission = mission
        self.settings = settings if settings is not None else ServeSettings()
        self.hub = Hub()
        self.prompts = PromptBoard(notify=self._on_prompt)
        self._lock = threading.Lock()
        self._queue: deque[QueuedRequest] = deque()
        self._finished: deque[QueuedRequest] = deque(maxlen=self.settings.history)
        self._current: QueuedRequest | None = None
        self._ids = itertools.count(1)
        self._commands: queue.SimpleQueue[tuple[Any, ...]] = queue.SimpleQueue()
        self._wake = threading.Event()
        self.paused = False
        self.stopping = False
        self.state = "starting"
        self.counts = {"accepted": 0, "served": 0, "succeeded": 0, "failed": 0, "dropped": 0}
        self.t = 0.0
        self.tip = ""
        self.info: dict[str, Any] = {}  # mission, backend, log: see set_info
        self.mission_info: dict[str, Any] | None = None  # GET /api/mission (see describe)
        self._recent: deque[dict[str, Any]] = deque(maxlen=RECENT_EVENTS)

    def configure(self, mission: Any, settings: ServeSettings) -> None:
        """Set the mission requests are checked against and the settings (before serving)."""
        info = mission_json(mission)
        with self._lock:
            self.mission = mission
            self.mission_info = info
            self.settings = settings
            self._finished = deque(self._finished, maxlen=settings.history)

    # ---------------------------------------------------------------- HTTP thread

    def submit(self, body: Any) -> QueuedRequest:
        """Queue a request: ``body`` is a JSON object of request fields, checked exactly as
        ``--request`` is (a field left out takes its declared default; a list or dict field
        may also be given as JSON). 422 bad fields, 409 stopping, 429 queue full."""
        where = "POST /api/requests"
        if not isinstance(body, dict):
            raise ServiceError(422, f"{where}: expected a JSON object of request fields, e.g. {{\"item\": 3}}")
        for k, v in body.items():  # a JSON list or object only for a field declared list or dict
            if isinstance(v, (dict, list)) and self.mission.request_fields.get(k) not in (list, dict):
                raise ServiceError(422, f"{where}: request field {k!r}: expected a scalar value")
        try:
            fields = dict(self.mission.validate_request(body))
        except ValueError as e:
            raise ServiceError(422, f"{where}: {e}") from None
        with self._lock:
            if self.stopping:
                raise ServiceError(409, f"{where}: the service is stopping; no new requests")
            if len(self._queue) >= self.settings.max_queue:
                raise ServiceError(429, f"{where}: the queue is full ({self.settings.max_queue} requests waiting)")
            req = QueuedRequest(next(self._ids), fields)
            self._queue.append(req)
            self.counts["accepted"] += 1
            self._commands.put(("queued", req))
        self._changed()
        return req

    def cancel(self, rid: int) -> QueuedRequest:
        """Cancel request ``rid``: a queued one is dropped at once (state ``dropped``); the
        running one is halted (state stays ``running`` until it has stopped: ``halting``
        is set in ``reason``). 404 unknown, 409 already ended."""
        with self._lock:
            for req in self._queue:
                if req.id == rid:
                    self._queue.remove(req)
                    self._drop(req, "cancelled through the API")
                    break
            else:
                req = self._running_or_error(rid)
                self._commands.put(("halt", rid, "cancelled through the API"))
                req.reason = "halting"
        self._changed()
        return req

    def halt(self) -> QueuedRequest:
        """Halt the running request (409 when none runs)."""
        with self._lock:
            req = self._current
            if req is None:
                raise ServiceError(409, "POST /api/halt: no request is running")
            self._commands.put(("halt", req.id, "halted through the API"))
            req.reason = "halting"
        return req

    def set_paused(self, paused: bool) -> dict[str, Any]:
        """Pause (or resume) taking requests from the queue; a running one goes on."""
        with self._lock:
            if self.stopping:
                raise ServiceError(409, f"POST /api/{'pause' if paused else 'resume'}: the service is stopping")
            if self.paused != paused:
                self.paused = paused
                self._commands.put(("paused" if paused else "resumed",))
        self._changed()
        return self.status()

    def stop(self) -> dict[str, Any]:
        """Stop the service: halt the running request, drop the queue, close the robot."""
        with self._lock:
            if not self.stopping:
                self.stopping = True
                self._commands.put(("stop", "stopped through the API"))
        self._changed()
        return self.status()

    def current_id(self) -> int | None:
        with self._lock:
            return self._current.id if self._current is not None else None

    def get(self, rid: int) -> QueuedRequest:
        with self._lock:
            for req in itertools.chain(self._queue, [self._current] if self._current else [], self._finished):
                if req.id == rid:
                    return req
        raise ServiceError(404, f"request {rid}: no such request (or it left the history of "
                                f"{self.settings.history})")

    def requests(self) -> dict[str, Any]:
        with self._lock:
            return {"current": self._current.to_json() if self._current else None,
                    "queued": [r.to_json() for r in self._queue],
                    "finished": [r.to_json() for r in reversed(self._finished)]}

    def status(self) -> dict[str, Any]:
        with self._lock:
            state = self.state
            if state == "idle" and self.paused:
                state = "paused"
            if self.stopping and state not in ("stopped",):
                state = "stopping"
            return {
                **self.info, "state": state, "paused": self.paused, "t": self.t, "tip": self.tip,
                "current": self._current.to_json() if self._current else None, "queued": len(self._queue),
                "counts": dict(self.counts), "prompts": [p.id for p in self.prompts.open_prompts()],
                "clients": self.hub.clients,
            }

    def _running_or_error(self, rid: int) -> QueuedRequest:
        if self._current is not None and self._current.id == rid:
            return self._current
        for req in self._finished:
            if req.id == rid:
                raise ServiceError(409, f"request {rid}: already ended ({req.state})")
        raise ServiceError(404, f"request {rid}: no such request")

    def _drop(self, req: QueuedRequest, reason: str) -> None:
        req.state, req.reason = "dropped", reason
        self._finished.append(req)
        self.counts["dropped"] += 1
        self._commands.put(("dropped", req, reason))

    def _changed(self) -> None:
        self._wake.set()

    def describe(self) -> dict[str, Any]:
        """The mission as the console shows it (``GET /api/mission``: request fields, node
        kinds and branch labels, see :func:`~mmexec.executive.serve.console.mission_json`)."""
        with self._lock:
            info, mission = self.mission_info, self.mission
        if info is None:
            if mission is None:
                raise ServiceError(409, "GET /api/mission: no mission is loaded yet")
            info = mission_json(mission)
            with self._lock:
                self.mission_info = info
        return info

    def events(self, limit: int) -> list[dict[str, Any]]:
        """The last ``limit`` event-log records (at most :data:`RECENT_EVENTS`), oldest first."""
        with self._lock:
            recent = list(self._recent)
        return recent[-limit:] if limit > 0 else []

    def keep_event(self, record: dict[str, Any]) -> None:
        """Keep an event-log record for :meth:`events` (tick thread)."""
        with self._lock:
            self._recent.append(record)

    def open_prompts(self) -> list[dict[str, Any]]:
        """The open prompts as the API and the stream show them (P in docs/console.md)."""
        return [prompt_json(p.to_json()) for p in self.prompts.open_prompts()]

    def _on_prompt(self, kind: str, data: dict[str, Any]) -> None:
        if kind == "prompt":
            data = prompt_json(data)
        self.hub.publish("prompt", {"action": kind, **data})
        self._wake.set()

    # ---------------------------------------------------------------- tick thread

    def commands(self) -> list[tuple[Any, ...]]:
        """Every command queued since the last call, in order (tick thread)."""
        out = []
        while True:
            try:
                out.append(self._commands.get_nowait())
            except queue.Empty:
                return out

    def take(self) -> QueuedRequest | None:
        """The next request to serve (now ``running``), or None (empty, paused, stopping)."""
        with self._lock:
            if self.paused or self.stopping or not self._queue:
                return None
            req = self._current = self._queue.popleft()
            req.state = "running"
            self.state = "running"
        return req

    def finished(self, result: RequestResult) -> None:
        with self._lock:
            req = self._current
            self._current = None
            self.state = "idle"
            self.counts["served"] += 1
            self.counts["succeeded" if result.ok else "failed"] += 1
            if req is not None:
                req.state, req.reason, req.duration = result.outcome, result.reason, result.duration
                self._finished.append(req)

    def drop_all(self, reason: str) -> None:
        """Drop every queued request (the run is ending)."""
        with self._lock:
            while self._queue:
                self._drop(self._queue.popleft(), reason)
            self.stopping = True

    def set_info(self, **fields: Any) -> None:
        """Identity fields shown in the status (mission, backend, log path)."""
        with self._lock:
            self.info = {**self.info, **fields}

    def set_state(self, state: str, t: float | None = None, tip: str | None = None) -> None:
        with self._lock:
            self.state = state
            if t is not None:
                self.t = t
            if tip is not None:
                self.tip = tip

    def wait(self, timeout: float) -> None:
        """Idle wait [wall s] that ends early when something changes (tick thread)."""
        self._wake.wait(timeout)
        self._wake.clear()


# --------------------------------------------------------------------------- the tick loop


class _Tap:
    """Stands in for a robot's camera or lidar on a stepped clock: skills use it as the
    device (every attribute is the device's), and the streams show only what the skills
    last read. Reading the device for the stream would change a seeded run: the
    simulator's sensor noise draws from the run's random stream, and a mock's faults
    count reads."""

    def __init__(self, device: Any) -> None:
        self._device = device
        self.latest: Any = None
        self.reads = 0

    def __getattr__(self, name: str) -> Any:
        return getattr(self._device, name)

    def _keep(self, value: Any) -> Any:
        if value is not None:
            self.latest = value
            self.reads += 1
        return value


class _CameraTap(_Tap):
    def frame(self) -> CameraFrame | None:
        return self._keep(self._device.frame())  # type: ignore[no-any-return]


class _LidarTap(_Tap):
    def scan(self) -> LaserScan | None:
        return self._keep(self._device.scan())  # type: ignore[no-any-return]


def _finite_or_none(values: Iterable[float]) -> list[float | None]:
    return [float(x) if math.isfinite(x) else None for x in values]


@dataclass(frozen=True)
class CameraSample:
    """A camera frame as the streams carry it: the frame and its JPEG bytes (quality
    :data:`STREAM_JPEG_QUALITY`), encoded once for every sink."""

    frame: CameraFrame
    jpeg: bytes


class StreamSink(Protocol):
    """Where :class:`Streams` sends messages: the console (:class:`ConsoleSink`), a Foxglove
    server or an MCAP recording (:mod:`mmexec.executive.recording`). Called in the tick
    thread only; each call returns promptly."""

    def refresh(self, t: float) -> bool:
        """Once per tick (and while a service idles), before anything is sent, at clock
        time ``t`` [s]; True when a viewer that just joined needs the whole tree."""

    def wants(self, topic: str, t: float) -> bool:
        """Whether to send it a ``topic`` message now (its subscriptions, its rates)."""

    def send(self, topic: str, data: Any, t: float) -> None:
        """One message at clock time ``t`` [s]. ``data`` by topic: ``event`` the event-log
        record, ``tree`` a :meth:`TreeView.snapshot`, ``pose`` the base's
        :class:`~mmexec.drivers.interfaces.BaseState`, ``path`` a list of (x, y) in ``map``
        [m], ``map`` the :class:`~mmexec.drivers.interfaces.OccupancyGrid`, ``scan`` a
        :class:`~mmexec.drivers.interfaces.LaserScan`, ``camera`` a :class:`CameraSample`."""


class Streams:
    """The live state of a run as stream messages, read in the tick thread and handed to
    every :class:`StreamSink` that wants them: each event-log record (``event``), the
    tree's statuses (``tree``: at request start, once per tick with changes, before
    ``request_end``), and from the robot the ``map`` (once), ``pose``, ``path``
    (``world[WORLD_PATH]`` when replaced), ``scan`` and ``camera``.

    Sensors are tapped (:class:`_Tap`) on a stepped clock, and on any clock when
    :attr:`tap` is set (a recording asks for it): the streams then carry the newest
    reading a skill took and never read a device themselves, so a seeded run does the same
    with or without anyone watching. Untapped (a wall clock), a sensor is read when a sink
    wants it. Attach with :meth:`Runner.add_log_listener` (:meth:`on_record`) and call
    :meth:`start` once the robot is up, then :meth:`publish` before every tick.
    """

    def __init__(self, world: Mapping[str, Any]) -> None:
        self.world = world
        self.tree = TreeView()
        self.sinks: list[StreamSink] = []
        #: tap the camera and lidar on a wall clock too (what a recording needs)
        self.tap = False
        self._last_path: Any = None
        self._taps: dict[str, _Tap] = {}  # what the skills read, by topic
        self._shown: dict[str, int] = {}  # the tap's read count last sent

    def add_sink(self, sink: StreamSink) -> None:
        self.sinks.append(sink)

    def start(self, robot: Robot) -> None:
        """Once the robot is up, before its first tick: tap its sensors (see the class
        doc) and send the map."""
        if robot.clock.stepped or self.tap:
            if robot.camera is not None:
                robot.camera = self._taps.setdefault("camera", _CameraTap(robot.camera))  # type: ignore[assignment]
            if robot.lidar is not None:
                robot.lidar = self._taps.setdefault("scan", _LidarTap(robot.lidar))  # type: ignore[assignment]
        if robot.occupancy is not None:
            self._send("map", robot.occupancy, robot.clock.now())

    def on_record(self, record: dict[str, Any]) -> None:
        """Event-log listener: the record as ``event``; the tree at request start and,
        with its final statuses, before ``request_end``."""
        ev = record.get("event")
        t = record.get("t")
        t = float(t) if isinstance(t, (int, float)) else self.tree.t
        if ev == "request_end" and self.tree.changed:
            self._send_tree(t)
        self._send("event", record, t)
        if self.tree.feed(record) and ev == "request_start":
            self._send_tree(t)

    def publish(self, robot: Robot) -> None:
        """Before every tick (tick thread): the tree when it changed (or to a sink with a
        new viewer), then pose, path, scan and camera to the sinks that want them now."""
        now = robot.clock.now()
        rejoined = [s for s in self.sinks if s.refresh(now)]  # every sink, every tick
        if self.tree.changed:
            self._send_tree(now)
        elif rejoined and self.tree.order:
            snap = self.tree.snapshot()
            for s in rejoined:
                if s.wants("tree", now):
                    s.send("tree", snap, now)
        if robot.base is not None and (sinks := self._wanting("pose", now)):
            state = robot.base.state()
            for s in sinks:
                s.send("pose", state, now)
        path = self.world.get(WORLD_PATH)
        if path is not self._last_path:
            self._last_path = path
            self._send("path", [(float(x), float(y)) for x, y in path or []], now)
        if robot.lidar is not None and (sinks := self._wanting("scan", now)):
            scan = self._sensor("scan", robot.lidar.scan)
            for s in sinks if scan is not None else ():
                s.send("scan", scan, now)
        if robot.camera is not None and (sinks := self._wanting("camera", now)):
            frame = self._sensor("camera", robot.camera.frame)
            if frame is not None:
                import cv2

                ok, buf = cv2.imencode(".jpg", frame.rgb[:, :, ::-1], [cv2.IMWRITE_JPEG_QUALITY, STREAM_JPEG_QUALITY])
                if ok:
                    sample = CameraSample(frame, bytes(buf))
                    for s in sinks:
                        s.send("camera", sample, now)

    def _wanting(self, topic: str, t: float) -> list[StreamSink]:
        return [s for s in self.sinks if s.wants(topic, t)]  # asks each one: rates are kept per sink

    def _send(self, topic: str, data: Any, t: float) -> None:
        for s in self._wanting(topic, t):
            s.send(topic, data, t)

    def _send_tree(self, t: float) -> None:
        sinks = self._wanting("tree", t)
        snap = self.tree.snapshot()  # resets the changed set, wanted or not
        for s in sinks:
            s.send("tree", snap, t)

    def _sensor(self, topic: str, read: Callable[[], Any]) -> Any:
        """The reading to send: where tapped the newest one a skill got (None when
        nothing new), else a fresh ``read()``."""
        tap = self._taps.get(topic)
        if tap is None:
            return read()
        if tap.reads == self._shown.get(topic, 0):
            return None
        self._shown[topic] = tap.reads
        return tap.latest


def console_message(topic: str, data: Any, t: float) -> Any:
    """The console stream's JSON ``data`` for a :class:`Streams` message (docs/console.md)."""
    if topic == "pose":
        return {"t": t, "x": data.pose.x, "y": data.pose.y, "theta": data.pose.theta, "v": data.v, "w": data.w}
    if topic == "path":
        return {"t": t, "points": [[x, y] for x, y in data]}
    if topic == "map":
        return {"width": data.width, "height": data.height, "resolution": data.resolution,
                "origin": [data.origin.x, data.origin.y, data.origin.theta],
                "data": base64.b64encode(data.data.astype("int8").tobytes()).decode("ascii")}
    if topic == "scan":
        return {"t": data.stamp, "angle_min": data.angle_min, "angle_increment": data.angle_increment,
                "range_min": data.range_min, "range_max": data.range_max, "ranges": _finite_or_none(data.ranges)}
    if topic == "camera":
        h, w = data.frame.rgb.shape[:2]
        return {"t": data.frame.stamp, "width": int(w), "height": int(h),
                "jpeg": base64.b64encode(data.jpeg).decode("ascii")}
    return data  # event records and tree snapshots are JSON already


class ConsoleSink:
    """The console's :class:`StreamSink`: messages to the service's :class:`Hub` as JSON,
    pose, scan and camera at the ``serve:`` section's wall-clock rates, the status twice a
    second; a client that joined gets the whole tree at the next tick."""

    def __init__(self, service: Service, detect: Callable[[Any], list[dict[str, Any]]] | None = None) -> None:
        self.service = service
        self.detect = detect  # markers on a camera frame's RGB image, sent with it (ConsoleWorld.detections)
        self._joined = 0  # stream clients seen so far
        self._due: dict[str, float] = {}
        self._pose: Any = None  # the base pose of this tick, sent with a scan (the console draws it from there)

    def refresh(self, t: float) -> bool:
        hub = self.service.hub
        joined = hub.joined != self._joined
        self._joined = hub.joined
        if self._is_due("status", STATUS_HZ):
            hub.publish("status", self.service.status())
        return joined

    def wants(self, topic: str, t: float) -> bool:
        if topic in ("map", "path"):
            return True  # sticky: kept for the clients still to come
        if topic == "pose":  # every tick (a scan goes with its pose); sent at pose_hz
            return self.service.hub.wants("pose") or self.service.hub.wants("scan")
        s = self.service.settings
        hz = {"pose": s.pose_hz, "scan": s.scan_hz, "camera": s.camera_hz}.get(topic)
        return self.service.hub.wants(topic) and (hz is None or self._is_due(topic, hz))

    def send(self, topic: str, data: Any, t: float) -> None:
        if topic == "pose":
            self._pose = data.pose
            if not (self.service.hub.wants("pose") and self._is_due("pose", self.service.settings.pose_hz)):
                return
        message = console_message(topic, data, t)
        if topic == "scan":
            m = data.T_base_lidar  # the lidar's mount in base_link, planar: [x, y, yaw]
            message["lidar"] = [float(m[0][3]), float(m[1][3]), math.atan2(float(m[1][0]), float(m[0][0]))]
            message["pose"] = None if self._pose is None else [self._pose.x, self._pose.y, self._pose.theta]
        elif topic == "camera" and self.detect is not None:
            message["detections"] = self.detect(data.frame.rgb)
        self.service.hub.publish(topic, message)

    def _is_due(self, topic: str, hz: float) -> bool:
        """Rate limit [wall Hz]: True at most ``hz`` times a second per topic."""
        now = time.monotonic()
        if now < self._due.get(topic, 0.0):
            return False
        self._due[topic] = now + 1.0 / hz
        return True


class ServeRunner(Runner):
    """A :class:`Runner` whose requests come from a :class:`Service` until it is stopped
    (through the API, or by SIGINT / SIGTERM / SIGHUP with ``run``'s safety contract).
    Between requests it waits: on a wall clock spinning the robot each period, on a
    stepped clock without stepping (the simulated world holds still while idle)."""

    def __init__(self, options: RunOptions, service: Service, **kw: Any) -> None:
        super().__init__(options, **kw)
        self.service = service
        self.world[OPERATOR_KEY] = service.prompts
        #: the live streams: to the console, and to Foxglove / MCAP sinks added before run()
        self.streams = Streams(self.world)
        #: the browser console's own streams (blackboard, markers, people) and marker detections
        self.console = ConsoleWorld(service, self.world)
        self.streams.add_sink(ConsoleSink(service, detect=self.console.detections))
        self.streams.add_sink(self.console)
        self._period = 0.05
        self._request_id = 0  # the service id of the request being served
        self.add_log_listener(self.streams.on_record)
        self.add_tick_hook(self._between_ticks)

    def prepare(self) -> None:
        """As :meth:`Runner.prepare`, then the config's ``serve:`` section (InputError)."""
        super().prepare()
        assert self.config is not None
        self.mission = self.console.watch(self.mission)  # the console streams each tree's blackboard
        settings = parse_section(self.config.config.serve, self.config.mark("serve"))
        self.service.configure(self.mission, settings)
        self.service.set_info(mission=getattr(self.mission, "name", ""), backend=self.config.backend)

    def say(self, line: str) -> None:
        """One line for the operator on the run's console (escaped; a console gone away is
        written no more)."""
        self._say(line)

    def _validate_requests(self, mission: Any) -> list[dict[str, Any]]:
        return []  # requests arrive through the service

    def _total(self) -> int | None:
        return None

    def _request_tags(self, index: int) -> dict[str, Any]:
        return {"id": self._request_id}

    def _next_request(self, served: int) -> tuple[int, dict[str, Any]] | None:
        assert self.robot is not None and self.log is not None
        svc = self.service
        if served == 0:
            self._started()
        while True:
            self._apply_commands()
            if self.interrupted or self.stop_requested or self.log.error is not None:
                return None
            req = svc.take()
            if req is not None:
                self._apply_commands()  # its request_queued record comes before request_start
                self._request_id = req.id
                return served + 1, req.fields
            svc.set_state("idle", t=self.robot.clock.now(), tip="")
            self._publish(self.robot)
            if self.robot.clock.stepped:
                svc.wait(IDLE_WAIT)
            else:
                self._spin(self.robot, self._period, self._interrupts, ending=False)

    def _record(self, result: RequestResult, total: int | None) -> None:
        self._served += 1
        self._succeeded += result.ok
        self.service.finished(result)
        self._print_result(result, total)
        self._publish_status()

    def _end_queue(self) -> None:
        self._apply_commands()
        signum = self.signal
        reason = "the service stopped" if signum is None else "the service was interrupted"
        self.service.drop_all(reason)
        self._apply_commands()
        self.service.set_state("stopped")
        self._publish_status()

    def _started(self) -> None:
        assert self.robot is not None and self.config is not None and self.log is not None
        rate = self.options.rate_hz if self.options.rate_hz is not None else self.config.config.rate_hz
        self._period = 1.0 / rate
        self.service.set_info(backend=self.config.backend, log=str(self.log_path))
        self.streams.start(self.robot)  # taps the sensors, sends the map
        self.console.start(self.robot)

    # tick thread: between ticks of a request, and while idle
    def _between_ticks(self, robot: Robot, period: float) -> None:
        self._apply_commands()
        if not self.interrupted:  # a signalled halt is not held back for the operator
            self.service.prompts.pace(robot, period)
        self.service.set_state("running", t=robot.clock.now())
        self._publish(robot)

    def _apply_commands(self) -> None:
        assert self.log is not None
        elog = self.log
        cmds = self.service.commands()
        for cmd in cmds:
            kind = cmd[0]
            if kind == "queued":
                elog.write("request_queued", id=cmd[1].id, request=cmd[1].fields)
            elif kind == "dropped":
                elog.write("request_dropped", id=cmd[1].id, request=cmd[1].fields, reason=cmd[2])
            elif kind in ("paused", "resumed"):
                elog.write(kind)
            elif kind == "halt":
                if self.service.current_id() == cmd[1]:
                    self.halt_request(cmd[2])
            elif kind == "stop":
                elog.write("stop", reason=cmd[1])
                self.request_stop()
        if cmds:
            self._publish_status()

    def _publish_status(self) -> None:
        self.service.hub.publish("status", self.service.status())

    def _publish(self, robot: Robot) -> None:
        tree = self.streams.tree
        if tree.changed:
            self.service.set_state(self.service.state, tip=self._tip())
        self.streams.publish(robot)

    def _tip(self) -> str:
        tree = self.streams.tree
        running = [p for p in tree.order if tree.status.get(p) == "RUNNING"]
        return running[-1] if running else ""
