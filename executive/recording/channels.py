"""The Foxglove channels of a run, and the sink that fills them from the live streams.

Every channel uses a schema Foxglove's panels understand: the well-known ``foxglove.*``
protobuf schemas (encoded by foxglove-sdk) for the robot, JSON with a JSON schema for
the executive's own records.

================  =========================  ==============================================
topic             schema                     what
================  =========================  ==============================================
``/tf``           foxglove.FrameTransforms   ``map`` -> ``base_link`` with each pose;
                                             ``base_link`` -> ``lidar`` / ``camera`` with
                                             each scan / frame (their mounts)
``/pose``         foxglove.PoseInFrame       the base pose in ``map``
``/map``          foxglove.Grid              the occupancy grid in ``map``: field
                                             ``occupancy`` (int8: 0 free .. 100 occupied,
                                             -1 unknown) and ``red green blue alpha``
``/scan``         foxglove.LaserScan         in ``lidar``; no return is NaN
``/camera``       foxglove.CompressedImage   JPEG, in ``camera`` (the optical frame)
``/path``         foxglove.PosesInFrame      the planned path in ``map``
                                             (``ctx.world["nav.path"]``), empty: none
``/mmexec/tree``  mmexec.TreeStatus (JSON)   the tree's statuses: at request start, then
                                             once per clock instant at which nodes changed
``/mmexec/events``  mmexec.Event (JSON)      every event-log record, exactly as written
``/mmexec/log``   foxglove.Log               every event-log record as one readable line
                                             (node changes at debug level)
================  =========================  ==============================================

Times: a message's log time is the run's start (``run_start.started``, wall clock) plus
the clock time [s] at which it was recorded (sim time in sim), in nanoseconds; header
timestamps are the readings' own stamps on the same base. The event-derived channels
(tree, events, log) are a function of the event log alone, so a recording made live and
one converted from the run's log afterwards (``mmexec log export``) hold the same
messages on them.
"""

from __future__ import annotations

import json
import logging
import math
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import datetime
from typing import Any, Protocol

import numpy as np
from foxglove.messages import (
    CompressedImage,
    FrameTransform,
    FrameTransforms,
    Grid,
    LaserScan,
    Log,
    LogLevel,
    PackedElementField,
    PackedElementFieldNumericType,
    Pose,
    PoseInFrame,
    PosesInFrame,
    Quaternion,
    Timestamp,
    Vector2,
    Vector3,
)

from mmexec.executive.logtools import SAME_INSTANT
from mmexec.executive.serve.service import TreeView

__all__ = [
    "BASE_FRAME",
    "CAMERA_FRAME",
    "CHANNELS",
    "LIDAR_FRAME",
    "MAP_FRAME",
    "ChannelOutput",
    "ChannelSpec",
    "Recorder",
    "log_line",
]

log = logging.getLogger(__name__)

MAP_FRAME = "map"
BASE_FRAME = "base_link"
LIDAR_FRAME = "lidar"
CAMERA_FRAME = "camera"

TF, POSE, MAP, SCAN, CAMERA, PATH = "/tf", "/pose", "/map", "/scan", "/camera", "/path"
TREE, EVENTS, LOG = "/mmexec/tree", "/mmexec/events", "/mmexec/log"

#: The stream topics (:class:`~mmexec.executive.serve.service.Streams`) whose messages
#: cost a device read or an encoding; an output says when it takes them (subscriptions,
#: rates): see :meth:`ChannelOutput.takes`.
COSTLY = ("pose", "scan", "camera")

_EVENT_SCHEMA: dict[str, Any] = {
    "title": "mmexec.Event",
    "description": "One record of the mmexec event log, as written (executive/eventlog.py)",
    "type": "object",
    "properties": {
        "event": {"type": "string", "description": "record type"},
        "seq": {"type": "integer", "description": "0, 1, 2, ... in write order"},
        "t": {"type": "number", "description": "clock time [s] since the backend started"},
        "node": {"type": "string", "description": "node path (events of the tree and skills)"},
        "path": {"type": "string", "description": "node path (node_status)"},
        "old": {"type": "string"},
        "new": {"type": "string"},
    },
    "required": ["event", "seq"],
    "additionalProperties": True,
}

_TREE_SCHEMA: dict[str, Any] = {
    "title": "mmexec.TreeStatus",
    "description": "The running tree's node statuses (py_trees names) after one clock instant",
    "type": "object",
    "properties": {
        "request": {"type": ["integer", "null"], "description": "request index (run) or id (serve)"},
        "t": {"type": "number", "description": "clock time [s] of the last change"},
        "nodes": {
            "type": "array",
            "description": "every node, in tree order (depth first)",
            "items": {
                "type": "object",
                "properties": {
                    "path": {"type": "string"},
                    "name": {"type": "string"},
                    "parent": {"type": ["string", "null"]},
                    "status": {"type": "string", "enum": ["INVALID", "RUNNING", "SUCCESS", "FAILURE"]},
                },
            },
        },
        "changed": {"type": "array", "items": {"type": "string"}, "description": "paths changed at t"},
    },
    "required": ["request", "t", "nodes", "changed"],
}


