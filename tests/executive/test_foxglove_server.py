"""``--foxglove`` (issue 13): a plain WebSocket client speaking Foxglove's protocol
(serverInfo, advertise, subscribe, binary message data) against the server on 127.0.0.1,
attached to a service on the mock backend: it receives the robot pose (decoded with the
advertised protobuf schema) while the service idles and the tree's statuses while a
request runs; a client subscribing to the tree later gets the latest snapshot."""

from __future__ import annotations

import asyncio
import base64
import io
import json
import struct
import threading
from pathlib import Path
from typing import Any

import pytest
import websockets
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

from mmexec.executive.recording.session import Recording
from mmexec.executive.runner import RunOptions
from mmexec.executive.serve.service import ServeRunner, Service

ROOT = Path(__file__).resolve().parents[2]
QUICK = ROOT / "tests" / "serve" / "missions" / "quick.yaml"
#: Foxglove's WebSocket subprotocols: foxglove-sdk names the protocol foxglove.sdk.v1,
#: earlier servers foxglove.websocket.v1 (the same messages); a client offers both
SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
#: [wall s] longest wait for one message before the test fails (no timing is asserted)
PATIENCE = 30.0


def _decoder(channel: dict[str, Any]) -> Any:
    """A protobuf message class from an advertised channel's schema (a FileDescriptorSet)."""
    fds = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(channel["schema"]))
    pool = descriptor_pool.DescriptorPool()
    for fd in fds.file:
        pool.Add(fd)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(channel["schemaName"]))


class FoxgloveClient:
    """Just enough of a Foxglove WebSocket client: the advertised channels by topic, and
    subscriptions whose binary messages are returned by :meth:`next`."""

    def __init__(self, ws: Any) -> None:
        self.ws = ws
        self.channels: dict[str, dict[str, Any]] = {}
        self.info: dict[str, Any] = {}
        self._subs: dict[int, str] = {}

    async def handshake(self, topics: set[str]) -> None:
        while not topics <= set(self.channels):
            msg = json.loads(await asyncio.wait_for(self.ws.recv(), PATIENCE))
            if msg["op"] == "serverInfo":
                self.info = msg
            elif msg["op"] == "advertise":
                self.channels.update({c["topic"]: c for c in msg["channels"]})

    async def subscribe(self, *topics: str) -> None:
        subs = []
        for topic in topics:
            sid = len(self._subs) + 1
            self._subs[sid] = topic
            subs.append({"id": sid, "channelId": self.channels[topic]["id"]})
        await self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    async def next(self, topic: str) -> tuple[int, bytes]:
        """The next message on ``topic``: (log time [ns], payload); other frames skipped."""
        while True:
            frame = await asyncio.wait_for(self.ws.recv(), PATIENCE)
            if isinstance(frame, bytes) and frame[0] == 1:  # message data
                sid, = struct.unpack_from("<I", frame, 1)
                t, = struct.unpack_from("<Q", frame, 5)
                if self._subs.get(sid) == topic:
                    return t, frame[13:]


@pytest.fixture
def service(tmp_path: Path) -> Any:
    """A service on the mock backend with a Foxglove server on 127.0.0.1 (a free port),
    its tick loop in a thread; stopped at the end."""
    svc = Service()
    runner = ServeRunner(RunOptions(mission=QUICK, config=ROOT / "config" / "mock.yaml",
                                    log_path=tmp_path / "serve.jsonl"), svc, out=io.StringIO(), err=io.StringIO())
    runner.prepare()
    rec = Recording(foxglove="127.0.0.1:0")
    rec.attach(runner)
    codes: list[int] = []
    thread = threading.Thread(target=lambda: codes.append(runner.run()), name="test-tick-loop", daemon=True)
    thread.start()
    try:
        assert rec.server is not None
        yield svc, rec.server
    finally:
        svc.stop()
        thread.join(PATIENCE)
        rec.close()
    assert codes == [0]


def test_a_websocket_client_gets_pose_and_tree(service: Any) -> None:
    svc, server = service
    assert server.addr.host == "127.0.0.1" and server.port > 0

    async def scenario() -> None:
        url = f"ws://127.0.0.1:{server.port}"
        async with websockets.connect(url, subprotocols=SUBPROTOCOLS, max_size=None) as ws:
            assert ws.subprotocol in SUBPROTOCOLS
            fox = FoxgloveClient(ws)
            await fox.handshake({"/pose", "/tf", "/mmexec/tree", "/mmexec/events", "/map", "/scan", "/camera"})
            assert "time" in fox.info["capabilities"]
            pose_ch, tree_ch = fox.channels["/pose"], fox.channels["/mmexec/tree"]
            assert (pose_ch["encoding"], pose_ch["schemaName"]) == ("protobuf", "foxglove.PoseInFrame")
            assert (tree_ch["encoding"], tree_ch["schemaName"], tree_ch["schemaEncoding"]) == (
                "json", "mmexec.TreeStatus", "jsonschema")
            await fox.subscribe("/pose", "/mmexec/tree")
            _, data = await fox.next("/pose")  # the service idles: the pose streams all the same
            pose = _decoder(pose_ch).FromString(data)
            assert pose.frame_id == "map" and pose.pose.orientation.w == pytest.approx(1.0)
            await asyncio.to_thread(svc.submit, {"item": 7})
            snaps = []
            while not snaps or snaps[-1]["nodes"][0]["status"] != "SUCCESS":
                _, data = await fox.next("/mmexec/tree")
                snaps.append(json.loads(data))
            assert snaps[0]["request"] == 1 and {n["status"] for n in snaps[0]["nodes"]} == {"INVALID"}
            assert [n["path"] for n in snaps[-1]["nodes"]] == [n["path"] for n in snaps[0]["nodes"]]

        # a client that subscribes later gets the latest tree at the next tick
        async with websockets.connect(url, subprotocols=SUBPROTOCOLS, max_size=None) as ws:
            fox = FoxgloveClient(ws)
            await fox.handshake({"/mmexec/tree"})
            await fox.subscribe("/mmexec/tree")
            _, data = await fox.next("/mmexec/tree")
            assert json.loads(data) == snaps[-1]

    asyncio.run(scenario())


def test_a_port_in_use_is_one_located_line(service: Any) -> None:
    from mmexec.config.yamlload import InputError

    _, server = service
    rec = Recording(foxglove=f"127.0.0.1:{server.port}")
    runner = ServeRunner(RunOptions(mission=QUICK, config=ROOT / "config" / "mock.yaml"), Service(),
                         out=io.StringIO(), err=io.StringIO())
    runner.prepare()
    with pytest.raises(InputError) as e:
        rec.attach(runner)
    (problem,) = e.value.problems
    assert str(problem).startswith(f"--foxglove: cannot listen on 127.0.0.1:{server.port}: ")
    assert "\n" not in str(problem)