@dataclass(frozen=True)
class ChannelSpec:
    """One channel: its topic, message encoding and schema (name, encoding, bytes)."""

    topic: str
    message_encoding: str
    schema_name: str
    schema_encoding: str
    schema_data: bytes


def _proto(topic: str, message: Any) -> ChannelSpec:
    schema = message.get_schema()
    return ChannelSpec(topic, "protobuf", schema.name, schema.encoding, bytes(schema.data))


def _json(topic: str, schema: Mapping[str, Any]) -> ChannelSpec:
    return ChannelSpec(topic, "json", str(schema["title"]), "jsonschema",
                       json.dumps(schema, separators=(",", ":")).encode("utf-8"))


#: Every channel, in the order they are registered (see the module doc).
CHANNELS: tuple[ChannelSpec, ...] = (
    _proto(TF, FrameTransforms),
    _proto(POSE, PoseInFrame),
    _proto(MAP, Grid),
    _proto(SCAN, LaserScan),
    _proto(CAMERA, CompressedImage),
    _proto(PATH, PosesInFrame),
    _json(TREE, _TREE_SCHEMA),
    _json(EVENTS, _EVENT_SCHEMA),
    _proto(LOG, Log),
)


class ChannelOutput(Protocol):
    """Where a :class:`Recorder` writes: an MCAP file, a Foxglove server."""

    def write(self, topic: str, data: bytes, log_time: int) -> None:
        """One encoded message on channel ``topic`` at ``log_time`` [ns since the epoch]."""

    def takes(self, topic: str, t: float) -> bool:
        """Whether it takes a :data:`COSTLY` stream topic now, at clock time ``t`` [s]."""

    def tick(self, log_time: int) -> None:
        """Once per tick, at ``log_time`` [ns] (a live server's clock, late subscribers)."""

    def close(self) -> None:
        """Finish (idempotent)."""


# --------------------------------------------------------------------------- encoding


def _yaw(theta: float) -> Quaternion:
    return Quaternion(x=0.0, y=0.0, z=math.sin(theta / 2.0), w=math.cos(theta / 2.0))


def _quaternion(R: np.ndarray) -> Quaternion:
    """The unit quaternion of a rotation matrix (Shepperd's method, numerically safe)."""
    m = np.asarray(R, dtype=float)
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0:
        s = 2.0 * math.sqrt(tr + 1.0)
        return Quaternion(x=(m[2, 1] - m[1, 2]) / s, y=(m[0, 2] - m[2, 0]) / s, z=(m[1, 0] - m[0, 1]) / s, w=0.25 * s)
    i = int(np.argmax([m[0, 0], m[1, 1], m[2, 2]]))
    j, k = (i + 1) % 3, (i + 2) % 3
    s = 2.0 * math.sqrt(max(1.0 + m[i, i] - m[j, j] - m[k, k], 1e-12))
    q = [0.0, 0.0, 0.0]
    q[i] = 0.25 * s
    q[j] = (m[j, i] + m[i, j]) / s
    q[k] = (m[k, i] + m[i, k]) / s
    return Quaternion(x=q[0], y=q[1], z=q[2], w=(m[k, j] - m[j, k]) / s)


def _transform(stamp: Timestamp, parent: str, child: str, T: np.ndarray) -> FrameTransform:
    """``child``'s pose in ``parent`` from a 4x4 homogeneous transform."""
    m = np.asarray(T, dtype=float)
    return FrameTransform(timestamp=stamp, parent_frame_id=parent, child_frame_id=child,
                          translation=Vector3(x=float(m[0, 3]), y=float(m[1, 3]), z=float(m[2, 3])),
                          rotation=_quaternion(m[:3, :3]))


def _grid_rgba(values: np.ndarray) -> np.ndarray:
    """Cells as RGBA: free white to occupied black by value, unknown translucent grey."""
    v = values.astype(np.int16)
    grey = (255 - np.clip(v, 0, 100) * 255 // 100).astype(np.uint8)
    rgba = np.empty(values.shape + (4,), dtype=np.uint8)
    rgba[..., 0] = rgba[..., 1] = rgba[..., 2] = grey
    rgba[..., 3] = 255
    unknown = v < 0
    rgba[unknown] = (128, 128, 128, 96)
    return rgba


_LEVELS = {"debug": LogLevel.Debug, "info": LogLevel.Info, "warning": LogLevel.Warning, "error": LogLevel.Error}
_WARN = frozenset({"skill_failure", "skill_failed", "recovery_attempt", "recovery_give_up", "recovery_failed",
                   "halt", "halt_abandoned", "timeout", "request_dropped", "goal_adjusted", "back_off_shortened"})
_QUIET = frozenset({"event", "seq", "t", "node", "nodes", "versions", "argv"})


def _scalar(value: Any) -> str:
    if isinstance(value, dict):
        return ", ".join(f"{k}={_scalar(v)}" for k, v in value.items())
    if isinstance(value, list):
        return "[" + ", ".join(_scalar(v) for v in value) + "]"
    return str(value)


def log_line(record: Mapping[str, Any]) -> tuple[LogLevel, str, str]:
    """One event-log record as a log line: (level, name, message). The name is the node
    path (``mmexec`` for the run's own records)."""
    ev = str(record.get("event", "?"))
    name = str(record.get("node") or record.get("path") or "mmexec")
    if ev == "node_status":
        return LogLevel.Debug, name, f"{record.get('old')} -> {record.get('new')}"
    if ev == "report":
        return _LEVELS.get(str(record.get("level", "info")), LogLevel.Info), name, str(record.get("message", ""))
    level = LogLevel.Warning if ev in _WARN else LogLevel.Info
    outcome = record.get("outcome")
    if ev in ("request_end", "run_end") and outcome not in ("success", "ok", "stopped"):
        level = LogLevel.Error if outcome == "error" else LogLevel.Warning
    if ev == "mission_reload" and not record.get("ok", True):
        level = LogLevel.Warning
    fields = ", ".join(f"{k}={_scalar(v)}" for k, v in record.items() if k not in _QUIET and v not in ("", None))
    return level, name, f"{ev}: {fields}" if fields else ev


def _started_ns(record: Mapping[str, Any]) -> int:
    """``run_start.started`` (ISO 8601) in ns since the epoch; 0 when absent or bad."""
    text = record.get("started")
    if not isinstance(text, str):
        return 0
    try:
        return int(datetime.fromisoformat(text).timestamp()) * 1_000_000_000
    except ValueError:
        log.warning("run_start: started %r is not an ISO 8601 time; recording times count from 1970", text)
        return 0


# --------------------------------------------------------------------------- the sink


class Recorder:
    """A :class:`~mmexec.executive.serve.service.StreamSink` that writes the channels of
    the module doc to a :class:`ChannelOutput`. The event-derived channels come from the
    records alone (its own :class:`TreeView`): every record on ``/mmexec/events`` and
    ``/mmexec/log``, a tree snapshot at each request start and once per clock instant
    with node changes, written when the clock has moved past that instant (the next
    record, the next tick, :meth:`close`). :attr:`counts`: messages per channel."""

    def __init__(self, output: ChannelOutput) -> None:
        self.output = output
        self.tree = TreeView()
        self.counts: Counter[str] = Counter()
        self.epoch_ns = 0
        self.started = False  # a run_start record was seen
        self._pending: float | None = None  # clock time of tree changes not yet written
        self._closed = False

    # StreamSink
    def refresh(self, t: float) -> bool:
        if self._pending is not None and t - self._pending > SAME_INSTANT:
            self._flush_tree()
        self.output.tick(self.ns(t))
        return False

    def wants(self, topic: str, t: float) -> bool:
        if topic in COSTLY:
            return self.output.takes(topic, t)
        return topic in ("event", "map", "path")  # the tree comes from the records

    def send(self, topic: str, data: Any, t: float) -> None:
        if topic == "event":
            self.record(data, t)
        elif topic == "pose":
            self._pose(data, t)
        elif topic == "scan":
            self._scan(data, t)
        elif topic == "camera":
            self._camera(data, t)
        elif topic == "map":
            self._map(data, t)
        elif topic == "path":
            self._path(data, t)

    def close(self) -> None:
        """Write the last tree changes and close the output (idempotent)."""
        if self._closed:
            return
        self._closed = True
        if self._pending is not None:
            self._flush_tree()
        self.output.close()

    # ------------------------------------------------------------------ records

    def ns(self, t: float) -> int:
        """Clock time ``t`` [s] as log time [ns since the epoch]."""
        return max(0, self.epoch_ns + round(t * 1e9))

    def _stamp(self, t: float) -> Timestamp:
        ns = self.ns(t)
        return Timestamp(ns // 1_000_000_000, ns % 1_000_000_000)

    def _write(self, topic: str, data: bytes, t: float) -> None:
        self.output.write(topic, data, self.ns(t))
        self.counts[topic] += 1

    def record(self, record: Mapping[str, Any], t: float) -> None:
        """One event-log record at clock time ``t`` [s] (its ``t``, or the last one)."""
        ev = record.get("event")
        if ev == "run_start" and not self.started:
            self.started = True
            self.epoch_ns = _started_ns(record)
        if self._pending is not None and (ev in ("request_start", "request_end") or t - self._pending > SAME_INSTANT):
            self._flush_tree()
        self._write(EVENTS, json.dumps(record, separators=(",", ":"), allow_nan=False).encode("utf-8"), t)
        level, name, message = log_line(record)
        self._write(LOG, Log(timestamp=self._stamp(t), level=level, name=name, message=message).encode(), t)
        if self.tree.feed(record):
            if ev == "request_start":
                self._write_tree()
            else:
                self._pending = self.tree.t

    def _flush_tree(self) -> None:
        self._write_tree()
        self._pending = None

    def _write_tree(self) -> None:
        snap = self.tree.snapshot()
        self._write(TREE, json.dumps(snap, separators=(",", ":"), allow_nan=False).encode("utf-8"), self.tree.t)

    # ------------------------------------------------------------------ robot

    def _pose(self, state: Any, t: float) -> None:
        p = state.pose
        stamp = self._stamp(state.stamp)
        pose = Pose(position=Vector3(x=p.x, y=p.y, z=0.0), orientation=_yaw(p.theta))
        self._write(POSE, PoseInFrame(timestamp=stamp, frame_id=MAP_FRAME, pose=pose).encode(), t)
        tf = FrameTransform(timestamp=stamp, parent_frame_id=MAP_FRAME, child_frame_id=BASE_FRAME,
                            translation=Vector3(x=p.x, y=p.y, z=0.0), rotation=_yaw(p.theta))
        self._write(TF, FrameTransforms(transforms=[tf]).encode(), t)

    def _scan(self, scan: Any, t: float) -> None:
        stamp = self._stamp(scan.stamp)
        n = len(scan.ranges)
        ranges = [float(r) if math.isfinite(r) and scan.range_min <= r <= scan.range_max else math.nan
                  for r in scan.ranges]
        intensities = [float(i) for i in scan.intensities] if getattr(scan, "intensities", None) is not None else []
        end = scan.angle_min + scan.angle_increment * max(n - 1, 0)
        msg = LaserScan(timestamp=stamp, frame_id=LIDAR_FRAME, pose=Pose(position=Vector3(), orientation=_yaw(0.0)),
                        start_angle=float(scan.angle_min), end_angle=float(end), ranges=ranges,
                        intensities=intensities)
        self._write(TF, FrameTransforms(transforms=[_transform(stamp, BASE_FRAME, LIDAR_FRAME,
                                                               scan.T_base_lidar)]).encode(), t)
        self._write(SCAN, msg.encode(), t)

    def _camera(self, sample: Any, t: float) -> None:
        frame = sample.frame
        stamp = self._stamp(frame.stamp)
        self._write(TF, FrameTransforms(transforms=[_transform(stamp, BASE_FRAME, CAMERA_FRAME,
                                                               frame.T_base_camera)]).encode(), t)
        self._write(CAMERA, CompressedImage(timestamp=stamp, frame_id=CAMERA_FRAME, data=sample.jpeg,
                                            format="jpeg").encode(), t)

    def _map(self, grid: Any, t: float) -> None:
        values = np.asarray(grid.data).astype(np.int8)
        cells = np.empty(values.shape + (5,), dtype=np.uint8)
        cells[..., 0] = values.view(np.uint8)
        cells[..., 1:] = _grid_rgba(values)
        u8 = PackedElementFieldNumericType.Uint8
        fields = [PackedElementField(name="occupancy", offset=0, type=PackedElementFieldNumericType.Int8)] + [
            PackedElementField(name=c, offset=i, type=u8) for i, c in enumerate(("red", "green", "blue", "alpha"), 1)]
        o = grid.origin
        msg = Grid(timestamp=self._stamp(t), frame_id=MAP_FRAME,
                   pose=Pose(position=Vector3(x=o.x, y=o.y, z=0.0), orientation=_yaw(o.theta)),
                   column_count=int(grid.width), cell_size=Vector2(x=grid.resolution, y=grid.resolution),
                   row_stride=int(grid.width) * 5, cell_stride=5, fields=fields, data=cells.tobytes())
        self._write(MAP, msg.encode(), t)

    def _path(self, points: Sequence[tuple[float, float]], t: float) -> None:
        poses = []
        for i, (x, y) in enumerate(points):
            nx, ny = points[i + 1] if i + 1 < len(points) else (x, y)
            px, py = points[i - 1] if i > 0 else (x, y)
            heading = math.atan2(ny - y, nx - x) if (nx, ny) != (x, y) else math.atan2(y - py, x - px)
            poses.append(Pose(position=Vector3(x=x, y=y, z=0.0), orientation=_yaw(heading)))
        self._write(PATH, PosesInFrame(timestamp=self._stamp(t), frame_id=MAP_FRAME, poses=poses).encode(), t)
